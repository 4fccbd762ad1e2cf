"""KF-GINS configuration files (``kf-gins.yaml``) as insgnss job files.

KF-GINS (i2Nav-WHU, https://github.com/i2Nav-WHU/KF-GINS) runs from a YAML file that names
the IMU and GNSS files, the processing interval, the initial state and its sigmas, the IMU
noise model and the antenna lever arm. :func:`kfgins_job` translates it key by key into an
insgnss job (:func:`job_toml` writes it as TOML with a comment per value naming the KF-GINS
key it came from, or saying why a key has no counterpart):

==================================  ===================================================
KF-GINS                             insgnss job
==================================  ===================================================
``imupath``                         ``[inputs.imu]`` format kfgins, path (the rate comes from
                                    the time stamps, not ``imudatarate``)
``gnsspath``, ``antlever`` (F R D)  ``[inputs.gnss]`` format kfgins, path, lever_arm (R F U)
``outputpath``                      ``[outputs]`` dir (formats csv, nav)
``starttime``, ``endtime``          ``[job]`` start, end (seconds of week, time_base sow)
``initatt``, ``initvel`` (N E D)    ``[initialization]`` method given, roll/pitch/heading_deg,
                                    velocity (E N U)
``initposstd``, ``initvelstd``,     position_std, velocity_std (largest axis),
``initattstd``                      attitude_std_deg
``imunoise`` arw, vrw               ``[filter.imu_model]`` gyro_arw_deg_sqrt_h,
                                    accel_vrw_m_s_sqrt_h
``imunoise`` gbstd, abstd,          gyro/accel bias instability, ``bias_correlation_time_s``
``corrtime`` (h)                    and ``[filter] bias_model = "gauss_markov"`` (KF-GINS'
                                    first-order Gauss-Markov biases)
``initbgstd``, ``initbastd``        the turn-on part of the initial bias sigma
                                    (insgnss: ``hypot(turn-on, instability)``)
``imunoise`` gsstd, asstd           ``gyro_scale_ppm``, ``accel_scale_ppm``,
                                    ``[filter] scale_factors = true``
==================================  ===================================================

Units: 1 mGal = 1e-5 m/s^2 = 1.0197 ug. Per-axis triples become one value (the largest axis)
where insgnss has one; the comment says so when the axes differ. ``initpos`` has no key: a job
with GNSS takes its start position from the GNSS at the first epoch. KF-GINS's initial bias
and scale-factor values (``initgyrbias`` ...) have no counterpart (insgnss starts from zero);
non-zero values are named in the notes. Paths in the YAML are relative to the folder KF-GINS
runs in (``base``); the job names them relative to its own folder.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import ConfigError, InputFormatError

#: 1 mGal in micro-g and in milli-g
MGAL_UG = 1e-5 / 9.80665e-6
MGAL_MG = 1e-5 / 9.80665e-3
#: turn-on share kept when KF-GINS's initial bias sigma equals its Gauss-Markov sigma
#: (insgnss needs a positive turn-on sigma; 1e-3 of it changes the initial sigma by 5e-7)
MIN_TURN_ON = 1e-3


def read_kfgins_config(path: str | os.PathLike) -> dict:
    """The KF-GINS YAML as a dict (errors name the file)."""
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except FileNotFoundError:
        raise ConfigError("KF-GINS configuration not found", file=p) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise InputFormatError(f"not valid YAML: {exc}", file=p,
                               row=None if mark is None else mark.line + 1) from None
    if not isinstance(data, dict):
        raise InputFormatError("a KF-GINS configuration is a YAML mapping", file=p,
                               found=type(data).__name__)
    return data


def _triple(cfg: dict, key: str, file, default=None) -> np.ndarray | None:
    v = cfg.get(key, default)
    if v is None:
        return None
    try:
        a = np.asarray(v, float).reshape(-1)
    except (TypeError, ValueError):
        a = np.array([np.nan])
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputFormatError("expected three numbers", file=file, column=key, found=repr(v))
    return a


def _number(cfg: dict, key: str, file) -> float | None:
    v = cfg.get(key)
    if v is None:
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        x = np.nan
    if not np.isfinite(x):
        raise InputFormatError("expected a number", file=file, column=key, found=repr(v))
    return x


def _one(a: np.ndarray, what: str, notes: list[str]) -> tuple[float, str]:
    """The largest axis of a triple, and a comment when the axes differ."""
    if np.ptp(a) > 1e-12 * max(1.0, float(np.max(np.abs(a)))):
        return float(np.max(a)), f"largest of {what} {a.tolist()}"
    return float(a[0]), what


def kfgins_job(cfg: dict, *, file=None, base: str | os.PathLike = ".",
               job_dir: str | os.PathLike = ".", name: str = "kfgins"
               ) -> tuple[list[tuple[str, list[tuple[str, object, str]]]], list[str]]:
    """The insgnss job of a KF-GINS configuration (module docstring).

    Returns the tables as ``[(table, [(key, value, comment), ...]), ...]`` (for
    :func:`job_toml` and :func:`job_dict`) and the notes on what has no counterpart.
    ``base`` is the folder KF-GINS resolves the YAML's paths in, ``job_dir`` the folder of
    the job file to write (the paths are written relative to it).
    """
    notes: list[str] = []
    base, job_dir = Path(base).resolve(), Path(job_dir).resolve()

    def path(key):
        v = cfg.get(key)
        if not isinstance(v, str) or not v.strip():
            raise InputFormatError("missing path", file=file, column=key,
                                   expected="a file path", found=repr(v))
        p = (base / v).resolve() if not Path(v).is_absolute() else Path(v)
        return Path(os.path.relpath(p, job_dir)).as_posix()

    job = [("name", name, "run name"), ("time_base", "sow",
                                        "KF-GINS files are in GPS seconds of week")]
    start, end = _number(cfg, "starttime", file), _number(cfg, "endtime", file)
    if start is not None:
        job.append(("start", start, "starttime [s of week]"))
    if end is not None and end >= 0:
        job.append(("end", end, "endtime [s of week]"))
    rate = _number(cfg, "imudatarate", file)
    imu = [("format", "kfgins", "increments, forward-right-down"),
           ("path", path("imupath"), "imupath")]
    if rate is not None:
        notes.append(f"imudatarate = {rate:g} Hz: insgnss measures the rate from the time "
                     "stamps")
    n_cols = _number(cfg, "imudatalen", file)
    if n_cols is not None and n_cols != 7:
        notes.append(f"imudatalen = {n_cols:g}: insgnss reads the first seven columns (time, "
                     "three angle and three velocity increments)")
    lever = _triple(cfg, "antlever", file, [0.0, 0.0, 0.0])
    gnss = [("format", "kfgins", "GNSS-RTK text, NED sigmas"),
            ("path", path("gnsspath"), "gnsspath"),
            ("lever_arm", [float(lever[1]), float(lever[0]), float(-lever[2])],
             f"antlever (forward, right, down) {lever.tolist()} as right-forward-up [m]")]
    att = _triple(cfg, "initatt", file)
    if att is None:
        raise InputFormatError("missing initial attitude", file=file, column="initatt",
                               expected="roll, pitch, yaw [deg]", found="none")
    ini = [("method", "given", "KF-GINS starts from the given attitude"),
           ("roll_deg", float(att[0]), "initatt roll"), ("pitch_deg", float(att[1]),
                                                          "initatt pitch"),
           ("heading_deg", float(np.mod(att[2], 360.0)), "initatt yaw")]
    vel = _triple(cfg, "initvel", file)
    if vel is not None and np.any(vel != 0):
        ini.append(("velocity", [float(vel[1]), float(vel[0]), float(-vel[2])],
                    f"initvel (north, east, down) {vel.tolist()} as east, north, up [m/s]"))
    for key, ours, what in (("initposstd", "position_std", "initposstd [m]"),
                            ("initvelstd", "velocity_std", "initvelstd [m/s]")):
        a = _triple(cfg, key, file)
        if a is not None:
            v, c = _one(a, what, notes)
            ini.append((ours, v, c))
    a = _triple(cfg, "initattstd", file)
    if a is not None:
        ini.append(("attitude_std_deg", a.tolist(), "initattstd roll, pitch, yaw [deg]"))
    pos = _triple(cfg, "initpos", file)
    if pos is not None:
        notes.append(f"initpos {pos.tolist()}: the start position comes from the GNSS at the "
                     "first epoch (a job with GNSS reads no initialization.lat_deg)")
    for key in ("initgyrbias", "initaccbias", "initgyrscale", "initaccscale"):
        a = _triple(cfg, key, file)
        if a is not None and np.any(a != 0):
            notes.append(f"{key} {a.tolist()}: insgnss starts the bias and scale-factor "
                         "estimates from zero")
    noise = cfg.get("imunoise") or {}
    if not isinstance(noise, dict):
        raise InputFormatError("imunoise must be a mapping", file=file, column="imunoise",
                               found=repr(noise))
    model, flt = [], [("bias_model", "gauss_markov", "KF-GINS: first-order Gauss-Markov "
                                                     "biases and scale factors")]

    def noise_triple(key):
        return _triple(noise, key, file)

    arw, vrw = noise_triple("arw"), noise_triple("vrw")
    if arw is not None:
        model.append(("gyro_arw_deg_sqrt_h", *_one(arw, "imunoise.arw [deg/sqrt(h)]", notes)))
    if vrw is not None:
        model.append(("accel_vrw_m_s_sqrt_h", *_one(vrw, "imunoise.vrw [m/s/sqrt(h)]", notes)))
    for gm_key, init_key, unit, ours_on, ours_in, scale_on, scale_in in (
            ("gbstd", "initbgstd", "deg/h", "gyro_bias_deg_h", "gyro_bias_instability_deg_h",
             1.0, 1.0),
            ("abstd", "initbastd", "mGal", "accel_bias_mg", "accel_bias_instability_ug",
             MGAL_MG, MGAL_UG)):
        gm = noise_triple(gm_key)
        if gm is None:
            continue
        sig, c = _one(gm, f"imunoise.{gm_key} [{unit}]", notes)
        init = _triple(cfg, init_key, file)
        s0 = sig if init is None else _one(init, f"{init_key} [{unit}]", notes)[0]
        turn_on = float(np.sqrt(max(s0 ** 2 - sig ** 2, (MIN_TURN_ON * sig) ** 2)))
        model.append((ours_in, sig * scale_in, c + (" as ug" if unit == "mGal" else "")))
        model.append((ours_on, turn_on * scale_on,
                      f"initial sigma {s0:g} {unit} ({init_key if init is not None else gm_key}"
                      f") = hypot(this, the instability)"))
    tau = _number(noise, "corrtime", file)
    if tau is not None:
        model.append(("bias_correlation_time_s", tau * 3600.0, f"imunoise.corrtime {tau:g} h"))
    gs, as_ = noise_triple("gsstd"), noise_triple("asstd")
    if gs is not None or as_ is not None:
        flt.append(("scale_factors", True, "KF-GINS estimates scale factors (21 states)"))
        for key, a, init_key, gm_key in (("gyro_scale_ppm", gs, "initsgstd", "gsstd"),
                                         ("accel_scale_ppm", as_, "initsastd", "asstd")):
            if a is None:
                continue
            init = _triple(cfg, init_key, file)
            src = init if init is not None else a
            v, c = _one(src, f"{init_key if init is not None else 'imunoise.' + gm_key} "
                             "[ppm]", notes)
            model.append((key, v, c + " (initial sigma; insgnss: random constant)"))
    out = [("dir", path("outputpath") if cfg.get("outputpath") else "out", "outputpath"),
           ("formats", ["csv", "nav"], "nav: the KF-GINS .nav format")]
    tables = [("job", job), ("inputs.imu", imu), ("inputs.gnss", gnss), ("initialization", ini),
              ("filter", flt), ("filter.imu_model", model), ("outputs", out)]
    return tables, notes


def job_dict(tables) -> dict:
    """The job of :func:`kfgins_job` as a dict (as parsed from TOML)."""
    out: dict = {}
    for table, rows in tables:
        d = out
        for part in table.split("."):
            d = d.setdefault(part, {})
        for key, value, _ in rows:
            d[key] = value
    return out


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int) and not isinstance(v, float):
        return str(v)
    if isinstance(v, float):
        x = f"{v + 0.0:.12g}"  # 12 digits; -0.0 -> 0
        return x if any(c in x for c in ".en") else x + ".0"
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {v!r}")


def job_toml(tables, notes: list[str], source: str) -> str:
    """TOML text of a translated job, a comment per value and the notes at the top."""
    lines = [f"# insgnss job translated from the KF-GINS configuration {source}",
             "# (insgnss import-kfgins; the mapping: insgnss.io.kfgins_yaml). Run it with",
             "#   insgnss process THIS_FILE.toml",
             "# Add the reference to evaluate against, e.g.",
             "#   [inputs.reference]",
             "#   format = \"kfgins_nav\"",
             "#   path = \"truth.nav\"",
             "#   point = \"imu\""]
    if notes:
        lines.append("#")
        lines.append("# Not translated:")
        lines += [f"#   {n}" for n in notes]
    for table, rows in tables:
        lines += ["", f"[{table}]"]
        width = max(len(f"{k} = {_toml(v)}") for k, v, _ in rows)
        lines += [f"{k} = {_toml(v)}".ljust(width) + f"   # {c}" for k, v, c in rows]
    return "\n".join(lines) + "\n"


__all__ = ["job_dict", "job_toml", "kfgins_job", "read_kfgins_config"]
