"""Job files: one TOML file describes one processing run end to end (schema in docs/jobs.md).

The loader checks every key against a declarative schema: an unknown key or a value of the wrong
type is a :class:`~insgnss.errors.ConfigError` that names the file and the dotted key
(``inputs.imu.gyro_unit``). Paths are resolved relative to the job file. Degrees appear only
in keys ending in ``_deg``; everything else is SI.

A job file may also carry simulation tables (``scenario``, ``trajectory``, ``imu``, ``gnss``...)
when it is a scenario for :mod:`insgnss.simulate`; those are validated by the simulator and
passed through here untouched (:data:`SIMULATION_TABLES`).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import ConfigError

_ANY = object()
_NUM = (int, float)


def _spec(kind, default=None, doc: str = "", choices=None):
    return {"type": kind, "default": default, "doc": doc, "choices": choices}


#: Schema: table -> key -> spec. A spec whose type is ``dict`` with a ``"keys"`` entry is a
#: sub-table. ``_ANY`` accepts any TOML value.
SCHEMA: dict[str, Any] = {
    "job": {
        "name": _spec(str, "job", "run name used in reports"),
        "description": _spec(str, "", "free text"),
        "time_base": _spec(str, "gps", "time base of the job: gps, sow, run",
                           choices=["gps", "sow", "run", "unspecified"]),
    },
    "inputs": {
        "imu": {
            "format": _spec(str, "csv", "csv, native, kfgins, rtklibexplorer",
                            choices=["csv", "native", "kfgins", "rtklibexplorer"]),
            "path": _spec(str, None, "IMU file"),
            "tag": _spec(str, None, "RTKLIB .tag file (rtklibexplorer format)"),
            "columns": _spec(dict, None, "slot -> column name or index (csv)"),
            "gyro_unit": _spec(str, "rad/s"),
            "accel_unit": _spec(str, "m/s^2"),
            "time_unit": _spec(str, "s", "s, ms, us, ns, or sample (a sample index at the "
                               "declared rate_hz)", choices=["s", "ms", "us", "ns", "sample"]),
            "time_offset": _spec(_NUM, 0.0, "added to the IMU time [s]"),
            "estimate_time_offset": _spec(bool, False, "estimate a further IMU-GNSS offset from "
                                          "gyro yaw rate vs GNSS course rate (land vehicles)"),
            "axis_map": _spec(str, None, 'sensor -> body axis map, e.g. "y,x,-z"'),
            "mounting_deg": _spec(list, None, "sensor mounting roll, pitch, yaw [deg]"),
            "mounting_convention": _spec(str, "active", choices=["active", "passive"]),
            "sensor_axes": _spec(str, "rfu", choices=["rfu", "frd"]),
            "rate_hz": _spec(_NUM, None, "declared IMU rate (checked)"),
            "delimiter": _spec(str, ","),
            "header": _spec(bool, True),
            "header_rows": _spec(int, 1, "header lines (csv); with more than one a column is "
                                 "named by its levels joined with '_'"),
            "gap_policy": _spec(str, "error", "gaps longer than max_gap: stop the run, bridge "
                                "them, or process the segments separately (docs/jobs.md, "
                                "Robustness)", choices=["error", "bridge", "split"]),
            "max_gap": _spec(_NUM, 1.0, "longest gap bridged with a warning [s]"),
            "gap_noise": _spec(bool, True, "add process noise for the motion missed in bridged "
                               "gaps (rate tables; insgnss.policies.gap_noise)"),
            "duplicates": _spec(str, "drop", "repeated time stamps: drop with a warning (first "
                                "kept) or stop", choices=["drop", "error"]),
        },
        "gnss": {
            "format": _spec(str, "rtklib_pos", choices=["rtklib_pos", "nmea", "kfgins", "native"]),
            "path": _spec(str, None),
            "lever_arm": _spec(list, [0.0, 0.0, 0.0], "IMU -> antenna, body RFU [m]"),
            "time_offset": _spec(_NUM, 0.0, "added to the GNSS time [s]"),
            "use_velocity": _spec(bool, False, "also use the velocity columns"),
            "date": _spec(str, None, "date for NMEA without RMC (YYYY-MM-DD)"),
            "duplicates": _spec(str, "drop", "repeated epochs: drop with a warning (first kept) "
                                "or stop", choices=["drop", "error"]),
        },
        "odometer": {
            "format": _spec(str, "native", choices=["native", "csv"]),
            "path": _spec(str, None),
            "kind": _spec(str, "speed", choices=["speed", "distance"]),
            "time_offset": _spec(_NUM, 0.0),
        },
        "reference": {
            "format": _spec(str, "rtklib_pos", choices=["rtklib_pos", "kfgins_nav", "native"]),
            "path": _spec(str, None),
            "point": _spec(str, "antenna", "which point the reference measures",
                           choices=["antenna", "imu"]),
            "q": _spec(list, None, "keep only these RTKLIB quality flags (e.g. [1])"),
        },
        "control_points": {
            "path": _spec(str, None, "CUPT points: native CSV time, lat_deg, lon_deg, height"),
            "std": _spec(_NUM, 0.02, "default point sigma [m]"),
        },
    },
    "process": {
        "preset": _spec(str, "standard", "standard: the error-state filter with the aiding "
                        "below; foot: foot-mounted pedestrian ZUPT/ZARU INS ([foot] table, "
                        "docs/zupt.md)", choices=["standard", "foot"]),
    },
    "foot": _spec(dict, {}, "foot-mounted settings (insgnss.foot.FootConfig fields, with a "
                  "[foot.detector] sub-table); checked by FootConfig"),
    "initialization": {
        "lat_deg": _spec(_NUM, None, "given start latitude (jobs without GNSS)"),
        "lon_deg": _spec(_NUM, None, "given start longitude (jobs without GNSS)"),
        "height": _spec(_NUM, None, "given start ellipsoidal height [m]"),
        "method": _spec(str, "static", "static, gnss_velocity or given",
                        choices=["static", "gnss_velocity", "given"]),
        "static_duration": _spec(_NUM, 30.0, "static window at the start [s]"),
        "static_max_accel_std": _spec(_NUM, 0.5, "stillness limit of the static window "
                                      "(specific-force variation, m/s^2; engine vibration)"),
        "static_max_rate_std_deg": _spec(_NUM, 5.0, "stillness limit of the static window "
                                         "(angular-rate variation, deg/s)"),
        "heading_deg": _spec(_NUM, None, "given heading (static with consumer IMU, or given)"),
        "roll_deg": _spec(_NUM, None),
        "pitch_deg": _spec(_NUM, None),
        "min_speed": _spec(_NUM, 3.0, "speed for GNSS-velocity heading [m/s]"),
        "start_time": _spec(_NUM, None, "start processing here [s, job time base]"),
        "position_std": _spec(_NUM, None, "initial position sigma [m] (default: GNSS)"),
        "velocity_std": _spec(_NUM, 0.1),
        "attitude_std_deg": _spec(list, None, "initial roll, pitch, heading sigma [deg]"),
    },
    "aiding": {
        "gnss_position": _spec(bool, True),
        "gnss_velocity": _spec(bool, False),
        "gnss_position_std": _spec(_NUM, None, "override per-epoch std [m]"),
        "gnss_velocity_std": _spec(_NUM, None, "override per-epoch std [m/s]"),
        "gnss_std_scale": _spec(_NUM, 1.0, "multiplies the file's std"),
        "gnss_min_std": _spec(_NUM, 0.005, "floor of the position std [m]"),
        "q_scale": _spec(dict, {"1": 1.0, "2": 3.0, "3": 1.0, "4": 1.0, "5": 1.0, "6": 1.0},
                         "std multiplier per RTKLIB Q flag (1 fix, 2 float, 3 SBAS, 4 DGPS, "
                         "5 single, 6 PPP; a flag not listed drops its epochs); float "
                         "solutions' std are optimistic"),
        "zupt": _spec(bool, False),
        "zaru": _spec(bool, False),
        "zupt_std": _spec(_NUM, 0.02),
        "zupt_interval": _spec(_NUM, 0.1, "ZUPT update interval during stillness [s]"),
        "zupt_max_speed": _spec(_NUM, 1.0, "apply ZUPT/ZARU only below this nominal speed "
                                "[m/s] (0: always; vehicles at constant speed look still)"),
        "detector": _spec(dict, {}, "stillness detector settings (docs/zupt.md)"),
        "static_intervals": _spec(list, None, "declared still intervals [[t0, t1], ...]"),
        "nhc": _spec(bool, False, "non-holonomic constraint (land vehicles)"),
        "nhc_std": _spec(list, [0.1, 0.1], "lateral, vertical body velocity sigma [m/s]"),
        "nhc_interval": _spec(_NUM, 0.25, "NHC update interval [s]: the constraint's violations "
                              "(suspension, vibration, slip) are correlated in time, so faster "
                              "updates over-weight it"),
        "nhc_min_speed": _spec(_NUM, 0.5, "apply NHC above this speed [m/s]"),
        "nhc_misalignment": _spec(bool, False, "estimate IMU-to-vehicle pitch/yaw misalignment"),
        "cupt": _spec(bool, False),
        "odometer": _spec(bool, False),
        "odometer_std": _spec(_NUM, 0.1),
    },
    "outages": {
        "windows": _spec(list, [], "explicit [[start, end], ...] [s, job time base]"),
        "relative_to": _spec(str, "first_gnss", choices=["first_gnss", "absolute"]),
        "periodic": {
            "start": _spec(_NUM, None, "first outage start after the first GNSS epoch [s]"),
            "length": _spec(_NUM, None, "outage length [s]"),
            "gap": _spec(_NUM, None, "GNSS time between outages [s]"),
            "stop_before_end": _spec(_NUM, 0.0, "no outage starts later than this before the end"),
        },
    },
    "filter": {
        "process_model": _spec(str, "strapdown", choices=["strapdown", "riss"]),
        "propagation_interval": _spec(_NUM, 0.1),
        "epoch_interval": _spec(_NUM, 1.0),
        "discretization": _spec(str, "second_order", choices=["second_order", "vanloan"]),
        "gate_probability": _spec(_NUM, 0.9999, "chi-square gate of every measurement (0: off)"),
        "gate_recovery": _spec(_NUM, 5.0, "after this many seconds of continuous rejection of "
                               "one measurement type the covariance is inflated and the "
                               "measurement accepted [s] (0: never)"),
        "nis_window": _spec(_NUM, 30.0, "runaway-NIS check window [s] (0: off)"),
        "nis_bound": _spec(_NUM, 25.0, "stop when the window median of NIS/dof of one "
                           "measurement type exceeds this"),
        "bias_model": _spec(str, "random_walk", "random_walk: turn-on bias + random walk "
                            "from the instability (robust); gauss_markov: the whole bias is a "
                            "zero-mean first-order GM process (only after a calibration removed "
                            "the turn-on bias)",
                            choices=["gauss_markov", "random_walk", "random_constant"]),
        "scale_factors": _spec(bool, False),
        "smoother": _spec(bool, True),
        "coning": _spec(bool, False, "two-sample coning/sculling correction of the increments "
                        "(strapdown and foot; for integrated increments, not for the exact "
                        "duals a simulation makes)"),
        "levelling_correlation": _spec(bool, False, "static initialization: correlate the "
                                       "levelled tilt with the accelerometer-bias states in P0 "
                                       "(FilterConfig.levelling_correlation; experimental)"),
        "noise_from_static": _spec(bool, False, "raise ARW/VRW to the noise measured in the "
                                   "static initialization window (vibration)"),
        "imu_grade": _spec(str, None, "IMU error model for the filter: navigation, tactical, "
                           "consumer/mems (default: the scenario's [imu] for simulated jobs, "
                           "else tactical)"),
        "riss": {
            "odometer_scale_std": _spec(_NUM, 0.02, "RISS: initial odometer scale-factor sigma"),
            "odometer_scale_psd": _spec(_NUM, 0.0, "RISS: its random-walk PSD [1/s]"),
            "slip_std": _spec(_NUM, 0.02, "RISS: wheel slip / speed model sigma [m/s]"),
            "split_turn_on": _spec(bool, True, "RISS: separate random-constant turn-on biases"),
            "azimuth": _spec(str, "exact", "RISS azimuth equation (docs/riss.md)",
                             choices=["exact", "level", "projected"]),
            "coriolis": _spec(bool, True, "RISS: Earth-rate / Coriolis terms"),
            "window": _spec(_NUM, 1.0, "RISS: pitch/roll smoothing window [s]"),
        },
        "imu_model": {
            "gyro_bias_deg_h": _spec(_NUM, None, "overrides of the grade, datasheet units"),
            "accel_bias_mg": _spec(_NUM, None),
            "gyro_bias_instability_deg_h": _spec(_NUM, None),
            "accel_bias_instability_ug": _spec(_NUM, None),
            "bias_correlation_time_s": _spec(_NUM, None),
            "gyro_arw_deg_sqrt_h": _spec(_NUM, None),
            "accel_vrw_m_s_sqrt_h": _spec(_NUM, None),
            "gyro_scale_ppm": _spec(_NUM, None),
            "accel_scale_ppm": _spec(_NUM, None),
        },
    },
    "evaluation": {
        "enabled": _spec(bool, True),
        "settle_time": _spec(_NUM, 10.0, "ignore the first seconds [s]"),
        "guard_time": _spec(_NUM, 1.0, "skip after each outage end in the non-outage RMS [s]"),
    },
    "outputs": {
        "dir": _spec(str, "out", "output folder (relative to the job file)"),
        "report": _spec(bool, True, "write report.html"),
        "formats": _spec(list, ["csv"], "trajectory formats: csv, nav, kml, geojson"),
        "figures": _spec(list, [], "report figures also written as fig_<name>.<ext> beside "
                         "the report", choices=["png", "pdf", "svg"]),
        "point": _spec(str, "imu", "trajectory point written: imu or antenna",
                       choices=["imu", "antenna"]),
        "progress": _spec(bool, True),
    },
}

#: top-level tables that belong to the simulator (validated by insgnss.simulate; the same names
#: as insgnss.simulate.scenario.SIM_TABLES) and to Monte Carlo runs
SIMULATION_TABLES = ("scenario", "trajectory", "imu", "gnss", "odometer", "magnetometer",
                     "montecarlo")


def _type_name(kind) -> str:
    if kind is _NUM:
        return "number"
    if isinstance(kind, tuple):
        return " or ".join(k.__name__ for k in kind)
    return {str: "string", bool: "boolean", int: "integer", list: "array",
            dict: "table"}.get(kind, str(kind))


def _check_value(value, spec, key: str, file) -> Any:
    kind = spec["type"]
    if kind is _ANY:
        return value
    ok = isinstance(value, kind) and not (kind is _NUM and isinstance(value, bool))
    if not ok:
        raise ConfigError("wrong type", file=file, column=key, expected=_type_name(kind),
                          found=f"{type(value).__name__} {value!r}")
    if spec["choices"] is not None and kind is list:  # a list of choices
        bad = [v for v in value if v not in spec["choices"]]
        if bad:
            raise ConfigError("value not allowed", file=file, column=key,
                              expected=f"some of {spec['choices']}", found=repr(bad))
    elif spec["choices"] is not None and value not in spec["choices"]:
        raise ConfigError("value not allowed", file=file, column=key,
                          expected=f"one of {spec['choices']}", found=repr(value))
    return float(value) if kind is _NUM else value


def _is_table_spec(spec) -> bool:
    return isinstance(spec, dict) and "type" not in spec


def _validate(table: dict, schema: dict, prefix: str, file) -> dict:
    out: dict[str, Any] = {}
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if key not in schema:
            raise ConfigError("unknown key", file=file, column=dotted,
                              expected=f"one of {sorted(schema)}", found=repr(key))
        spec = schema[key]
        if _is_table_spec(spec):
            if not isinstance(value, dict):
                raise ConfigError("wrong type", file=file, column=dotted, expected="table",
                                  found=type(value).__name__)
            out[key] = _validate(value, spec, dotted + ".", file)
        else:
            out[key] = _check_value(value, spec, dotted, file)
    for key, spec in schema.items():  # defaults
        if key in out:
            continue
        out[key] = _validate({}, spec, f"{prefix}{key}.", file) if _is_table_spec(spec) else \
            spec["default"]
    return out


@dataclass
class Job:
    """A validated job: the settings (dict of tables with defaults filled in), the file it came
    from, and any simulation tables it carries."""

    settings: dict
    path: Path | None = None
    simulation: dict = field(default_factory=dict)

    def __getitem__(self, table: str) -> dict:
        return self.settings[table]

    @property
    def base_dir(self) -> Path:
        return self.path.parent if self.path is not None else Path.cwd()

    def resolve(self, p: str | None) -> Path | None:
        """Path relative to the job file (absolute paths unchanged)."""
        if p is None:
            return None
        q = Path(p).expanduser()
        return q if q.is_absolute() else (self.base_dir / q).resolve()

    @property
    def output_dir(self) -> Path:
        return self.resolve(self.settings["outputs"]["dir"])

    def input_paths(self) -> list[Path]:
        """Every input file the job reads (outputs must never overwrite one)."""
        out = []
        for spec in self.settings["inputs"].values():
            for k in ("path", "tag"):
                if spec.get(k):
                    out.append(self.resolve(spec[k]))
        return out


def load_job_dict(data: dict, path: str | Path | None = None) -> Job:
    """Validate a job given as a dict (as parsed from TOML)."""
    file = None if path is None else str(path)
    if not isinstance(data, dict):
        raise ConfigError("a job must be a TOML table", file=file)
    sim = {k: v for k, v in data.items() if k in SIMULATION_TABLES}
    rest = {k: v for k, v in data.items() if k not in SIMULATION_TABLES}
    settings = _validate(rest, SCHEMA, "", file)
    return Job(settings=settings, path=None if path is None else Path(path).resolve(),
               simulation=sim)


def load_job(path: str | Path) -> Job:
    """Read and validate a TOML job file."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ConfigError("job file not found", file=path) from None
    except UnicodeDecodeError as exc:
        raise ConfigError("job file is not UTF-8 text", file=path, found=str(exc)) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        row = None
        if "(at line " in msg:
            try:
                row = int(msg.split("(at line ")[1].split(",")[0])
            except ValueError:
                row = None
        raise ConfigError(f"not valid TOML: {msg}", file=path, row=row) from None
    return load_job_dict(data, path)


def schema_markdown() -> str:
    """The schema as Markdown tables (used to keep docs/jobs.md in step)."""
    lines = []

    def walk(schema, prefix):
        rows = []
        for key, spec in schema.items():
            if _is_table_spec(spec):
                walk(spec, f"{prefix}{key}.")
            else:
                rows.append(f"| `{prefix}{key}` | {_type_name(spec['type'])} | "
                            f"`{spec['default']!r}` | {spec['doc']}"
                            + (f" (one of {', '.join(map(str, spec['choices']))})"
                               if spec["choices"] else "") + " |")
        if rows:
            lines.append(f"\n### `[{prefix.rstrip('.')}]`\n")
            lines.append("| key | type | default | meaning |")
            lines.append("|---|---|---|---|")
            lines.extend(rows)

    walk(SCHEMA, "")
    return "\n".join(lines) + "\n"
