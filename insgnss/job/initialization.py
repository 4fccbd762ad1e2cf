"""Initialization of a job (``[initialization] method``): the filter's initial nominal state
(:class:`~insgnss.mechanization.strapdown.NavState`) and its sigmas.

- ``static``: levelling over the first ``static_duration`` seconds; heading by gyrocompassing
  when the IMU grade allows it, else the given ``heading_deg``, else from GNSS: the course over
  ground at the first GNSS epoch faster than ``min_speed`` minus the heading change the gyros
  measured from the start to that epoch (a free-inertial run with the levelled attitude);
- ``gnss_velocity``: start at the first GNSS epoch faster than ``min_speed`` with the GNSS
  position and velocity, heading = course over ground (no side slip), roll/pitch from the
  accelerometers (averaged over 1 s) or given;
- ``given``: roll, pitch, heading given; position from the first GNSS epoch.

The alignment algorithms are in :mod:`insgnss.align`; this module chooses among them from the
job and the data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..align import can_gyrocompass, coarse_align, gyrocompass, level
from ..attitude import euler_to_dcm
from ..config import Job
from ..earth import enu_displacement_to_geodetic
from ..errors import ConfigError
from ..imu import ACCEL_COLS, DV_COLS, GYRO_COLS, ImuErrorModel
from ..mechanization.strapdown import NavState, mechanize
from .inputs import Inputs


@dataclass
class Initialization:
    """Initial nominal state of the filter and its sigmas (``att_std`` roll, pitch, heading
    [rad]; ``pos_std`` [m], scalar or east/north/up; ``vel_std`` [m/s]), how it was found
    (``method``, ``heading_source``) and the end of the static window (``static_end``)."""

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


__all__ = ["Initialization", "initialize"]
