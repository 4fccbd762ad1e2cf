"""Scenario files: one TOML file describes a simulated run end to end.

A scenario file has the tables ``[scenario]``, ``[trajectory]``, ``[imu]``, ``[gnss]``,
``[odometer]`` and ``[magnetometer]`` (only ``[scenario]`` and ``[trajectory]`` are required; a
missing sensor table means that sensor is not simulated, a missing ``[imu]`` gives ideal
sensors). Other top-level tables (``[process]``, ``[aiding]``, ``[outputs]``, ``[evaluation]``,
``[montecarlo]``, ...) belong to the processing job and are ignored here, so one file can both
simulate and process. Inside the simulation tables every key is checked: an unknown key is a
:class:`~insgnss.errors.ConfigError` naming it.

Angles are in **degrees** in the file (latitude, longitude, heading, turn angles and rates,
bank, foot pitch, magnetometer errors) and in radians inside insgnss. See ``docs/simulation.md``
for every key and ``scenarios/*.toml`` for examples.

Reproducibility: the ``seed`` (from ``[scenario]``, overridden by the ``seed`` argument, or
drawn and recorded when absent) feeds a ``numpy.random.SeedSequence`` whose four children drive
the IMU errors, GNSS, odometer and magnetometer; changing the settings of one sensor does not
change the random draws of the others.
"""

from __future__ import annotations

import inspect
import json
import os
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .._version import __version__
from ..earth import GRAVITY_MODELS
from ..errors import ConfigError
from ..imu import (
    ACCEL_COLS,
    DTHETA_COLS,
    DV_COLS,
    GYRO_COLS,
    ImuErrorModel,
    grade,
    is_increment_table,
)
from ..io.native import atomic_write_text, jsonable, write_table
from ..mechanization.inverse import inverse_mechanize
from ..mechanization.strapdown import NAV_COLS
from .aiding import simulate_gnss, simulate_magnetometer, simulate_odometer
from .sensors import BIAS_INSTABILITY_MODELS, OUTPUTS, simulate_imu
from .trajectory import ANGLE_KEYS, generate

SIM_TABLES = ("scenario", "trajectory", "imu", "gnss", "odometer", "magnetometer")
SEED_STREAMS = ("imu", "gnss", "odometer", "magnetometer")
BIAS_FILE_RATE_MAX = 10.0  #: imu_bias.csv is written at no more than this rate [Hz]

SCENARIO_KEYS = {"name", "description", "seed", "imu_rate", "duration", "start_time",
                 "gravity_model"}
TRAJECTORY_KEYS = {"vehicle", "lat", "lon", "height", "heading", "speed", "roll_gain",
                   "segments", "waypoints", "start_at_rest", "end_at_rest"}
IMU_KEYS_EXTRA = {"grade", "bias_instability_model", "flicker_band", "flicker_per_decade",
                  "output", "idle_vibration_accel_std", "idle_vibration_gyro_std_deg_s"}
GNSS_KEYS = {"rate", "horizontal_std", "vertical_std", "correlation_time", "velocity",
             "velocity_std", "vertical_velocity_std", "lever_arm", "outages", "periodic_outages",
             "degraded", "outlier_probability", "outlier_duration", "outlier_magnitude", "q", "ns"}
PERIODIC_KEYS = {"start", "length", "gap", "stop_before_end"}
DEGRADED_KEYS = {"start", "stop", "factor"}
ODOMETER_KEYS = {"rate", "output", "scale_factor", "scale_factor_std", "noise_std",
                 "speed_quantum", "distance_quantum", "distance_noise_std", "lever_arm"}
MAGNETOMETER_KEYS = {"rate", "noise_std", "declination_error", "deviation", "deviation_phase"}
MAGNETOMETER_ANGLES = {"noise_std", "declination_error", "deviation", "deviation_phase"}


def datasheet_keys() -> dict[str, tuple[str, float]]:
    """Map each datasheet-unit argument of :meth:`ImuErrorModel.from_datasheet` to the SI field
    it sets and its conversion factor (found by calling ``from_datasheet`` itself, so the unit
    conversions stay in one place)."""
    base = ImuErrorModel.from_datasheet()
    names = [f.name for f in fields(ImuErrorModel) if f.name not in ("name", "source")]
    out = {}
    for key in inspect.signature(ImuErrorModel.from_datasheet).parameters:
        if key in ("name", "source", "cls"):
            continue
        probe = ImuErrorModel.from_datasheet(**{key: 2.0})
        changed = [f for f in names if getattr(probe, f) != getattr(base, f)]
        if len(changed) == 1:
            out[key] = (changed[0], getattr(probe, changed[0]) / 2.0)
    return out


# --- typed access to one table ------------------------------------------------------------------
class _Table:
    """A config table with typed getters; errors name ``table.key`` and the file."""

    def __init__(self, data: Any, name: str, file, allowed: set[str] | None):
        if not isinstance(data, dict):
            raise ConfigError("must be a table", file=file, column=name, found=type(data).__name__)
        self.d, self.name, self.file = data, name, file
        if allowed is not None:
            for key in data:
                if key not in allowed:
                    raise ConfigError(f"unknown key '{key}'", file=file, column=f"{name}.{key}",
                                      expected=sorted(allowed))

    def __contains__(self, key):
        return key in self.d

    def err(self, key, msg, **kw):
        return ConfigError(msg, file=self.file, column=f"{self.name}.{key}", **kw)

    def num(self, key, default=None, *, positive=False, nonneg=False, required=False) -> float:
        if key not in self.d:
            if required:
                raise self.err(key, "missing value", expected="a number")
            return default
        v = self.d[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise self.err(key, "not a finite number", found=repr(v))
        if positive and v <= 0:
            raise self.err(key, "must be positive", found=v)
        if nonneg and v < 0:
            raise self.err(key, "must not be negative", found=v)
        return float(v)

    def integer(self, key, default=None, *, nonneg=True):
        if key not in self.d:
            return default
        v = self.d[key]
        if isinstance(v, bool) or not isinstance(v, int) or (nonneg and v < 0):
            raise self.err(key, "must be a non-negative integer", found=repr(v))
        return int(v)

    def string(self, key, default=None, choices=None) -> str:
        if key not in self.d:
            return default
        v = self.d[key]
        if not isinstance(v, str):
            raise self.err(key, "must be a string", found=repr(v))
        if choices is not None and v not in choices:
            raise self.err(key, f"unknown value {v!r}", expected=list(choices))
        return v

    def boolean(self, key, default=False) -> bool:
        if key not in self.d:
            return default
        v = self.d[key]
        if not isinstance(v, bool):
            raise self.err(key, "must be true or false", found=repr(v))
        return v

    def vector(self, key, n, default=None) -> list[float]:
        if key not in self.d:
            return default
        v = self.d[key]
        if (not isinstance(v, list) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, int | float) for x in v)):
            raise self.err(key, f"must be a list of {n} numbers", found=repr(v))
        return [float(x) for x in v]

    def table_list(self, key) -> list:
        if key not in self.d:
            return []
        v = self.d[key]
        if not isinstance(v, list):
            raise self.err(key, "must be a list", found=repr(v))
        return v


# --- loading ------------------------------------------------------------------------------------
def load_scenario(source: str | os.PathLike | dict) -> tuple[dict, Path | None]:
    """Read a scenario (TOML path or already-parsed dict); returns ``(config, path)``."""
    if isinstance(source, dict):
        return source, None
    path = Path(source)
    try:
        with open(path, "rb") as fh:
            cfg = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError("scenario file not found", file=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", file=path) from None
    return cfg, path


def _segments_to_si(segments: list, file) -> list[dict]:
    """Convert the degree-valued keys of segment tables to radians."""
    out = []
    for i, seg in enumerate(segments):
        if not isinstance(seg, dict):
            raise ConfigError("a segment must be a table", file=file,
                              column=f"trajectory.segments[{i}]", found=repr(seg))
        s = dict(seg)
        for key in ANGLE_KEYS.get(s.get("type"), ()):
            if key in s and isinstance(s[key], int | float) and not isinstance(s[key], bool):
                s[key] = float(np.radians(s[key]))
        out.append(s)
    return out


def _imu_model(tab: _Table) -> tuple[ImuErrorModel, dict]:
    ds = datasheet_keys()
    for key in tab.d:
        if key not in ds and key not in IMU_KEYS_EXTRA:
            raise tab.err(key, f"unknown key '{key}'", expected=sorted(IMU_KEYS_EXTRA | set(ds)))
    name = tab.string("grade")
    if name is not None:
        try:
            model = grade(name)
        except ValueError:
            raise tab.err("grade", f"unknown grade {name!r}",
                          expected=["navigation", "tactical", "consumer", "mems"]) from None
    else:
        model = ImuErrorModel(name="custom")
    changes = {}
    for key, (fname, factor) in ds.items():
        if key in tab:
            changes[fname] = tab.num(key, nonneg=(key != "bias_correlation_time_s"),
                                     positive=(key == "bias_correlation_time_s")) * factor
    if changes:
        model = model.scaled(**changes)
        if name is None:
            model = model.scaled(name="custom")
    opts = {
        "bias_instability": tab.string("bias_instability_model", "gauss_markov",
                                       BIAS_INSTABILITY_MODELS),
        "output": tab.string("output", "increments", OUTPUTS),
        "flicker_per_decade": tab.integer("flicker_per_decade", 3),
    }
    if opts["flicker_per_decade"] < 1:
        raise tab.err("flicker_per_decade", "must be at least 1", found=opts["flicker_per_decade"])
    band = tab.vector("flicker_band", 2)
    if band is not None:
        if not 0 < band[0] < band[1]:
            raise tab.err("flicker_band", "must be [low, high] with 0 < low < high", found=band)
        opts["flicker_band"] = tuple(band)
    vib = (tab.num("idle_vibration_accel_std", nonneg=True) if "idle_vibration_accel_std" in tab
           else 0.0,
           np.radians(tab.num("idle_vibration_gyro_std_deg_s", nonneg=True))
           if "idle_vibration_gyro_std_deg_s" in tab else 0.0)
    if any(vib):
        opts["idle_vibration"] = vib
    return model, opts


def add_idle_vibration(imu: pd.DataFrame, still: np.ndarray, accel_std: float,
                       gyro_std: float, rng: np.random.Generator) -> pd.DataFrame:
    """Engine vibration of a parked vehicle: white specific force (``accel_std`` [m/s^2] per
    axis and sample) and angular rate (``gyro_std`` [rad/s]) added to the increments of the
    samples where the vehicle is ``still`` (an idling engine shakes a parked car by 0.1-0.4
    m/s^2; the IMU errors while moving are the model's alone)."""
    out = imu.copy()
    t = out.index.to_numpy(float)
    dt = np.empty(t.size)
    dt[1:] = np.diff(t)
    dt[0] = dt[1] if t.size > 1 else 0.0
    k = np.flatnonzero(still)
    noise = rng.standard_normal((k.size, 6)) * dt[k, None]
    cols = DTHETA_COLS + DV_COLS
    if not is_increment_table(out):
        cols = GYRO_COLS + ACCEL_COLS
        noise = noise / dt[k, None]
    vals = out[cols].to_numpy(float, copy=True)
    vals[k, :3] += noise[:, :3] * gyro_std
    vals[k, 3:] += noise[:, 3:] * accel_std
    out[cols] = vals
    out.attrs = dict(imu.attrs)
    return out


def _gnss_kwargs(tab: _Table) -> dict:
    kw: dict[str, Any] = {}
    for key in ("rate", "horizontal_std", "vertical_std", "velocity_std",
                "vertical_velocity_std", "outlier_magnitude"):
        if key in tab:
            kw[key] = tab.num(key, positive=True)
    for key in ("correlation_time", "outlier_duration"):
        if key in tab:
            kw[key] = tab.num(key, nonneg=True)
    if "outlier_probability" in tab:
        p = tab.num("outlier_probability", nonneg=True)
        if p >= 1:
            raise tab.err("outlier_probability", "must be below 1", found=p)
        kw["outlier_probability"] = p
    kw["velocity"] = tab.boolean("velocity", False)
    kw["lever_arm"] = tab.vector("lever_arm", 3, [0.0, 0.0, 0.0])
    windows = []
    for i, w in enumerate(tab.table_list("outages")):
        if (not isinstance(w, list) or len(w) != 2
                or any(isinstance(x, bool) or not isinstance(x, int | float) for x in w)
                or not w[0] < w[1]):
            raise tab.err(f"outages[{i}]", "must be [start, stop] with start < stop [s]",
                          found=repr(w))
        windows.append([float(w[0]), float(w[1])])
    kw["outages"] = windows
    if "periodic_outages" in tab:
        po = _Table(tab.d["periodic_outages"], f"{tab.name}.periodic_outages", tab.file,
                    PERIODIC_KEYS)
        kw["periodic_outages"] = {
            "start": po.num("start", required=True, nonneg=True),
            "length": po.num("length", required=True, positive=True),
            "gap": po.num("gap", required=True, nonneg=True),
            "stop_before_end": po.num("stop_before_end", 0.0, nonneg=True),
        }
    degraded = []
    for i, d in enumerate(tab.table_list("degraded")):
        dt = _Table(d, f"{tab.name}.degraded[{i}]", tab.file, DEGRADED_KEYS)
        degraded.append({"start": dt.num("start", required=True),
                         "stop": dt.num("stop", required=True),
                         "factor": dt.num("factor", required=True, positive=True)})
    kw["degraded"] = degraded
    kw["q"] = tab.integer("q", 5)
    if "ns" in tab:
        kw["ns"] = tab.integer("ns")
    return kw


def _odometer_kwargs(tab: _Table) -> dict:
    kw: dict[str, Any] = {"output": tab.string("output", "speed", ("speed", "distance", "both"))}
    if "rate" in tab:
        kw["rate"] = tab.num("rate", positive=True)
    if "scale_factor" in tab:
        kw["scale_factor"] = tab.num("scale_factor")
    for key in ("scale_factor_std", "noise_std", "speed_quantum", "distance_quantum",
                "distance_noise_std"):
        if key in tab:
            kw[key] = tab.num(key, nonneg=True)
    kw["lever_arm"] = tab.vector("lever_arm", 3, [0.0, 0.0, 0.0])
    return kw


def _magnetometer_kwargs(tab: _Table) -> dict:
    kw: dict[str, Any] = {}
    if "rate" in tab:
        kw["rate"] = tab.num("rate", positive=True)
    if "noise_std" in tab:
        kw["noise_std"] = float(np.radians(tab.num("noise_std", nonneg=True)))
    for key in ("declination_error", "deviation", "deviation_phase"):
        if key in tab:
            kw[key] = float(np.radians(tab.num(key)))
    return kw


# --- result ---------------------------------------------------------------------------------------
#: columns and units of the written files (angles are written in degrees by write_table)
FILE_UNITS = {
    "truth.csv": {"time": "s", "lat_deg": "deg", "lon_deg": "deg", "height": "m (ellipsoidal)",
                  "vel_e": "m/s", "vel_n": "m/s", "vel_u": "m/s", "roll_deg": "deg",
                  "pitch_deg": "deg", "heading_deg": "deg clockwise from north",
                  "stationary": "1 at rest (zero velocity, constant attitude), else 0"},
    "imu.csv": {"time": "s", "dtheta_x..z": "rad (increment over the interval ending at time)",
                "dv_x..z": "m/s (increment)", "gyro_x..z": "rad/s (rates output)",
                "accel_x..z": "m/s^2 (rates output)"},
    "imu_bias.csv": {"time": "s", "gyro_bias_x..z": "rad/s", "accel_bias_x..z": "m/s^2",
                     "rate": "IMU samples decimated to at most 10 Hz (the bias is slow)"},
    "gnss.csv": {"time": "s", "lat_deg": "deg", "lon_deg": "deg", "height": "m",
                 "east_std": "m", "north_std": "m", "up_std": "m", "vel_e..u": "m/s",
                 "vel_e_std..vel_u_std": "m/s", "q": "RTKLIB quality (1 fix, 2 float, 5 single)",
                 "ns": "satellites", "outlier": "1 for a simulated multipath outlier"},
    "odometer.csv": {"time": "s", "speed": "m/s forward", "distance": "m over the interval"},
    "magnetometer.csv": {"time": "s", "heading_deg": "deg clockwise from north",
                         "heading_std_deg": "deg"},
}
FRAMES = {
    "navigation": "local level ENU (x east, y north, z up)",
    "body": "right-forward-up",
    "attitude": "C_b^l = Rz(-heading) Rx(pitch) Ry(roll); heading clockwise from north",
    "position": "WGS84 geodetic latitude, longitude, ellipsoidal height",
    "imu": "body-frame increments; row k integrates (t[k-1], t[k]]; row 0 is the interval "
           "before the first sample",
}


@dataclass
class SimulationResult:
    """Output of :func:`simulate_scenario`.

    ``truth`` (NAV_COLS + ``stationary``), ``imu`` (with errors), ``imu_ideal`` (inverse
    mechanization of the truth), ``imu_bias`` (bias time series, truth for the filter), ``gnss``,
    ``odometer``, ``magnetometer`` (None when not configured), ``metadata`` (JSON-ready dict:
    units, frames, seed, configuration and the error parameters actually drawn) and
    ``imu_model`` (the :class:`~insgnss.imu.ImuErrorModel` used, grade plus overrides).
    """

    truth: pd.DataFrame
    imu: pd.DataFrame
    imu_ideal: pd.DataFrame
    imu_bias: pd.DataFrame | None
    gnss: pd.DataFrame | None
    odometer: pd.DataFrame | None
    magnetometer: pd.DataFrame | None
    metadata: dict = field(default_factory=dict)
    imu_model: ImuErrorModel | None = None  #: the error model used (SI), None for ideal sensors

    @property
    def seed(self) -> int:
        return int(self.metadata["seed"])

    def sensor_errors(self) -> pd.DataFrame | None:
        """The simulated IMU errors the filter estimates, as the filter names them: the bias
        series ``gyro_bias_x .. accel_bias_z`` [rad/s, m/s^2] and the drawn (constant) scale
        factors ``gyro_scale_x .. accel_scale_z`` [-]; None for ideal sensors."""
        if self.imu_bias is None:
            return None
        out = self.imu_bias.copy()
        drawn = (self.metadata.get("imu") or {}).get("drawn") or {}
        for key in ("gyro_scale", "accel_scale"):
            if key in drawn:
                for j, ax in enumerate("xyz"):
                    out[f"{key}_{ax}"] = float(np.asarray(drawn[key], float)[j])
        return out

    def tables(self) -> dict[str, pd.DataFrame]:
        """The tables that are written, by file name (``imu_bias`` decimated to <= 10 Hz)."""
        out = {"truth.csv": self.truth, "imu.csv": self.imu}
        bias = self.imu_bias
        if bias is not None and len(bias) > 1:
            dt = float(np.median(np.diff(bias.index.to_numpy(float))))
            step = max(int(round(1.0 / (BIAS_FILE_RATE_MAX * dt))), 1)
            bias = bias.iloc[::step]
        for name, df in (("imu_bias.csv", bias), ("gnss.csv", self.gnss),
                         ("odometer.csv", self.odometer), ("magnetometer.csv", self.magnetometer)):
            if df is not None:
                out[name] = df
        return out

    def write(self, directory: str | os.PathLike) -> dict[str, Path]:
        """Write the native CSV tables and ``metadata.json`` into ``directory`` (atomically,
        file by file). Returns the written paths by file name."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        paths = {}
        for name, df in self.tables().items():
            paths[name] = write_table(df, d / name)
        meta = dict(self.metadata)
        meta["files"] = {name: FILE_UNITS[name] for name in paths}
        paths["metadata.json"] = atomic_write_text(d / "metadata.json",
                                                   json.dumps(jsonable(meta), indent=2) + "\n")
        return paths




def _initial_state(truth: pd.DataFrame) -> dict:
    r = truth.iloc[0]
    return {"time": float(truth.index[0]), "lat_deg": float(np.degrees(r["lat"])),
            "lon_deg": float(np.degrees(r["lon"])), "height": float(r["height"]),
            "vel_e": float(r["vel_e"]), "vel_n": float(r["vel_n"]), "vel_u": float(r["vel_u"]),
            "roll_deg": float(np.degrees(r["roll"])), "pitch_deg": float(np.degrees(r["pitch"])),
            "heading_deg": float(np.degrees(r["heading"]))}


# --- the simulation -------------------------------------------------------------------------------
def simulate_scenario(source: str | os.PathLike | dict, seed: int | None = None, *,
                      duration: float | None = None) -> SimulationResult:
    """Simulate a scenario: truth, ideal and erroneous IMU, GNSS, odometer, magnetometer.

    Parameters
    ----------
    source : path or dict
        Scenario TOML file, or its parsed content.
    seed : int, optional
        Overrides ``[scenario] seed`` (Monte Carlo runs use this).
    duration : float, optional
        Overrides ``[scenario] duration`` [s] (truncate, or continue the final motion).

    Returns
    -------
    SimulationResult
    """
    cfg, path = load_scenario(source)
    file = path
    if not isinstance(cfg, dict):
        raise ConfigError("a scenario is a TOML table", file=file)
    for name in ("scenario", "trajectory"):
        if name not in cfg:
            raise ConfigError(f"missing table [{name}]", file=file, column=name)
    sc = _Table(cfg["scenario"], "scenario", file, SCENARIO_KEYS)
    tj = _Table(cfg["trajectory"], "trajectory", file, TRAJECTORY_KEYS)

    if seed is None:
        seed = sc.integer("seed")
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2**63))
    seed = int(seed)
    streams = dict(zip(SEED_STREAMS, (np.random.default_rng(s) for s in
                                      np.random.SeedSequence(seed).spawn(len(SEED_STREAMS))),
                       strict=True))
    rate = sc.num("imu_rate", required=True, positive=True)
    gravity_model = sc.string("gravity_model", "somigliana", tuple(GRAVITY_MODELS))
    start_time = sc.num("start_time", 0.0)

    # trajectory
    if ("segments" in tj) == ("waypoints" in tj):
        raise ConfigError("give exactly one of 'segments' and 'waypoints'", file=file,
                          column="trajectory")
    try:
        traj = generate(
            rate=rate,
            lat=np.radians(tj.num("lat", required=True)),
            lon=np.radians(tj.num("lon", required=True)),
            height=tj.num("height", 0.0),
            heading=np.radians(tj.num("heading", 0.0)),
            speed=tj.num("speed", 0.0, nonneg=True),
            vehicle=tj.string("vehicle", "land", ("land", "aircraft", "pedestrian")),
            segments=(_segments_to_si(tj.table_list("segments"), file)
                      if "segments" in tj else None),
            waypoints=tj.table_list("waypoints") if "waypoints" in tj else None,
            start_at_rest=tj.boolean("start_at_rest"),
            end_at_rest=tj.boolean("end_at_rest"),
            roll_gain=np.radians(tj.num("roll_gain", 0.0)),
            duration=duration if duration is not None else sc.num("duration", None, positive=True),
            start_time=start_time,
        )
    except ConfigError as exc:
        if exc.file is None and file is not None:
            raise ConfigError(exc.message, file=file, column=exc.column, expected=exc.expected,
                              found=exc.found) from None
        raise
    truth = traj.truth
    ideal = inverse_mechanize(truth[NAV_COLS], gravity_model=gravity_model)

    meta: dict[str, Any] = {
        "insgnss_version": __version__,
        "scenario": {"name": sc.string("name", path.stem if path else "scenario"),
                     "description": sc.string("description", ""),
                     "file": str(path) if path else None},
        "seed": seed,
        "seed_streams": list(SEED_STREAMS),
        "frames": FRAMES,
        "time": {"start": float(truth.index[0]), "end": float(truth.index[-1]),
                 "imu_rate": rate, "samples": len(truth)},
        "gravity_model": gravity_model,
        "initial_state": _initial_state(truth),
        "trajectory": {"vehicle": traj.vehicle, "segments": traj.segments},
    }

    # IMU
    imu_bias = None
    model = None
    if "imu" in cfg:
        model, opts = _imu_model(_Table(cfg["imu"], "imu", file, None))
        vib = opts.pop("idle_vibration", None)
        errs = simulate_imu(ideal, model, streams["imu"], **opts)
        imu, imu_bias = errs.imu, errs.bias
        if vib is not None:  # its own child stream: the other errors stay as without it
            still = truth["stationary"].reindex(imu.index, method="nearest").to_numpy() > 0.5
            imu = add_idle_vibration(imu, still, *vib, streams["imu"].spawn(1)[0])
            errs.settings["idle_vibration"] = {"accel_std": vib[0], "gyro_std": vib[1]}
        meta["imu"] = {"grade": model.name, "model_si": model.to_dict(),
                       "settings": errs.settings, "drawn": errs.params_as_lists()}
    else:
        imu = ideal
        meta["imu"] = {"grade": "ideal", "model_si": None, "drawn": None}

    gnss = odo = mag = None
    if "gnss" in cfg:
        kw = _gnss_kwargs(_Table(cfg["gnss"], "gnss", file, GNSS_KEYS))
        gnss = simulate_gnss(truth, streams["gnss"], **kw)
        meta["gnss"] = {**kw, "epochs": len(gnss), "outliers": int(gnss["outlier"].sum())}
    if "odometer" in cfg:
        kw = _odometer_kwargs(_Table(cfg["odometer"], "odometer", file, ODOMETER_KEYS))
        odo, drawn = simulate_odometer(truth, streams["odometer"], **kw)
        meta["odometer"] = {**kw, "drawn": drawn}
    if "magnetometer" in cfg:
        kw = _magnetometer_kwargs(_Table(cfg["magnetometer"], "magnetometer", file,
                                         MAGNETOMETER_KEYS))
        mag = simulate_magnetometer(truth, streams["magnetometer"], **kw)
        meta["magnetometer"] = {k: (float(np.degrees(v)) if k in MAGNETOMETER_ANGLES else v)
                                for k, v in kw.items()}
        meta["magnetometer"]["angle_unit"] = "deg"
    meta["config"] = {k: v for k, v in cfg.items() if k in SIM_TABLES}
    meta["config"]["scenario"] = {**cfg["scenario"], "seed": seed}
    return SimulationResult(truth=truth, imu=imu, imu_ideal=ideal, imu_bias=imu_bias, gnss=gnss,
                            odometer=odo, magnetometer=mag, metadata=meta, imu_model=model)
