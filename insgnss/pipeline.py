"""End-to-end processing of a job (docs/jobs.md): inputs -> initialization -> aiding
measurements -> error-state filter (+ RTS smoother) -> evaluation -> outputs.

Every step is a small function that takes the validated :class:`~insgnss.config.Job` and returns
plain data, so that the CLI (``insgnss process``), the comparisons (``insgnss compare``), Monte
Carlo and batch runs share one implementation. Algorithms never read files; this module is the
only place that wires readers, algorithms and writers together.

Initialization (``[initialization] method``):

- ``static``: levelling over the first ``static_duration`` seconds; heading by gyrocompassing
  when the IMU grade allows it, else the given ``heading_deg``, else from GNSS: the course over
  ground at the first GNSS epoch faster than ``min_speed`` minus the heading change the gyros
  measured from the start to that epoch (a free-inertial run with the levelled attitude);
- ``gnss_velocity``: start at the first GNSS epoch faster than ``min_speed`` with the GNSS
  position and velocity, heading = course over ground (no side slip), roll/pitch from the
  accelerometers (averaged over 1 s) or given;
- ``given``: roll, pitch, heading given; position from the first GNSS epoch.
"""

from __future__ import annotations

import json
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .align import can_gyrocompass, coarse_align, gyrocompass, level
from .config import Job
from .errors import ConfigError, InputFormatError
from .evaluate import move_point, outage_metrics, position_errors
from .filter.engine import FilterConfig, FilterResult, run_filter
from .filter.measurements import BodyVelocity, Cupt, GnssPosition, GnssVelocity, Zaru, Zupt
from .imu import ACCEL_COLS, DV_COLS, GYRO_COLS, ImuErrorModel, grade
from .io.native import jsonable
from .mechanization.strapdown import NavState, mechanize
from .outages import in_windows, periodic_windows
from .policies import check_imu_table, gap_noise, gap_policy, run_segments, shift_report
from .preprocess import estimate_time_offset, shift_time, with_static_noise
from .validate import check_gnss_in_imu_span


# --- inputs -----------------------------------------------------------------------------------
@dataclass
class Inputs:
    """Data of a job, in insgnss conventions."""

    imu: pd.DataFrame
    gnss: pd.DataFrame | None = None
    odometer: pd.DataFrame | None = None
    reference: pd.DataFrame | None = None
    reference_point: str = "antenna"
    control_points: pd.DataFrame | None = None
    lever_arm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    imu_model: ImuErrorModel | None = None
    truth: pd.DataFrame | None = None
    source: str = "files"
    seed: int | None = None


def _imu_model(job: Job, default: ImuErrorModel | None) -> ImuErrorModel:
    f = job["filter"]
    if f["imu_grade"] is not None:
        base = grade(f["imu_grade"])
    elif default is not None:
        base = default
    else:
        base = grade("tactical")
    over = {k: v for k, v in f["imu_model"].items() if v is not None}
    if not over:
        return base
    ds = ImuErrorModel.from_datasheet(**over)
    changes = {}
    key_to_field = {"gyro_bias_deg_h": "gyro_bias", "accel_bias_mg": "accel_bias",
                    "gyro_bias_instability_deg_h": "gyro_bias_instability",
                    "accel_bias_instability_ug": "accel_bias_instability",
                    "bias_correlation_time_s": "bias_correlation_time",
                    "gyro_arw_deg_sqrt_h": "gyro_arw", "accel_vrw_m_s_sqrt_h": "accel_vrw",
                    "gyro_scale_ppm": "gyro_scale", "accel_scale_ppm": "accel_scale"}
    for k in over:
        changes[key_to_field[k]] = getattr(ds, key_to_field[k])
    return base.scaled(**changes, name=f"{base.name}+overrides")


def _read_imu(job: Job) -> pd.DataFrame:
    spec = job["inputs"]["imu"]
    path = job.resolve(spec["path"])
    if path is None:
        raise ConfigError("no IMU file given", file=job.path, column="inputs.imu.path")
    fmt = spec["format"]
    if fmt == "rtklibexplorer":
        from .io.rtklibexplorer import read_rtklibexplorer_imu

        if spec["mounting_deg"] is None:
            raise ConfigError("the rtklibexplorer format needs the declared mounting",
                              file=job.path, column="inputs.imu.mounting_deg")
        return read_rtklibexplorer_imu(path, mounting_rpy_deg=spec["mounting_deg"],
                                       tag_path=job.resolve(spec["tag"]),
                                       time_offset=spec["time_offset"], rate_hz=spec["rate_hz"],
                                       gap_policy=gap_policy(job),
                                       duplicates=spec["duplicates"])
    if fmt == "kfgins":
        from .io.kfgins import read_kfgins_imu

        return read_kfgins_imu(path, gap_policy=gap_policy(job), duplicates=spec["duplicates"])
    if fmt == "native":
        from .io.tracks import read_trajectory_csv

        return read_trajectory_csv(path, required=(), duplicates=spec["duplicates"])
    from .io.imu_csv import read_imu_csv

    return read_imu_csv(path, columns=spec["columns"], gyro_unit=spec["gyro_unit"],
                        accel_unit=spec["accel_unit"], time_unit=spec["time_unit"],
                        time_offset=spec["time_offset"], axis_map=spec["axis_map"],
                        mounting_euler_deg=spec["mounting_deg"], sensor_axes=spec["sensor_axes"],
                        euler_convention=spec["mounting_convention"], rate_hz=spec["rate_hz"],
                        delimiter=spec["delimiter"], header=spec["header"],
                        gap_policy=gap_policy(job), duplicates=spec["duplicates"])


def _read_gnss(job: Job) -> pd.DataFrame | None:
    spec = job["inputs"]["gnss"]
    path = job.resolve(spec["path"])
    if path is None:
        return None
    fmt = spec["format"]
    if fmt == "rtklib_pos":
        from .io.rtklib import read_rtklib_pos

        g = read_rtklib_pos(path, duplicates=spec["duplicates"])
    elif fmt == "nmea":
        from .io.nmea import read_nmea

        g = read_nmea(path, date=spec["date"], duplicates=spec["duplicates"])
    elif fmt == "kfgins":
        from .io.kfgins import read_kfgins_gnss

        g = read_kfgins_gnss(path, duplicates=spec["duplicates"])
    else:
        from .io.tracks import read_trajectory_csv

        g = read_trajectory_csv(path, duplicates=spec["duplicates"])
    if spec["time_offset"]:
        g = g.set_axis(g.index + spec["time_offset"], axis=0)
    return g


def _read_reference(job: Job) -> pd.DataFrame | None:
    spec = job["inputs"]["reference"]
    path = job.resolve(spec["path"])
    if path is None:
        return None
    if spec["format"] == "rtklib_pos":
        from .io.rtklib import read_rtklib_pos

        ref = read_rtklib_pos(path)
        if spec["q"] is not None:
            ref = ref[ref["q"].isin([float(q) for q in spec["q"]])]
    else:
        from .io.reference import read_reference

        ref = read_reference(path, "kfgins-nav" if spec["format"] == "kfgins_nav" else "native")
    return ref


def load_inputs(job: Job, seed: int | None = None) -> Inputs:
    """Read (or simulate, for a job that carries a scenario) all inputs of a job."""
    la = np.asarray(job["inputs"]["gnss"]["lever_arm"], float)
    if la.shape != (3,):
        raise ConfigError("lever arm must have 3 elements", file=job.path,
                          column="inputs.gnss.lever_arm", found=list(la))
    if job.simulation and job["inputs"]["imu"]["path"] is None:
        from .simulate.scenario import simulate_scenario

        sim = simulate_scenario(dict(job.simulation), seed=seed)
        sim_la = np.asarray(job.simulation.get("gnss", {}).get("lever_arm", la), float)
        truth = sim.truth
        step = max(1, int(round(0.1 / np.median(np.diff(truth.index.to_numpy()[:100])))))
        sim_grade = job.simulation.get("imu", {}).get("grade")
        return Inputs(imu=sim.imu, gnss=sim.gnss, odometer=sim.odometer,
                      reference=truth.iloc[::step], reference_point="imu",
                      lever_arm=sim_la, truth=truth, source="simulation", seed=sim.seed,
                      imu_model=_imu_model(job, grade(sim_grade) if sim_grade else None))
    imu = _read_imu(job)
    gnss = _read_gnss(job)
    odo = None
    if job["inputs"]["odometer"]["path"] is not None:
        from .io.odometer import read_odometer

        odo = read_odometer(job.resolve(job["inputs"]["odometer"]["path"]),
                            kind=job["inputs"]["odometer"]["kind"])
    cp = None
    if job["inputs"]["control_points"]["path"] is not None:
        from .io.native import read_table

        cp = read_table(job.resolve(job["inputs"]["control_points"]["path"]),
                        required=["lat", "lon", "height"])
    return Inputs(imu=imu, gnss=gnss, odometer=odo, reference=_read_reference(job),
                  reference_point=job["inputs"]["reference"]["point"], control_points=cp,
                  lever_arm=la, imu_model=_imu_model(job, None))


# --- outages ------------------------------------------------------------------------------------
def outage_windows(job: Job, gnss: pd.DataFrame | None) -> list[tuple[float, float]]:
    """Outage windows of the job in its time base."""
    o = job["outages"]
    t_first = float(gnss.index[0]) if gnss is not None and len(gnss) else 0.0
    t_last = float(gnss.index[-1]) if gnss is not None and len(gnss) else 0.0
    off = t_first if o["relative_to"] == "first_gnss" else 0.0
    wins = [(off + float(a), off + float(b)) for a, b in o["windows"]]
    p = o["periodic"]
    if p["start"] is not None or p["length"] is not None:
        if p["start"] is None or p["length"] is None or p["gap"] is None:
            raise ConfigError("periodic outages need start, length and gap", file=job.path,
                              column="outages.periodic")
        if gnss is None:
            raise ConfigError("periodic outages need GNSS data", file=job.path,
                              column="outages.periodic")
        wins += periodic_windows(t_first, t_last, p["start"], p["length"], p["gap"],
                                 p["stop_before_end"])
    return sorted(wins)


# --- initialization -------------------------------------------------------------------------------
@dataclass
class Initialization:
    state: NavState
    method: str
    heading_source: str
    gyro_bias: np.ndarray | None = None
    att_std: tuple[float, float, float] = (np.radians(0.5), np.radians(0.5), np.radians(2.0))
    pos_std: float | tuple = 1.0
    vel_std: float = 0.1
    static_end: float | None = None
    levelled: bool = False  # roll/pitch from accelerometer levelling (tilt ~ accel bias)


def _mean_specific_force(win: pd.DataFrame) -> np.ndarray:
    """Mean specific force [m/s^2] of a rate or increment IMU window."""
    if ACCEL_COLS[0] in win.columns:
        return win[ACCEL_COLS].to_numpy().mean(0)
    t = win.index.to_numpy(float)
    return win[DV_COLS].to_numpy()[1:].sum(0) / max(t[-1] - t[0], 1e-9)


def _gnss_at(gnss: pd.DataFrame, t: float) -> np.ndarray:
    ti = gnss.index.to_numpy(float)
    return np.array([np.interp(t, ti, gnss[c].to_numpy(float)) for c in ("lat", "lon", "height")])


def _antenna_to_imu(llh: np.ndarray, C: np.ndarray, lever_arm: np.ndarray) -> np.ndarray:
    from .earth import enu_displacement_to_geodetic

    d = -(C @ lever_arm)
    dlat, dlon, dh = enu_displacement_to_geodetic(llh[0], llh[2], d[0], d[1], d[2])
    return llh + np.array([dlat, dlon, dh])


def initialize(job: Job, inputs: Inputs, model: ImuErrorModel) -> Initialization:
    """Initial nominal state of the filter (see the module docstring)."""
    ini = job["initialization"]
    imu, gnss = inputs.imu, inputs.gnss
    t0 = float(imu.index[0]) if ini["start_time"] is None else float(ini["start_time"])
    imu = imu.loc[t0:]
    method = ini["method"]
    given = [ini[k] for k in ("roll_deg", "pitch_deg", "heading_deg")]
    if gnss is None or not len(gnss):
        if inputs.truth is None:
            raise ConfigError("initialization needs GNSS (or a simulated truth) for the position",
                              file=job.path, column="inputs.gnss.path")
    def position_at(t, C):
        if gnss is not None and len(gnss):
            return _antenna_to_imu(_gnss_at(gnss, t), C, inputs.lever_arm)
        r = inputs.truth.iloc[inputs.truth.index.get_indexer([t], method="nearest")[0]]
        return np.array([r["lat"], r["lon"], r["height"]])

    pos_std = ini["position_std"]
    if pos_std is None:  # the GNSS sigmas of the start, per axis (east, north, up)
        cols = ("east_std", "north_std", "up_std")
        pos_std = tuple(float(np.nanmedian(gnss[c])) for c in cols) if gnss is not None and \
            all(c in gnss.columns for c in cols) else 1.0
    if method == "gnss_velocity":
        if gnss is None or "vel_e" not in gnss.columns:
            raise ConfigError("gnss_velocity initialization needs GNSS velocity", file=job.path,
                              column="initialization.method")
        sp = np.hypot(gnss["vel_e"].to_numpy(), gnss["vel_n"].to_numpy())
        k = np.nonzero((sp > ini["min_speed"]) & (gnss.index.to_numpy() >= t0))[0]
        if not k.size:
            raise ConfigError("GNSS never faster than min_speed", file=job.path,
                              column="initialization.min_speed", found=float(sp.max()))
        k = int(k[0])
        t_s = float(gnss.index[k])
        hdg = float(np.arctan2(gnss["vel_e"].iloc[k], gnss["vel_n"].iloc[k]))
        win = imu.loc[t_s - 0.5: t_s + 0.5]
        r, p = level(_mean_specific_force(win)) if given[0] is None else \
            (np.radians(given[0]), np.radians(given[1] or 0.0))
        from .attitude import euler_to_dcm

        C = euler_to_dcm(r, p, hdg)
        t_imu = float(imu.index[imu.index.get_indexer([t_s], method="nearest")[0]])
        vel = gnss[["vel_e", "vel_n", "vel_u"]].iloc[k].to_numpy(float)
        st = NavState(*position_at(t_imu, C), vel, C, t_imu)
        return Initialization(st, method, "gnss_velocity", pos_std=pos_std, vel_std=0.2,
                              att_std=(np.radians(2), np.radians(2), np.radians(5)))
    if method == "given":
        if any(v is None for v in given):
            raise ConfigError("given initialization needs roll_deg, pitch_deg and heading_deg",
                              file=job.path, column="initialization")
        r, p, h = np.radians(given)
        from .attitude import euler_to_dcm

        C = euler_to_dcm(r, p, h)
        st = NavState(*position_at(t0, C), np.zeros(3), C, t0)
        return Initialization(st, method, "given", pos_std=pos_std)
    # static
    win = imu.loc[: t0 + ini["static_duration"]]
    heading = None if given[2] is None else np.radians(given[2])
    src = "given" if heading is not None else ("gyrocompass" if can_gyrocompass(model, 0.0 if
                                               gnss is None else float(gnss["lat"].iloc[0]))
                                               else "gnss_course")
    lat_guess = float(gnss["lat"].iloc[0]) if gnss is not None and len(gnss) else \
        float(inputs.truth["lat"].iloc[0])
    res = coarse_align(win, lat_guess, 0.0, model=model,
                       heading=heading if heading is not None else 0.0,
                       heading_source="given" if src != "gyrocompass" else "gyrocompass",
                       max_accel_std=ini["static_max_accel_std"],
                       max_rate_std=np.radians(ini["static_max_rate_std_deg"]))
    w_mean = win[GYRO_COLS].to_numpy().mean(0) if GYRO_COLS[0] in win.columns else None
    t_end = res.time
    hdg = res.heading
    if job["filter"]["levelling_correlation"]:
        # the tilt error of levelling is the horizontal accelerometer bias over g, modelled as
        # a correlation with the bias states (FilterConfig.levelling_correlation): the tilt
        # sigma here is only the white-noise part (VRW over the window), floored at 0.02 deg
        T = max(float(win.index[-1] - win.index[0]), 1e-3)
        tilt = max(model.accel_vrw / np.sqrt(T) / 9.81, np.radians(0.02))
        tilt = (tilt, tilt)
    else:
        tilt = (max(res.roll_std, np.radians(0.1)), max(res.pitch_std, np.radians(0.1)))
    att_std = (*tilt, res.heading_std if np.isfinite(res.heading_std) else np.radians(5.0))
    if src == "gnss_course":
        hdg = _heading_from_course(imu, gnss, res, ini["min_speed"], w_mean)
        att_std = (att_std[0], att_std[1], np.radians(3.0))
    elif src == "gyrocompass":
        hdg = gyrocompass(w_mean, res.roll, res.pitch) if w_mean is not None else res.heading
    from .attitude import euler_to_dcm

    C = euler_to_dcm(res.roll, res.pitch, hdg)
    # the vehicle is still over the window, so the aligned attitude holds from its start: the
    # filter runs from there (covering the window, with ZUPT/ZARU if enabled)
    t_begin = float(win.index[0])
    st = NavState(*position_at(t_begin, C), np.zeros(3), C, t_begin)
    return Initialization(st, method, src, gyro_bias=None, att_std=att_std, pos_std=pos_std,
                          vel_std=0.02, static_end=t_end,
                          levelled=bool(job["filter"]["levelling_correlation"]))


def _heading_from_course(imu, gnss, res, min_speed, w_mean) -> float:
    if gnss is None or "vel_e" not in gnss.columns:
        raise ConfigError("the IMU cannot gyrocompass: give initialization.heading_deg or GNSS "
                          "velocity", column="initialization.heading_deg")
    sp = np.hypot(gnss["vel_e"].to_numpy(), gnss["vel_n"].to_numpy())
    k = np.nonzero((sp > min_speed) & (gnss.index.to_numpy() > res.time))[0]
    if not k.size:
        raise ConfigError("GNSS never faster than min_speed: cannot get the heading",
                          column="initialization.min_speed")
    k = int(k[0])
    tm = float(gnss.index[k])
    course = float(np.arctan2(gnss["vel_e"].iloc[k], gnss["vel_n"].iloc[k]))
    seg = imu.loc[res.time: tm]
    if w_mean is not None and GYRO_COLS[0] in seg.columns:  # remove the static gyro bias
        seg = seg.copy()
        seg[GYRO_COLS] = seg[GYRO_COLS].to_numpy() - w_mean
    lat = float(gnss["lat"].iloc[0])
    x = NavState.from_euler(lat, float(gnss["lon"].iloc[0]), float(gnss["height"].iloc[0]),
                            (0, 0, 0), res.roll, res.pitch, 0.0, time=res.time)
    m = mechanize(seg, x, fix_height=True)
    return float(np.mod(course - m["heading"].iloc[-1], 2 * np.pi))


# --- measurements -----------------------------------------------------------------------------------
class SpeedGatedZupt(Zupt):
    """ZUPT applied only while the nominal speed is below ``max_speed``.

    An IMU stillness detector cannot tell steady straight motion from rest (both give constant
    specific force and no rotation; only vibration differs), so a vehicle at constant speed can
    be flagged still. The nominal speed of the filter (GNSS-aided, or a short dead-reckoning
    extrapolation during outages) resolves that ambiguity.
    """

    def __init__(self, times, std, max_speed: float, **kw):
        super().__init__(times, std=std, **kw)
        self.max_speed = float(max_speed)

    def evaluate(self, i, nav):
        if np.linalg.norm(nav.vel) > self.max_speed:
            return None
        return super().evaluate(i, nav)


class SpeedGatedZaru(Zaru):
    """ZARU applied only while the nominal speed is below ``max_speed`` (see SpeedGatedZupt)."""

    def __init__(self, times, max_speed: float, **kw):
        super().__init__(times, **kw)
        self.max_speed = float(max_speed)

    def evaluate(self, i, nav):
        if np.linalg.norm(nav.vel) > self.max_speed:
            return None
        return super().evaluate(i, nav)


def stillness_times(job: Job, imu: pd.DataFrame) -> np.ndarray:
    """Times (at the ZUPT interval) when the IMU is still, from the detector and/or declared
    static intervals."""
    a = job["aiding"]
    t = imu.index.to_numpy(float)
    still = np.zeros(t.size, bool)
    if a["detector"] or not a["static_intervals"]:
        from .detect import DetectorConfig, detect_stillness

        cfg = DetectorConfig.from_dict(a["detector"]) if a["detector"] else \
            DetectorConfig(method="amv", window=0.5, threshold=0.1, min_stance=1.0, margin=0.3)
        still |= detect_stillness(imu, cfg).still.to_numpy(bool)
    for a0, a1 in a["static_intervals"] or []:
        still |= (t >= a0) & (t <= a1)
    ts = t[still]
    if not ts.size:
        return ts
    step = a["zupt_interval"]
    keep = np.concatenate([[True], np.diff(np.floor((ts - ts[0]) / step)) > 0])
    return ts[keep]


def build_measurements(job: Job, inputs: Inputs, windows, imu: pd.DataFrame) -> list:
    """Aiding measurement models of the job (GNSS with outages removed, ZUPT, ZARU, NHC, CUPT,
    odometer)."""
    a = job["aiding"]
    out = []
    gnss = inputs.gnss
    if gnss is not None and len(gnss):
        g = check_gnss_in_imu_span(gnss, imu, policy="trim")  # warns, names the file/lines
        # the initial position comes from the GNSS at the first IMU time: an epoch there would
        # be used twice (initial state and update), with correlated errors
        g = g[g.index > imu.index[0] + 1e-6]
        g = g[~in_windows(g.index.to_numpy(float), windows)]
        scale = {int(float(k)): float(v) for k, v in a["q_scale"].items()}
        use_q = list(scale) if "q" in g.columns else None
        if a["gnss_position"]:
            std = a["gnss_position_std"]
            if std is not None:
                g = g.drop(columns=[c for c in GnssPosition.STD_COLS if c in g.columns])
            kw = {"std": std} if std is not None else {}
            if a["gnss_std_scale"] != 1.0 and std is None:
                g = g.copy()
                for c in GnssPosition.STD_COLS:
                    g[c] = g[c] * a["gnss_std_scale"]
            out.append(GnssPosition(g, lever_arm=inputs.lever_arm, std_scale=scale if use_q
                                    else None, use_q=use_q, min_std=a["gnss_min_std"], **kw))
        if a["gnss_velocity"]:
            if "vel_e" not in g.columns:
                raise InputFormatError("GNSS velocity aiding requested but the GNSS data has no "
                                       "velocity", column="vel_e")
            std = a["gnss_velocity_std"]
            gv = g.drop(columns=[c for c in ("vel_e_std", "vel_n_std", "vel_u_std")
                                 if c in g.columns]) if std is not None else g
            out.append(GnssVelocity(gv, lever_arm=inputs.lever_arm,
                                    std_scale=scale if use_q else None, use_q=use_q,
                                    **({"std": std} if std is not None else {})))
    if a["zupt"] or a["zaru"]:
        ts = stillness_times(job, imu)
        if ts.size:
            vmax = a["zupt_max_speed"]
            if a["zupt"]:
                out.append(SpeedGatedZupt(ts, a["zupt_std"], vmax) if vmax else
                           Zupt(ts, std=a["zupt_std"]))
            if a["zaru"]:
                out.append(SpeedGatedZaru(ts, vmax) if vmax else Zaru(ts))
    if a["nhc"]:
        t = imu.index.to_numpy(float)
        tn = t[0] + np.arange(1, int((t[-1] - t[0]) / a["nhc_interval"])) * a["nhc_interval"]
        out.append(BodyVelocity(tn, 0.0, axes=(0, 2), std=a["nhc_std"], name="nhc",
                                misalignment_state="nhc_misalignment" if a["nhc_misalignment"]
                                else None))
    if a["cupt"]:
        if inputs.control_points is None:
            raise ConfigError("CUPT needs inputs.control_points.path", file=job.path,
                              column="aiding.cupt")
        out.append(Cupt.from_table(inputs.control_points,
                                   **({} if "east_std" in inputs.control_points.columns else
                                      {"std": job["inputs"]["control_points"]["std"]})))
    if a["odometer"]:
        if inputs.odometer is None or "speed" not in inputs.odometer.columns:
            raise ConfigError("odometer aiding needs an odometer speed table", file=job.path,
                              column="aiding.odometer")
        o = inputs.odometer
        o = o[(o.index > imu.index[0]) & (o.index <= imu.index[-1])]
        out.append(BodyVelocity(o.index.to_numpy(float), o["speed"].to_numpy(float), axes=(1,),
                                std=a["odometer_std"], scale_state="odometer_scale",
                                name="odometer"))
    return out


def filter_config(job: Job, model: ImuErrorModel, init: Initialization) -> FilterConfig:
    f = job["filter"]
    return FilterConfig(
        imu_model=model, bias_model=f["bias_model"], scale_factors=f["scale_factors"],
        propagation_interval=f["propagation_interval"], epoch_interval=f["epoch_interval"],
        discretization=f["discretization"], gate_probability=f["gate_probability"] or None,
        smoother=f["smoother"], initial_pos_std=init.pos_std, initial_vel_std=init.vel_std,
        initial_att_std=init.att_std, coning=f["coning"],
        levelling_correlation=init.levelled,
        gate_recovery=f["gate_recovery"] or None, nis_window=f["nis_window"] or None,
        nis_bound=f["nis_bound"],
        gyro_bias=None if init.gyro_bias is None else tuple(init.gyro_bias))


# --- run --------------------------------------------------------------------------------------------
@dataclass
class JobResult:
    """Everything a run produced (in memory)."""

    job: Job
    inputs: Inputs
    init: Initialization
    windows: list
    filter: FilterResult
    evaluation: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)


def evaluate_solution(sol: pd.DataFrame, inputs: Inputs, windows, job: Job) -> dict:
    """Errors of one solution against the job's reference (None without a reference)."""
    if inputs.reference is None or sol is None:
        return {}
    pt = move_point(sol, inputs.lever_arm) if inputs.reference_point == "antenna" else sol
    err = position_errors(pt, inputs.reference)
    for s in ("east_std", "north_std", "up_std"):
        if s in sol.columns:
            err[s] = np.interp(err.index.to_numpy(float), sol.index.to_numpy(float),
                               sol[s].to_numpy(float))
    ev = job["evaluation"]
    t_first = float(inputs.gnss.index[0]) if inputs.gnss is not None and len(inputs.gnss) \
        else float(inputs.reference.index[0])
    table, summary = outage_metrics(err, windows, t_first=t_first,
                                    settle_time=ev["settle_time"], guard_time=ev["guard_time"])
    hz = err["horizontal"].dropna()
    summary["rms_h_m"] = float(np.sqrt(np.mean(hz.to_numpy() ** 2))) if len(hz) else float("nan")
    summary["max_h_m"] = float(hz.max()) if len(hz) else float("nan")
    summary["n_reference"] = int(len(err))
    summary["n_covered"] = int(err["horizontal"].notna().sum())
    return {"errors": err, "outages": table, "summary": summary}


def run_job(job: Job, *, progress: bool | None = None, seed: int | None = None,
            inputs: Inputs | None = None) -> JobResult:
    """Run a validated job in memory (no files written)."""
    t_start = _time.perf_counter()
    inputs = load_inputs(job, seed) if inputs is None else inputs
    t_read = _time.perf_counter() - t_start
    # duplicates, gaps and segments of the table actually processed (policies.py)
    inputs.imu, imu_report = check_imu_table(inputs.imu, gap_policy(job),
                                             job["inputs"]["imu"]["duplicates"])
    model = inputs.imu_model or _imu_model(job, None)
    windows = outage_windows(job, inputs.gnss)
    preprocessing = {}
    if job["inputs"]["imu"]["estimate_time_offset"] and inputs.gnss is not None:
        dt, info = estimate_time_offset(inputs.imu, inputs.gnss, windows)
        inputs.imu = shift_time(inputs.imu, dt)
        imu_report = shift_report(imu_report, dt)
        inputs.imu.attrs.update({k: imu_report[k] for k in ("gaps", "segments",
                                                            "dropped_duplicates")})
        preprocessing["imu_time_offset_estimated_s"] = dt
        preprocessing["imu_time_offset_info"] = info
    if len(imu_report["segments"]) > 1:  # gap_policy = "split" and long gaps
        out = run_segments(job, inputs, windows, imu_report["segments"], progress=progress,
                           preprocessing=preprocessing)
        out.summary["imu"] = imu_report
        return out
    other = None
    if job["process"]["preset"] == "foot":
        other = _run_foot(job, inputs, windows, t_start)
    elif job["filter"]["process_model"] == "riss":
        other = _run_riss(job, inputs, windows, model, t_start)
    if other is not None:
        other.summary.setdefault("imu", imu_report)
        return other
    init = initialize(job, inputs, model)
    if job["filter"]["noise_from_static"] and init.static_end is not None:
        model = with_static_noise(model, inputs.imu.loc[:init.static_end])
        preprocessing["gyro_arw_deg_sqrt_h"] = float(np.degrees(model.gyro_arw) * 60)
        preprocessing["accel_vrw_m_s_sqrt_h"] = float(model.accel_vrw * 60)
    imu = inputs.imu.loc[init.state.time:]
    meas = build_measurements(job, inputs, windows, imu)
    cfg = filter_config(job, model, init)
    if job["inputs"]["imu"]["gap_noise"]:
        cfg.extra_noise = gap_noise(imu, imu_report["gaps"])  # bridged IMU gaps
    show = job["outputs"]["progress"] if progress is None else progress
    res = run_filter(imu, init.state, meas, cfg, progress=show)
    extra = {"imu": imu_report, "preprocessing": preprocessing}
    return _job_result(job, inputs, init, windows, res, meas, model, len(imu), t_start,
                       {"read": t_read}, extra)


def _job_result(job: Job, inputs: Inputs, init: Initialization, windows, res, meas,
                model: ImuErrorModel, n_imu: int, t_start: float, timing_extra: dict,
                extra: dict) -> JobResult:
    """Evaluate a finished filter run and build its :class:`JobResult` with the summary."""
    out = JobResult(job, inputs, init, windows, res)
    for name in ("forward", "smoothed"):
        ev = evaluate_solution(getattr(res, name), inputs, windows, job)
        if ev:
            out.evaluation[name] = ev
    timing = {**res.timing, **timing_extra, "job_total": _time.perf_counter() - t_start}
    name = job["job"]["name"]
    if name == "job" and job.simulation.get("scenario", {}).get("name"):
        name = job.simulation["scenario"]["name"]
    r, p, h = init.state.euler
    out.summary = {
        "job": name, "source": inputs.source, "seed": inputs.seed,
        "process_model": job["filter"]["process_model"],
        "complete": bool(res.complete), "error": None if res.error is None else str(res.error),
        "stopped_at": None if res.complete or res.final is None else float(res.final.time),
        "imu_samples": int(n_imu), "initialization": {
            "method": init.method, "heading_source": init.heading_source,
            "time": init.state.time, "roll_deg": float(np.degrees(r)),
            "pitch_deg": float(np.degrees(p)), "heading_deg": float(np.degrees(h))},
        "measurements": {m.name: int(len(m)) for m in meas},
        "rejected": res.rejected.groupby("type").size().astype(int).to_dict()
        if len(res.rejected) else {},
        "outages": [list(w) for w in windows],
        "imu_model": model.name,
        **extra,
        "timing_s": timing,
        "evaluation": {k: v["summary"] for k, v in out.evaluation.items()},
    }
    return out


@dataclass
class PresetResult:
    """Filter-like result of a preset process (same attributes the outputs use)."""

    forward: pd.DataFrame
    smoothed: pd.DataFrame | None
    innovations: pd.DataFrame
    rejected: pd.DataFrame
    timing: dict
    complete: bool = True
    error: Exception | None = None


def _run_foot(job: Job, inputs: Inputs, windows, t_start: float) -> JobResult:
    """Foot-mounted pedestrian INS (:mod:`insgnss.foot`): compiled ZUPT/ZARU filter and
    smoother; heading unobservable, so it is given (``[foot] heading``, default 0)."""
    from .foot import FootConfig, run_foot_ins

    cfg = FootConfig.from_dict(job["foot"])
    ini = job["initialization"]
    lat = np.radians(ini["lat_deg"] or 0.0)
    lon = np.radians(ini["lon_deg"] or 0.0)
    h = ini["height"] or 0.0
    c0 = _time.perf_counter()
    fr = run_foot_ins(inputs.imu, cfg, lat=lat, lon=lon, height=h)
    run_s = _time.perf_counter() - c0
    inn = fr.innovations.reset_index()
    inn = inn.rename(columns={inn.columns[0]: "time"})
    inn.insert(1, "type", "zupt")
    inn["accepted"] = True
    res = PresetResult(forward=fr.forward.join(fr.std).join(fr.biases),
                       smoothed=fr.trajectory if cfg.smooth else None, innovations=inn,
                       rejected=inn.iloc[:0], timing={"total": run_s})
    init = Initialization(fr.initial, "foot_levelling", "given")
    out = JobResult(job, inputs, init, windows, res)
    for name in ("forward", "smoothed"):
        ev = evaluate_solution(getattr(res, name), inputs, windows, job)
        if ev:
            out.evaluation[name] = ev
    out.summary = {
        "job": job["job"]["name"], "source": inputs.source, "complete": True, "error": None,
        "preset": "foot", "imu_samples": int(len(inputs.imu)), "zupt_updates": fr.n_updates,
        "initialization": {"method": "foot_levelling", "heading_source": "given",
                           "time": fr.initial.time,
                           "roll_deg": float(np.degrees(fr.initial.euler[0])),
                           "pitch_deg": float(np.degrees(fr.initial.euler[1])),
                           "heading_deg": float(np.degrees(fr.initial.euler[2]))},
        "measurements": {"zupt": int(fr.stillness.still.sum())}, "rejected": {},
        "timing_s": {"total": run_s, "job_total": _time.perf_counter() - t_start},
        "evaluation": {k: v["summary"] for k, v in out.evaluation.items()},
    }
    return out


def _run_riss(job: Job, inputs: Inputs, windows, model: ImuErrorModel, t_start: float
              ) -> JobResult:
    """``[filter] process_model = "riss"``: the same initialization, aiding, evaluation and
    summary as the strapdown job, with the RISS process model (:mod:`insgnss.filter.riss_model`);
    the job's odometer is the process input (``aiding.odometer`` would use it twice)."""
    from .filter.riss_model import RissConfig, run_riss_filter

    if inputs.odometer is None or not len(inputs.odometer):
        raise ConfigError("the RISS process model needs an odometer (inputs.odometer.path or a "
                          "simulated [odometer])", file=job.path, column="inputs.odometer.path")
    if job["aiding"]["odometer"]:
        raise ConfigError("with process_model = \"riss\" the odometer is the process input; "
                          "switch aiding.odometer off", file=job.path, column="aiding.odometer")
    init = initialize(job, inputs, model)
    odo = inputs.odometer
    t_odo = odo.index.to_numpy(float)
    imu = inputs.imu.loc[max(init.state.time, t_odo[0]):t_odo[-1]]
    if len(imu) < 2:
        raise ConfigError("the odometer does not overlap the IMU data", file=job.path,
                          column="inputs.odometer.path")
    if float(imu.index[0]) != init.state.time:
        init.state = init.state.copy()
        init.state.time = float(imu.index[0])
    meas = build_measurements(job, inputs, windows, imu)
    cfg = filter_config(job, model, init)
    # aiding.odometer_std is the odometer speed noise; filter.scale_factors estimates the
    # vertical gyro scale factor
    rcfg = RissConfig(odometer_speed_std=float(job["aiding"]["odometer_std"]),
                      gyro_scale=bool(job["filter"]["scale_factors"]), **job["filter"]["riss"])
    res = run_riss_filter(imu, odo, init.state, meas, cfg, rcfg)
    return _job_result(job, inputs, init, windows, res, meas, model, len(imu), t_start, {}, {})


# --- outputs ----------------------------------------------------------------------------------------
#: every file name write_outputs may produce (a previous run's files that a new run does not
#: produce are removed when the new set is committed, so a folder never mixes two runs)
OUTPUT_NAMES = tuple(
    [f"{t}{ext}" for t in ("forward", "smoothed")
     for ext in (".csv", ".nav", ".kml", ".geojson", "_eval.csv")]
    + ["innovations.csv", "rejected.csv", "outages_forward.csv", "outages_smoothed.csv",
       "summary.json", "report.html"])


def write_outputs(result: JobResult, out_dir: str | Path | None = None) -> dict[str, Path]:
    """Write trajectories, logs, summary and report of a run; returns the paths by name.

    The files form one set (:class:`insgnss.io.outputset.OutputSet`): they are written into a
    hidden staging folder and moved onto their final names together at the end, so an
    interrupted run leaves the previous outputs complete, or (interrupted during the final
    renames) a set marked by an ``INCOMPLETE`` file. A run whose filter stopped early writes
    what it computed and keeps ``INCOMPLETE`` (with the reason; ``summary.json`` has
    ``"complete": false``, the error and ``"stopped_at"``). No output may overwrite an input.
    """
    from .io.native import atomic_write, write_table
    from .io.outputset import MARKER, OutputSet

    job = result.job
    out = Path(out_dir) if out_dir is not None else job.output_dir
    complete = bool(result.summary.get("complete", result.filter.complete))
    with OutputSet(out, protect=job.input_paths(), stale=OUTPUT_NAMES + (MARKER,)) as outs:
        dest = outs.path
        point = job["outputs"]["point"]
        tables = {"forward": result.filter.forward, "smoothed": result.filter.smoothed}
        formats = job["outputs"]["formats"]
        for name, df in tables.items():
            if df is None:
                continue
            if point == "antenna":
                df = move_point(df, result.inputs.lever_arm)
            if "csv" in formats:
                write_table(df, dest(f"{name}.csv"))
            if "nav" in formats:
                from .io.kfgins import write_kfgins_nav

                write_kfgins_nav(df, dest(f"{name}.nav"))
            if "kml" in formats:
                from .io.tracks import write_kml

                write_kml({name: df}, dest(f"{name}.kml"))
            if "geojson" in formats:
                from .io.tracks import write_geojson

                write_geojson({name: df}, dest(f"{name}.geojson"))
            if "eval" in formats:
                from .io.tracks import write_eval_csv

                write_eval_csv(move_point(tables[name], result.inputs.lever_arm),
                               dest(f"{name}_eval.csv"))
        for name in ("innovations", "rejected"):
            log = getattr(result.filter, name)
            write_table(log.set_index("time") if "time" in log.columns else log,
                        dest(f"{name}.csv"))
        for name, ev in result.evaluation.items():
            if len(ev["outages"]):
                table = ev["outages"]
                atomic_write(dest(f"outages_{name}.csv"),
                             lambda p, table=table: table.to_csv(p, index=False))
        summary = dict(result.summary)
        summary["files"] = sorted(outs.names + ["summary.json"]
                                  + (["report.html"] if job["outputs"]["report"] else [])
                                  + ([] if complete else [MARKER]))
        from .io.native import atomic_write_text

        atomic_write_text(dest("summary.json"), json.dumps(jsonable(summary), indent=2) + "\n")
        if job["outputs"]["report"]:
            from .report import write_report

            write_report(result, dest("report.html"))
        reason = "" if complete else (
            f"The filter stopped early at t = {summary.get('stopped_at')} s: "
            f"{summary.get('error')}\nThe trajectories and logs end there (summary.json has "
            '"complete": false).')
        return outs.commit(complete=complete, reason=reason)




def process(job: Job, out_dir: str | Path | None = None, *, progress: bool | None = None
            ) -> tuple[JobResult, dict[str, Path]]:
    """Run a job and write its outputs."""
    res = run_job(job, progress=progress)
    return res, write_outputs(res, out_dir)


__all__ = ["Inputs", "Initialization", "JobResult", "build_measurements", "evaluate_solution",
           "filter_config", "initialize", "load_inputs", "outage_windows", "process", "run_job",
           "write_outputs"]
