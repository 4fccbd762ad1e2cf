"""Small generated data in every input format a job can name, for tests that run job files as a
user writes them (the docs/jobs.md examples, ``insgnss init`` templates, KF-GINS imports).

:func:`generate_for` simulates a short land-vehicle drive that fits the job - its
initialization (a static start long enough for ``static_duration``, the given heading), its
declared still intervals, its IMU grade, its lever arm, its odometer - and writes each
``[inputs.*]`` file the job names in the job's declared format, units, axes, mounting, time
unit, time offset and time base (:data:`WRITERS`). It returns the job with its paths pointing
at the generated files and the simulated truth to judge the result against.

Time bases: jobs with GNSS run in GPS seconds from :data:`T0` (KF-GINS files: seconds of week),
jobs without GNSS from 0 (their still intervals are written in seconds from the start).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pandas as pd
from io_helpers import gga, gst, kfgins_imu_text, pos_text, raw_imu_text, rmc, tag_bytes

from insgnss.earth import radii
from insgnss.imu import G0
from insgnss.io.gpstime import WEEK_SECONDS, datetime64_from_gps_seconds
from insgnss.io.imu_csv import mounting_matrix
from insgnss.io.kfgins import write_kfgins_nav
from insgnss.io.native import write_table
from insgnss.io.rtklibexplorer import rtklibexplorer_mounting
from insgnss.simulate.scenario import simulate_scenario

#: GPS seconds of the simulated start (2025-07-08 19:34:00 GPST) of jobs with GNSS
T0 = 1436038440.0
#: GPS - UTC in 2025 [s]
LEAP = 18.0
#: GNSS noise of the simulated receiver per input format: (horizontal, vertical sigma [m],
#: RTKLIB Q). NMEA: a DGPS fix (GGA quality 2) whose HDOP 0.9 with the reader's UERE of 1 m
#: gives the simulated sigmas (insgnss.io.nmea.UERE)
GNSS_NOISE = {"rtklib_pos": (0.02, 0.04, 1), "kfgins": (0.05, 0.1, 1), "native": (0.5, 1.0, 5),
              "nmea": (0.9 * 1.0 / np.sqrt(2.0), 2.0 * 0.9 * 1.0, 4)}
NMEA_HDOP = 0.9
#: the drive after the start: speeds up, turns, stops (ZUPT), drives on, stops
DRIVE = [{"type": "accelerate", "speed": 10.0, "duration": 8.0},
         {"type": "hold", "duration": 20.0},
         {"type": "turn", "angle": 90.0, "duration": 9.0},
         {"type": "hold", "duration": 25.0},
         {"type": "decelerate", "speed": 0.0, "duration": 6.0},
         {"type": "static", "duration": 8.0},
         {"type": "accelerate", "speed": 12.0, "duration": 8.0},
         {"type": "turn", "angle": -60.0, "duration": 8.0},
         {"type": "hold", "duration": 40.0},
         {"type": "decelerate", "speed": 0.0, "duration": 6.0},
         {"type": "static", "duration": 5.0}]


#: walking speed [m/s] of the generated data of a pedestrian job
WALK_SPEED = 1.4


def _move(d: float) -> list[dict]:
    """Segments that leave rest and come back to rest after ``d`` seconds."""
    if d < 30.0:
        return [{"type": "static", "duration": d}]
    h = (d - 23.0) / 2.0
    return [{"type": "accelerate", "speed": 8.0, "duration": 8.0},
            {"type": "hold", "duration": h}, {"type": "turn", "angle": 90.0, "duration": 9.0},
            {"type": "hold", "duration": h}, {"type": "decelerate", "speed": 0.0, "duration": 6.0}]


def _segments(job: dict) -> list[dict]:
    ini = job.get("initialization", {})
    still = job.get("aiding", {}).get("static_intervals")
    if still:
        segs, t = [], 0.0
        for a, b in sorted(still):
            if a > t:
                segs += _move(a - t)
            segs.append({"type": "static", "duration": b - max(a, t)})
            t = b
        return segs + _move(60.0) + [{"type": "static", "duration": 5.0}]
    method = ini.get("method", "static")
    start = ini.get("static_duration", 30.0) + 5.0 if method == "static" else 5.0
    motion = DRIVE
    if job.get("job", {}).get("platform") == "pedestrian":  # a walk, not a drive
        motion = [{**s, "speed": WALK_SPEED} if s.get("speed") else s for s in DRIVE]
    return [{"type": "static", "duration": start}] + motion


def has_gnss(job: dict) -> bool:
    return bool(job.get("inputs", {}).get("gnss", {}).get("path"))


def scenario_for(job: dict, seed: int = 5) -> dict:
    """The simulation scenario that fits ``job`` (module docstring)."""
    g = job.get("inputs", {}).get("gnss", {})
    hs, vs, q = GNSS_NOISE[g.get("format", "rtklib_pos")]
    ini = job.get("initialization", {})
    sc = {"scenario": {"name": "example", "seed": seed, "imu_rate": 100.0},
          "trajectory": {"vehicle": "land", "lat": ini.get("lat_deg", 45.0),
                         "lon": ini.get("lon_deg", 7.0), "height": ini.get("height", 250.0),
                         "heading": ini.get("heading_deg", 30.0), "segments": _segments(job)},
          "imu": {"grade": job.get("filter", {}).get("imu_grade") or "tactical"},
          "gnss": {"rate": 1.0, "horizontal_std": hs, "vertical_std": vs, "velocity": True,
                   "velocity_std": 0.05, "lever_arm": list(g.get("lever_arm", [0.0, 0.0, 0.0])),
                   "q": q}}
    if job.get("inputs", {}).get("odometer", {}).get("path"):
        sc["odometer"] = {"rate": 10.0}
    return sc


# --------------------------------------------------------------------------------------------
# writers: (simulated table, file time of each row, the job's table spec, path) -> file
# --------------------------------------------------------------------------------------------

def _rates(imu: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Mean rates over each sample interval from the simulated increments (body RFU); the
    first row (the increment before the first sample) is repeated from the second."""
    t = imu.index.to_numpy(float)
    dt = np.diff(t, prepend=t[0] - np.median(np.diff(t)))[:, None]
    w = imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy() / dt
    f = imu[["dv_x", "dv_y", "dv_z"]].to_numpy() / dt
    w[0], f[0] = w[1], f[1]
    return w, f


def write_imu_csv(imu, tf, spec, path):
    """Generic CSV: the declared columns, units, time unit, axis map / mounting / sensor axes."""
    w, f = _rates(imu)
    M = mounting_matrix(spec.get("axis_map"), spec.get("mounting_deg"),
                        sensor_axes=spec.get("sensor_axes", "rfu"),
                        euler_convention=spec.get("mounting_convention", "active"))
    w, f = w @ M, f @ M  # v_s = M^T v_b, row-wise
    gyro = {"rad/s": 1.0, "deg/s": 180.0 / np.pi}[spec.get("gyro_unit", "rad/s")]
    accel = {"m/s^2": 1.0, "g": 1.0 / G0}[spec.get("accel_unit", "m/s^2")]
    scale = {"s": 1.0, "ms": 1e3, "us": 1e6, "ns": 1e9}[spec.get("time_unit", "s")]
    cols = spec.get("columns") or {}
    names = {k: cols.get(k, k) for k in ("time", "gyro_x", "gyro_y", "gyro_z", "accel_x",
                                         "accel_y", "accel_z")}
    data = {names["time"]: [f"{x:.6f}" for x in tf * scale]}
    for j, ax in enumerate("xyz"):
        data[names[f"gyro_{ax}"]] = w[:, j] * gyro
    for j, ax in enumerate("xyz"):
        data[names[f"accel_{ax}"]] = f[:, j] * accel
    pd.DataFrame(data).to_csv(path, index=False, float_format="%.10g",
                              sep=spec.get("delimiter", ","))


def write_imu_native(imu, tf, spec, path):
    write_table(imu.set_axis(pd.Index(tf, name="time"), axis=0), path)


def write_imu_rtklibexplorer(imu, tf, spec, path):
    """Raw ``ax..az [g], wx..wz [deg/s], ms`` in the sensor axes of the declared mounting, a
    dummy first and last line (the reader skips them) and the ``.tag`` file (GPST start and
    span)."""
    w, f = _rates(imu)
    M = rtklibexplorer_mounting(spec["mounting_deg"])
    w, f = np.degrees(w @ M), (f @ M) / G0
    ms = 5000.0 + 1000.0 * (tf - tf[0])
    text = raw_imu_text(np.concatenate([[ms[0] - 10], ms, [ms[-1] + 10]]),
                        np.vstack([f[:1], f, f[-1:]]), np.vstack([w[:1], w, w[-1:]]))
    Path(path).write_text(text)
    span = int(round(1000.0 * (tf[-1] - tf[0])))
    tag = spec.get("tag") or str(path) + ".tag"
    Path(tag).write_bytes(tag_bytes(float(tf[0]), [0, span], [0, 44]))


def write_imu_kfgins(imu, tf, spec, path):
    """KF-GINS increments in forward-right-down axes, seconds of week."""
    P = mounting_matrix(sensor_axes="frd")
    dth = imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy() @ P
    dv = imu[["dv_x", "dv_y", "dv_z"]].to_numpy() @ P
    Path(path).write_text(kfgins_imu_text(tf % WEEK_SECONDS, dth, dv))


def write_gnss_native(gnss, tf, spec, path):
    write_table(gnss.set_axis(pd.Index(tf, name="time"), axis=0), path)


def write_gnss_rtklib_pos(gnss, tf, spec, path):
    """RTKLIB .pos (GPST calendar time, lat/lon deg, height, Q, sigmas, velocity)."""
    vel = gnss[["vel_e", "vel_n", "vel_u"]].to_numpy() if "vel_e" in gnss.columns else None
    sd = tuple(float(gnss[c].iloc[0]) for c in ("north_std", "east_std", "up_std"))
    Path(path).write_text(pos_text(tf, gnss["lat"].to_numpy(), gnss["lon"].to_numpy(),
                                   gnss["height"].to_numpy(), q=gnss["q"].to_numpy(int),
                                   vel=vel, sd=sd))


def write_gnss_nmea(gnss, tf, spec, path):
    """NMEA: RMC (date, speed and course over ground) and GGA (DGPS fix, HDOP
    :data:`NMEA_HDOP`, ellipsoidal height with a zero geoid separation) per epoch; GST on every
    fourth epoch (the reader takes the sigmas from GST there, from the HDOP elsewhere)."""
    lines = []
    utc = datetime64_from_gps_seconds(np.asarray(tf, float) - LEAP)
    for k, (u, r) in enumerate(zip(utc, gnss.itertuples(), strict=True)):
        s = str(u.astype("datetime64[ms]"))
        tod = float((u - u.astype("datetime64[D]")) / np.timedelta64(1, "ms")) / 1000.0
        date = s[8:10] + s[5:7] + s[2:4]
        speed = np.hypot(r.vel_e, r.vel_n)
        course = np.degrees(np.arctan2(r.vel_e, r.vel_n)) % 360.0
        lat, lon = np.degrees(r.lat), np.degrees(r.lon)
        lines.append(rmc(tod, date, lat, lon, speed / (1852.0 / 3600.0), course))
        lines.append(gga(tod, lat, lon, r.height, sep=0.0, quality=2, hdop=NMEA_HDOP))
        if k % 4 == 0:
            lines.append(gst(tod, r.north_std, r.east_std, r.up_std))
    Path(path).write_text("\n".join(lines) + "\n")


def write_gnss_kfgins(gnss, tf, spec, path):
    """KF-GINS GNSS: ``sow lat lon h std_n std_e std_d`` (7 columns)."""
    v = np.column_stack([tf % WEEK_SECONDS, np.degrees(gnss["lat"]), np.degrees(gnss["lon"]),
                         gnss["height"], gnss["north_std"], gnss["east_std"], gnss["up_std"]])
    Path(path).write_text("\n".join(" ".join(f"{x:.9f}" for x in r) for r in v) + "\n")


def write_reference_native(truth, tf, spec, path):
    write_table(truth.set_axis(pd.Index(tf, name="time"), axis=0), path)


def write_reference_kfgins_nav(truth, tf, spec, path):
    """KF-GINS .nav with the GPS week (as KF-GINS writes its results and truth files)."""
    t = truth.set_axis(pd.Index(tf, name="time"), axis=0)
    t.attrs["time_base"] = "gps"
    write_kfgins_nav(t, path)


def write_reference_rtklib_pos(truth, tf, spec, path):
    t = truth.copy()
    for c, s in (("north_std", 0.01), ("east_std", 0.01), ("up_std", 0.02)):
        t[c] = s
    t["q"] = 1
    write_gnss_rtklib_pos(t, tf, spec, path)


def write_control_points(truth, tf, spec, path):
    write_table(truth[["lat", "lon", "height"]].set_axis(pd.Index(tf, name="time"), axis=0), path)


def write_odometer_native(odo, tf, spec, path):
    write_table(odo[["speed"]].set_axis(pd.Index(tf, name="time"), axis=0), path)


WRITERS = {("imu", "csv"): write_imu_csv, ("imu", "native"): write_imu_native,
           ("imu", "rtklibexplorer"): write_imu_rtklibexplorer,
           ("imu", "kfgins"): write_imu_kfgins,
           ("gnss", "native"): write_gnss_native, ("gnss", "rtklib_pos"): write_gnss_rtklib_pos,
           ("gnss", "nmea"): write_gnss_nmea, ("gnss", "kfgins"): write_gnss_kfgins,
           ("reference", "native"): write_reference_native,
           ("reference", "kfgins_nav"): write_reference_kfgins_nav,
           ("reference", "rtklib_pos"): write_reference_rtklib_pos,
           ("control_points", None): write_control_points,
           ("odometer", "native"): write_odometer_native}
#: defaults of the [inputs.*] format keys (insgnss.config.SCHEMA)
DEFAULT_FORMAT = {"imu": "csv", "gnss": "rtklib_pos", "reference": "rtklib_pos",
                  "control_points": None, "odometer": "native"}


def _still_points(truth: pd.DataFrame, still) -> pd.DataFrame:
    """Truth rows at the middle of each still interval (surveyed control points)."""
    t = truth.index.to_numpy(float)
    k = [int(np.argmin(np.abs(t - 0.5 * (a + b)))) for a, b in still]
    return truth.iloc[k]


def generate_for(job: dict, folder: Path, seed: int = 5):
    """Simulate data that fits ``job`` and write its input files into ``folder`` (module
    docstring). Returns ``(job with the generated paths, simulated truth indexed in the job's
    time base)``."""
    job = copy.deepcopy(job)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sim = simulate_scenario(scenario_for(job, seed))
    origin = T0 if has_gnss(job) else 0.0
    inputs = job.get("inputs", {})
    if inputs.get("imu", {}).get("format") == "kfgins" or \
            inputs.get("gnss", {}).get("format") == "kfgins":
        origin = T0 % WEEK_SECONDS  # KF-GINS files are in seconds of week
    tables = {"imu": sim.imu, "gnss": sim.gnss, "reference": sim.truth,
              "odometer": sim.odometer,
              "control_points": _still_points(sim.truth, job.get("aiding", {}).get(
                  "static_intervals") or [])}
    for name, spec in inputs.items():
        if not spec.get("path"):
            continue
        fmt = spec.get("format", DEFAULT_FORMAT[name])
        table = tables[name]
        tf = origin + table.index.to_numpy(float) - spec.get("time_offset", 0.0)
        path = folder / Path(spec["path"]).name
        spec["path"] = path.name
        if spec.get("tag"):
            spec["tag"] = str(folder / Path(spec["tag"]).name)
        if name == "reference" and spec.get("point", "antenna") == "antenna":
            from insgnss.evaluate import move_point

            table = move_point(table, np.asarray(inputs["gnss"]["lever_arm"], float))
        WRITERS[(name, fmt)](table, tf, spec, path)
    truth = sim.truth.set_axis(pd.Index(origin + sim.truth.index.to_numpy(float), name="time"),
                               axis=0)
    return job, truth


def horizontal_errors(sol: pd.DataFrame, truth: pd.DataFrame) -> np.ndarray:
    """Horizontal position errors [m] of a solution against the truth at the solution's
    epochs (truth interpolated)."""
    t = sol.index.to_numpy(float)
    tt = truth.index.to_numpy(float)
    lat = np.interp(t, tt, truth["lat"].to_numpy(float))
    lon = np.interp(t, tt, truth["lon"].to_numpy(float))
    M, N = radii(lat)
    de = (sol["lon"].to_numpy(float) - lon) * N * np.cos(lat)
    dn = (sol["lat"].to_numpy(float) - lat) * M
    return np.hypot(de, dn)
