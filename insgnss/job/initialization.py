"""Initialization of a job (``[initialization] method``): the filter's initial nominal state
(:class:`~insgnss.mechanization.strapdown.NavState`) and its sigmas.

- ``static``: levelling over the initial static window; heading by gyrocompassing
  when the IMU grade allows it, else the given ``heading_deg``, else from GNSS: the course over
  ground at the first GNSS epoch faster than ``min_speed`` minus the heading change the gyros
  measured from the start to that epoch (a free-inertial run with the levelled attitude); with
  ``heading_alignment = "in_motion"`` first the in-motion alignment
  (:func:`insgnss.align.heading_in_motion`: the free-inertial path matched to the GNSS path
  after the static window), used when its sigma is below :data:`MAX_MOTION_HEADING_STD` and
  ``course_heading_std_deg``;
- ``gnss_velocity``: start at the first GNSS epoch faster than ``min_speed`` with the GNSS
  position and velocity, heading = course over ground (no side slip), roll/pitch from the
  accelerometers averaged over 1 s with the vehicle's acceleration over that second (GNSS
  velocity difference) removed (:func:`insgnss.align.level_moving`), or given;
- ``given``: roll, pitch, heading (and ``velocity``, default at rest) given; position from
  the first GNSS epoch.

The static window is found in the data (:func:`insgnss.detect.find_static_windows`, with the
stillness limits ``static_max_accel_std`` / ``static_max_rate_std_deg`` of the platform
profile): the truly still period at the start when it lasts at least
:data:`MIN_STATIC` seconds, else the stationary one (with a warning: levelling over a moving
hand averages its tilt); GNSS epochs showing motion (faster than :data:`STATIC_GNSS_SPEED`)
end it. ``static_duration`` fixes it instead, with a warning when that window is not still.
The IMU noise is measured only in a truly still window (:attr:`Initialization.noise_window`,
``filter.noise_from_static``).

GNSS inside the job's outage windows is withheld here as in the aiding
(:func:`~insgnss.job.windows.outside_windows`): an initialization never uses an epoch the run
is meant not to see, so a run (or a split segment) that starts in an outage starts from the
first usable epoch after it. A position is taken from GNSS only at a time bracketed by usable
epochs at most :data:`MAX_INTERPOLATION` seconds apart (never extrapolated, never across an
outage).

The alignment algorithms are in :mod:`insgnss.align`; this module chooses among them from the
job and the data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..align import (
    GYROCOMPASS_MAX_BIAS_RATIO,
    MotionHeading,
    coarse_align,
    free_inertial_drift_std,
    gyrocompass,
    gyrocompass_check,
    heading_in_motion,
    level_moving,
    static_means,
)
from ..attitude import euler_to_dcm
from ..checks import check_gyro_at_rest, check_upright, static_window_error
from ..config import Job
from ..detect import find_static_windows
from ..earth import earth_rate_l, enu_displacement_to_geodetic, geodetic_to_enu
from ..errors import AlignmentError, ConfigError
from ..imu import ACCEL_COLS, DV_COLS, GYRO_COLS, ImuErrorModel
from ..mechanization.strapdown import NavState, mechanize
from ..validate import time_slice, warn
from .inputs import Inputs
from .windows import describe_windows, outage_windows, outside_windows

#: longest interval [s] between the two usable GNSS epochs an initial position is interpolated
#: between (a few epochs of any GNSS rate in use; an outage window is far longer)
MAX_INTERPOLATION = 2.0
#: a GNSS epoch this close [s] to the initial time gives the position directly (the state time
#: is an IMU sample, within one IMU interval of the epoch)
NEAR_EPOCH = 0.02
#: shortest truly still period at the start that serves as the static window [s]
MIN_STATIC = 1.0
#: a GNSS antenna faster than this [m/s] is moving: the static window ends before that epoch
#: (RTK speed noise is a few cm/s, a single-point fix's a few dm/s)
STATIC_GNSS_SPEED = 0.3
#: in-motion heading alignment (``initialization.heading_alignment = "in_motion"``): longest
#: free-inertial run after the static window [s] (the fit stops earlier, where the modelled
#: inertial drift outgrows the distance travelled), a GNSS gap longer than this [s] ends it
#: (an outage: the run never uses an epoch it is meant not to see), the per-axis GNSS position
#: sigma [m] when the table has none, the floor of the heading sigma it gives and the largest
#: sigma it is used with [rad] (beyond a few degrees the small-angle heading error of the filter
#: is what the alignment is meant to avoid: the GNSS course is used then)
MOTION_WINDOW = 60.0
MOTION_MAX_GAP = 2.0
MOTION_GNSS_STD = 0.05
MIN_MOTION_HEADING_STD = float(np.radians(0.5))
MAX_MOTION_HEADING_STD = float(np.radians(5.0))


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
    #: truly still window (start, end) [s] where the IMU noise may be measured (None: none)
    noise_window: tuple | None = None
    #: how the static window was found (summary.json "initialization" "static_window")
    static_info: dict | None = None


def _mean_specific_force(win: pd.DataFrame) -> np.ndarray:
    """Mean specific force [m/s^2] of a rate or increment IMU window."""
    if ACCEL_COLS[0] in win.columns:
        return win[ACCEL_COLS].to_numpy().mean(0)
    t = win.index.to_numpy(float)
    return win[DV_COLS].to_numpy()[1:].sum(0) / max(t[-1] - t[0], 1e-9)


def _mean_acceleration(gnss: pd.DataFrame, t0: float, t1: float) -> np.ndarray | None:
    """Mean ENU acceleration [m/s^2] over [t0, t1]: the GNSS velocity difference (velocities
    interpolated between usable epochs), or None where they do not bracket the interval."""
    tg = gnss.index.to_numpy(float)
    if t1 <= t0 or tg.size < 2 or t0 < tg[0] or t1 > tg[-1]:
        return None
    k0, k1 = np.searchsorted(tg, [t0, t1])
    if np.diff(tg[max(k0 - 1, 0):k1 + 1]).max(initial=0.0) > MAX_INTERPOLATION:
        return None  # an outage inside: no velocity difference over it
    v = [np.interp([t0, t1], tg, gnss[c].to_numpy(float)) for c in _vel_cols(gnss)]
    acc = [(b - a) / (t1 - t0) for a, b in v]
    return np.array(acc + [0.0] * (3 - len(acc)))  # horizontal-only GNSS: no vertical term


def _vel_cols(gnss: pd.DataFrame) -> list[str]:
    """The velocity columns of a GNSS table: ENU, or east/north only (NMEA: speed and course
    over ground, no vertical velocity)."""
    return [c for c in ("vel_e", "vel_n", "vel_u") if c in gnss.columns]


def _gnss_at(gnss: pd.DataFrame, t: float, windows) -> np.ndarray:
    """GNSS position at ``t`` interpolated between the usable epochs around it."""
    ti = gnss.index.to_numpy(float)
    j = int(np.searchsorted(ti, t, side="right"))
    near = float(np.min(np.abs(ti[max(j - 1, 0):j + 1] - t))) <= NEAR_EPOCH
    if not near and (j == 0 or j == ti.size or ti[j] - ti[j - 1] > MAX_INTERPOLATION):
        around = ", ".join(f"{x:.3f}" for x in ti[max(j - 1, 0):j + 1])
        raise AlignmentError(
            f"no usable GNSS epoch around t = {t:.3f} s to take the initial position from "
            f"(nearest usable epochs: {around} s; GNSS inside {describe_windows(windows)} is "
            "withheld, and a position is not extrapolated or interpolated over more than "
            f"{MAX_INTERPOLATION:g} s)", file=gnss.attrs.get("source"), column="time")
    return np.array([np.interp(t, ti, gnss[c].to_numpy(float)) for c in ("lat", "lon", "height")])


def _moving_epochs(gnss: pd.DataFrame, min_speed: float, t_from: float, t_to: float,
                   *, strict: bool = False) -> np.ndarray:
    """Indices of the GNSS epochs faster than ``min_speed`` in [t_from, t_to]."""
    t = gnss.index.to_numpy(float)
    sp = np.hypot(gnss["vel_e"].to_numpy(float), gnss["vel_n"].to_numpy(float))
    after = t > t_from if strict else t >= t_from
    return np.nonzero((sp > min_speed) & after & (t <= t_to))[0]


def _no_moving_epoch(gnss: pd.DataFrame, all_gnss: pd.DataFrame, windows, min_speed: float,
                     t_from: float, t_to: float, what: str) -> ConfigError:
    """The error when no usable GNSS epoch is fast enough, naming what removed them."""
    if not len(gnss):
        cause = f"every GNSS epoch lies inside {describe_windows(windows)}"
    else:
        tg = gnss.index.to_numpy(float)
        inside = (tg >= t_from) & (tg <= t_to)
        if not inside.any():
            cause = (f"no usable GNSS epoch between {t_from:.3f} and {t_to:.3f} s (usable GNSS "
                     f"{tg[0]:.3f} .. {tg[-1]:.3f} s; the IMU data ends at {t_to:.3f} s)")
        else:
            fast = _moving_epochs(all_gnss, min_speed, t_from, t_to).size
            sp = np.hypot(gnss["vel_e"].to_numpy(float), gnss["vel_n"].to_numpy(float))[inside]
            cause = (f"GNSS never faster than initialization.min_speed = {min_speed:g} m/s "
                     f"between {t_from:.3f} and {t_to:.3f} s (fastest usable epoch "
                     f"{float(np.nanmax(sp)):.2f} m/s)")
            if fast:
                cause += (f"; {fast} faster epoch(s) lie inside {describe_windows(windows)}, "
                          "withheld")
    return ConfigError(f"{what}: {cause}", file=gnss.attrs.get("source") or
                       all_gnss.attrs.get("source"), column="initialization.min_speed")


def _antenna_to_imu(llh: np.ndarray, C: np.ndarray, lever_arm: np.ndarray) -> np.ndarray:
    d = -(C @ lever_arm)
    dlat, dlon, dh = enu_displacement_to_geodetic(llh[0], llh[2], d[0], d[1], d[2])
    return llh + np.array([dlat, dlon, dh])


def initialize(job: Job, inputs: Inputs, model: ImuErrorModel, windows=None) -> Initialization:
    """Initial nominal state of the filter (see the module docstring).

    ``windows`` are the outage windows whose GNSS is withheld (default: the job's,
    :func:`~insgnss.job.windows.outage_windows`). ``initialization.attitude_std_deg`` and
    ``velocity_std``, when given, replace the sigmas the method found.
    """
    init = _initialize(job, inputs, model, windows)
    ini = job["initialization"]
    if ini["attitude_std_deg"] is not None:
        init.att_std = tuple(float(np.radians(v)) for v in ini["attitude_std_deg"])
    if ini["velocity_std"] is not None:
        init.vel_std = float(ini["velocity_std"])
    return init


def _initialize(job: Job, inputs: Inputs, model: ImuErrorModel, windows) -> Initialization:
    ini = job["initialization"]
    imu, all_gnss = inputs.imu, inputs.gnss
    if all_gnss is not None and not len(all_gnss):
        all_gnss = None
    if windows is None:
        windows = outage_windows(job, all_gnss)
    gnss = None if all_gnss is None else outside_windows(all_gnss, windows)
    t0 = float(imu.index[0]) if ini["start_time"] is None else float(ini["start_time"])
    imu = time_slice(imu, t0)
    if len(imu) < 2:
        raise AlignmentError(f"no IMU data after the start time {t0:.3f} s (IMU "
                             f"{float(inputs.imu.index[0]):.3f} .. "
                             f"{float(inputs.imu.index[-1]):.3f} s)", file=job.path,
                             column="initialization.start_time")
    t_last = float(imu.index[-1])
    method = ini["method"]
    given = [ini[k] for k in ("roll_deg", "pitch_deg", "heading_deg")]
    fixed = None if ini["lat_deg"] is None else np.array(  # given start (jobs without GNSS)
        [np.radians(ini["lat_deg"]), np.radians(ini["lon_deg"] or 0.0), ini["height"] or 0.0])
    if gnss is None and inputs.truth is None and fixed is None:
        raise ConfigError("initialization needs GNSS, a simulated truth or initialization."
                          "lat_deg/lon_deg/height for the position", file=job.path,
                          column="inputs.gnss.path")
    if gnss is not None and not len(gnss):
        if inputs.truth is None:
            raise AlignmentError(f"initialization needs a GNSS position, but every GNSS epoch "
                                 f"lies inside {describe_windows(windows)}",
                                 file=all_gnss.attrs.get("source"), column="outages")
        gnss = None  # a simulation: the position from the truth

    def position_at(t, C):
        if gnss is not None:
            return _antenna_to_imu(_gnss_at(gnss, t, windows), C, inputs.lever_arm)
        if inputs.truth is None:
            return fixed
        r = inputs.truth.iloc[inputs.truth.index.get_indexer([t], method="nearest")[0]]
        return np.array([r["lat"], r["lon"], r["height"]])

    pos_std = ini["position_std"]
    cols = ("east_std", "north_std", "up_std")
    if pos_std is None and gnss is not None and all(c in gnss.columns for c in cols):
        # the GNSS sigmas of the run, per axis (east, north, up); finite ones only
        sig = gnss[list(cols)].to_numpy(float)
        ok = np.all(np.isfinite(sig) & (sig > 0), axis=1)
        pos_std = tuple(float(v) for v in np.median(sig[ok], axis=0)) if ok.any() else None
    if pos_std is None:
        pos_std = 1.0
    if method == "gnss_velocity":
        if gnss is None or "vel_e" not in gnss.columns:
            raise ConfigError("gnss_velocity initialization needs GNSS velocity", file=job.path,
                              column="initialization.method")
        # the accelerometer window (1 s around the epoch, or after it) lies inside the IMU data
        k = _moving_epochs(gnss, ini["min_speed"], t0, t_last - 1.0)
        if not k.size:
            raise _no_moving_epoch(gnss, all_gnss, windows, ini["min_speed"], t0, t_last - 1.0,
                                   "gnss_velocity initialization")
        k = int(k[0])
        t_s = float(gnss.index[k])
        hdg = float(np.arctan2(gnss["vel_e"].iloc[k], gnss["vel_n"].iloc[k]))
        if given[0] is None:
            # 1 s around the epoch; after it when the GNSS before is withheld (an outage)
            acc = None
            for a0 in (t_s - 0.5, t_s):
                win = time_slice(imu, a0, a0 + 1.0)
                tw = win.index.to_numpy(float)
                acc = _mean_acceleration(gnss, float(tw[0]), float(tw[-1]))
                if acc is not None:
                    break
            r, p = level_moving(_mean_specific_force(win), np.zeros(3) if acc is None else acc,
                                hdg)
            check_upright(r, p, what="levelling at the gnss_velocity start",
                          file=inputs.imu.attrs.get("source"))
        else:
            r, p = np.radians(given[0]), np.radians(given[1] or 0.0)
        C = euler_to_dcm(r, p, hdg)
        # the first IMU sample at or after the epoch: its position is interpolated between
        # this epoch and the next (the one before may be withheld: an outage window)
        t_imu = float(imu.index[min(int(imu.index.searchsorted(t_s, "left")), len(imu) - 1)])
        # a horizontal-only GNSS velocity (NMEA) starts with zero vertical velocity, inside
        # the initial velocity sigma of a vehicle on a road grade
        vel = np.zeros(3)
        vel[:len(_vel_cols(gnss))] = gnss[_vel_cols(gnss)].iloc[k].to_numpy(float)
        st = NavState(*position_at(t_imu, C), vel, C, t_imu)
        return Initialization(st, method, "gnss_velocity", pos_std=pos_std, vel_std=0.2,
                              att_std=(np.radians(2), np.radians(2),
                                       np.radians(max(ini["course_heading_std_deg"], 5.0))))
    if method == "given":
        if any(v is None for v in given):
            raise ConfigError("given initialization needs roll_deg, pitch_deg and heading_deg",
                              file=job.path, column="initialization")
        r, p, h = np.radians(given)
        C = euler_to_dcm(r, p, h)
        vel = np.zeros(3) if ini["velocity"] is None else np.asarray(ini["velocity"], float)
        st = NavState(*position_at(t0, C), vel, C, t0)
        return Initialization(st, method, "given", pos_std=pos_std)
    # static
    win, static_info, noise_window = _static_window(job, imu, all_gnss, windows, t0)
    heading = None if given[2] is None else np.radians(given[2])
    lat_guess = float(gnss["lat"].iloc[0]) if gnss is not None and len(gnss) else \
        float(inputs.truth["lat"].iloc[0]) if inputs.truth is not None else float(fixed[0])
    max_rate = np.radians(ini["static_max_rate_std_deg"])
    imu_file = inputs.imu.attrs.get("source")
    # deg/s declared as rad/s also fails the stillness test (57 times the noise): name it first
    check_gyro_at_rest(win, model, file=imu_file, max_accel_std=ini["static_max_accel_std"])
    try:
        res = coarse_align(win, lat_guess, 0.0, model=model,
                           heading=heading if heading is not None else 0.0,
                           heading_source="given",
                           max_accel_std=ini["static_max_accel_std"], max_rate_std=max_rate)
    except AlignmentError as exc:  # name the key when the window reaches into motion
        raise static_window_error(exc, win, ini["static_duration"], ini["static_max_accel_std"],
                                  max_rate, file=job.path) from None
    check_upright(res.roll, res.pitch, what="static levelling", file=imu_file)
    w_mean, _, w_static, _, T = static_means(win)
    compass = None
    if heading is not None:
        src = "given"
    else:
        # the preset's bias and the parked data must both allow gyrocompassing (align module)
        compass = gyrocompass_check(model, lat_guess, w_static, res.roll, res.pitch)
        src = "gyrocompass" if compass.feasible else "gnss_course"
        if not compass.feasible:
            warn(f"static alignment: no gyrocompassing because {compass.reason}; levelled, the "
                 "heading comes from the GNSS course once faster than initialization.min_speed",
                 file=job.path, column="initialization.method", expected="a gyrocompass heading "
                 f"1-sigma <= {np.degrees(GYROCOMPASS_MAX_BIAS_RATIO):.3g} deg",
                 found=f"{np.degrees(compass.heading_std):.3g} deg" if
                 compass.heading_std < np.pi else "over 180 deg (no heading information)")
    t_end = res.time
    hdg = res.heading
    if job["filter"]["levelling_correlation"]:
        # the tilt error of levelling is the horizontal accelerometer bias over g, modelled as
        # a correlation with the bias states (FilterConfig.levelling_correlation): the tilt
        # sigma here is only the white-noise part (VRW over the window), floored at 0.02 deg
        T = max(T, 1e-3)
        tilt = max(model.accel_vrw / np.sqrt(T) / 9.81, np.radians(0.02))
        tilt = (tilt, tilt)
    else:
        tilt = (max(res.roll_std, np.radians(0.1)), max(res.pitch_std, np.radians(0.1)))
    att_std = (*tilt, np.radians(5.0))
    motion = None
    if src == "gnss_course" and ini["heading_alignment"] == "in_motion" \
            and GYRO_COLS[0] in win.columns:
        motion = _heading_in_motion(job, imu, gnss, res, w_mean, model, T,
                                    float(win.index[0]))
        if motion is not None and motion.std < min(MAX_MOTION_HEADING_STD,
                                                   np.radians(ini["course_heading_std_deg"])):
            src = "in_motion"
            hdg = motion.offset
            att_std = (att_std[0], att_std[1], max(motion.std, MIN_MOTION_HEADING_STD))
    if src == "gnss_course":
        hdg = _heading_from_course(imu, gnss, all_gnss, windows, res, ini["min_speed"],
                                   w_mean if GYRO_COLS[0] in win.columns else None,
                                   compass.reason)
        att_std = (att_std[0], att_std[1], np.radians(ini["course_heading_std_deg"]))
    elif src == "gyrocompass":
        hdg = gyrocompass(w_mean, res.roll, res.pitch)
        # bias and measured noise over the Earth rate, with the tilt-induced term (Groves 5.108)
        att_std = (*tilt, float(np.hypot(compass.heading_std, res.roll_std * np.tan(lat_guess))))
    C = euler_to_dcm(res.roll, res.pitch, hdg)
    # the vehicle is still over the window, so the aligned attitude holds from its start: the
    # filter runs from there (covering the window, with ZUPT/ZARU if enabled)
    t_begin = float(win.index[0])
    t_pos = t_begin
    if gnss is not None and len(gnss):
        # the platform does not move over the window: any usable GNSS epoch inside it gives
        # the position at its start (the IMU may start just before the first epoch)
        tg = gnss.index.to_numpy(float)
        inside = tg[(tg >= t_begin) & (tg <= float(win.index[-1]))]
        if inside.size and (tg[0] > t_begin):
            t_pos = float(inside[0])
    st = NavState(*position_at(t_pos, C), np.zeros(3), C, t_begin)
    return Initialization(st, method, src, gyro_bias=None, att_std=att_std, pos_std=pos_std,
                          vel_std=0.02, static_end=t_end,
                          levelled=bool(job["filter"]["levelling_correlation"]),
                          noise_window=noise_window, static_info=static_info)


def standing_intervals(gnss: pd.DataFrame | None, windows) -> list[tuple[float, float]]:
    """Intervals between consecutive usable GNSS epochs (outside the outage windows, no gap
    longer than 1.5 epoch intervals) that both show a horizontal speed below
    :data:`STATIC_GNSS_SPEED`: positive evidence that the vehicle stands (none without GNSS
    velocities, or inside an outage)."""
    if gnss is None or not len(gnss) or "vel_e" not in gnss.columns:
        return []
    g = outside_windows(gnss, windows)
    t = g.index.to_numpy(float)
    if t.size < 2:
        return []
    slow = np.hypot(g["vel_e"].to_numpy(float), g["vel_n"].to_numpy(float)) < STATIC_GNSS_SPEED
    pair = slow[:-1] & slow[1:] & (np.diff(t) <= 1.5 * float(np.median(np.diff(t))))
    out: list[tuple[float, float]] = []
    for k in np.flatnonzero(pair):
        if out and out[-1][1] == t[k]:
            out[-1] = (out[-1][0], float(t[k + 1]))
        else:
            out.append((float(t[k]), float(t[k + 1])))
    return out


def gnss_moving_intervals(gnss: pd.DataFrame | None, windows,
                          displacement_sigmas: float | None = None
                          ) -> list[tuple[float, float]]:
    """Intervals around the usable GNSS epochs faster than :data:`STATIC_GNSS_SPEED` (half an
    epoch interval either side): the antenna moved, so the platform is not static there.

    With ``displacement_sigmas`` and the position sigmas in the table, the span between two
    consecutive usable epochs (at most 1.5 median intervals apart) also counts as moving when
    the horizontal displacement between them exceeds ``displacement_sigmas`` times its sigma
    ``sqrt(s_1^2 + s_2^2)``, ``s = hypot(east_std, north_std)``: 2 cm RTK positions resolve
    the first second of a smooth pull-away that the speed limit, sized for single-point
    velocities, misses."""
    if gnss is None or not len(gnss):
        return []
    g = outside_windows(gnss, windows)
    t = g.index.to_numpy(float)
    if t.size < 2:
        return []
    dt = float(np.median(np.diff(t)))
    out: list[tuple[float, float]] = []
    if "vel_e" in g.columns:
        sp = np.hypot(g["vel_e"].to_numpy(float), g["vel_n"].to_numpy(float))
        out += [(float(x) - 0.5 * dt, float(x) + 0.5 * dt) for x in t[sp > STATIC_GNSS_SPEED]]
    if displacement_sigmas and {"east_std", "north_std"} <= set(g.columns):
        e, n, _ = geodetic_to_enu(g["lat"].to_numpy(float), g["lon"].to_numpy(float),
                                  g["height"].to_numpy(float), float(g["lat"].iloc[0]),
                                  float(g["lon"].iloc[0]), float(g["height"].iloc[0]))
        sd = np.hypot(g["east_std"].to_numpy(float), g["north_std"].to_numpy(float))
        step = np.hypot(np.diff(np.asarray(e)), np.diff(np.asarray(n)))
        lim = displacement_sigmas * np.hypot(sd[:-1], sd[1:])
        k = np.flatnonzero((step > lim) & np.isfinite(lim) & (np.diff(t) <= 1.5 * dt))
        out += [(float(t[i]), float(t[i + 1])) for i in k]
    return sorted(out)


def _static_window(job: Job, imu: pd.DataFrame, gnss, windows, t0: float):
    """The static window of a ``static`` initialization (module docstring): ``(imu window,
    info for the summary, truly still noise window or None)``."""
    ini = job["initialization"]
    bridged = [(g["start"], g["end"]) for g in imu.attrs.get("gaps") or []
               if g.get("action") == "bridged"]
    sw = find_static_windows(imu, max_accel_std=ini["static_max_accel_std"],
                             max_rate_std=np.radians(ini["static_max_rate_std_deg"]),
                             exclude=bridged + gnss_moving_intervals(gnss, windows))
    src = imu.attrs.get("source")
    floors = {"accel_floor": sw.accel_floor, "rate_floor_deg_s": float(np.degrees(sw.rate_floor))}
    if ini["static_duration"] is not None:
        t1 = t0 + float(ini["static_duration"])
        a, w = sw.motion(t0, t1)
        still = next(((p, q) for p, q in sw.still if p <= t0 + 0.5 and q >= t1 - 0.5), None)
        info = {"source": "initialization.static_duration", "start": t0, "end": t1,
                "truly_still": still is not None, "accel_std": a,
                "rate_std_deg_s": float(np.degrees(w)), **floors}
        if still is None:
            warn(f"the static window {t0:.3f} .. {t1:.3f} s (initialization.static_duration) "
                 f"is not still: specific-force variation {a:.3f} m/s^2 and angular-rate "
                 f"variation {np.degrees(w):.2f} deg/s (median over 0.5 s windows) against a "
                 f"noise floor of {sw.accel_floor:.3f} m/s^2 and "
                 f"{np.degrees(sw.rate_floor):.2f} deg/s; levelling averages that motion and "
                 "the IMU noise is not measured there", file=src,
                 column="initialization.static_duration")
        return time_slice(imu, None, t1), info, (t0, t1) if still is not None else None
    stationary, still = sw.initial(t0, 0.5)
    if still is not None and still[1] - still[0] >= MIN_STATIC:
        a0, a1 = t0, still[1]
        truly = True
    elif stationary is not None and stationary[1] - stationary[0] >= MIN_STATIC:
        a0, a1 = t0, stationary[1]
        truly = False
    else:
        a, w = sw.motion(t0, t0 + 2.0)
        raise AlignmentError(
            f"no static window at the start of the IMU data ({t0:.3f} s): the IMU is not still "
            f"for {MIN_STATIC:g} s (specific-force variation {a:.3f} m/s^2, angular rate "
            f"{np.degrees(w):.2f} deg/s over the first 2 s; stillness limits "
            f"{ini['static_max_accel_std']:g} m/s^2 and {ini['static_max_rate_std_deg']:g} "
            "deg/s), or the GNSS shows motion; start later (initialization.start_time) or use "
            "method = \"gnss_velocity\"", file=src, column="initialization.method")
    a, w = sw.motion(a0, a1)
    info = {"source": "found", "start": a0, "end": a1, "truly_still": truly, "accel_std": a,
            "rate_std_deg_s": float(np.degrees(w)), **floors}
    if not truly:
        warn(f"the IMU is not truly still at the start: the stationary window {a0:.3f} .. "
             f"{a1:.3f} s shows a specific-force variation of {a:.3f} m/s^2 and an angular-rate "
             f"variation of {np.degrees(w):.2f} deg/s against a noise floor of "
             f"{sw.accel_floor:.3f} m/s^2 and {np.degrees(sw.rate_floor):.2f} deg/s (a hand-held "
             "device?); levelling averages that motion and the IMU noise is not measured there",
             file=src, column="initialization.static_duration")
    return time_slice(imu, a0, a1), info, (a0, a1) if truly else None


def _heading_in_motion(job: Job, imu, gnss, res, w_mean, model: ImuErrorModel,
                       static_T: float, t_begin: float):
    """In-motion heading alignment after the static window (:func:`insgnss.align.heading_in_motion`):
    a free-inertial run from the levelled attitude with heading 0 over at most
    :data:`MOTION_WINDOW` seconds, its antenna displacements matched to the GNSS displacements
    from the mean usable GNSS position over the static window (the platform is still there),
    up to the first gap longer than :data:`MOTION_MAX_GAP` between the epochs after it (an
    outage). The static mean rate minus the Earth rate of the
    heading-0 attitude is removed from the gyros (the heading-0 run then sees the Earth rate a
    perfect IMU would see at heading 0). None without GNSS velocity-free positions to match or
    with too little motion."""
    if gnss is None or len(gnss) < 3:
        return None
    t_s = res.time
    still = time_slice(gnss, t_begin, t_s)
    g = time_slice(gnss, np.nextafter(t_s, np.inf), t_s + MOTION_WINDOW)
    tg = g.index.to_numpy(float)
    if not len(still) or tg.size < 3:
        return None
    gaps = np.flatnonzero(np.diff(tg) > MOTION_MAX_GAP)
    if gaps.size:
        g, tg = g.iloc[:gaps[0] + 1], tg[:gaps[0] + 1]
    # the platform is still over the static window: its usable epochs give the start point
    lat0, lon0, h0 = (float(still[c].mean()) for c in ("lat", "lon", "height"))
    e, n, _ = geodetic_to_enu(g["lat"].to_numpy(float), g["lon"].to_numpy(float),
                              g["height"].to_numpy(float), lat0, lon0, h0)
    y = np.column_stack([np.asarray(e), np.asarray(n)])
    seg = time_slice(imu, t_s, min(float(tg[-1]) + 0.1, float(imu.index[-1]))).copy()
    if len(seg) < 3:
        return None
    C0 = euler_to_dcm(res.roll, res.pitch, 0.0)
    seg[GYRO_COLS] = seg[GYRO_COLS].to_numpy() - (w_mean - C0.T @ earth_rate_l(lat0))

    x0 = NavState.from_euler(lat0, lon0, h0, (0, 0, 0), res.roll, res.pitch, 0.0, time=t_s)
    m = mechanize(seg, x0, fix_height=True)
    tm = m.index.to_numpy(float)
    tg = tg[tg <= tm[-1]]
    if tg.size < 3:
        return None
    y = y[:tg.size]
    ie, in_, _ = geodetic_to_enu(m["lat"].to_numpy(float), m["lon"].to_numpy(float),
                                 m["height"].to_numpy(float), lat0, lon0, h0)
    C = euler_to_dcm(m["roll"].to_numpy(float), m["pitch"].to_numpy(float),
                     m["heading"].to_numpy(float))
    lever = np.asarray(job["inputs"]["gnss"]["lever_arm"], float)
    ant = np.column_stack([ie, in_]) + (C @ lever)[:, :2] - (C0 @ lever)[:2]
    # body rotation from the start attitude: angle of C0^T C
    rot = np.arccos(np.clip(0.5 * (np.einsum("ij,kij->k", C0, C) - 1.0), -1.0, 1.0))
    drift = free_inertial_drift_std(tm - t_s, rot, model, static_T)
    turned = np.abs(np.unwrap(m["heading"].to_numpy(float)) - float(m["heading"].iloc[0]))
    k = np.clip(np.searchsorted(tm, tg), 0, tm.size - 1)
    x = ant[k]
    sg = MOTION_GNSS_STD
    if "east_std" in g.columns and "north_std" in g.columns:
        sg = float(np.nanmedian(np.hypot(g["east_std"], g["north_std"])) / np.sqrt(2.0))
        sg = sg if np.isfinite(sg) and sg > 0 else MOTION_GNSS_STD
    out = heading_in_motion(tg, x, y, drift[k], np.sqrt(2.0) * sg,
                            angle_std=model.gyro_scale * turned[k])
    if out is None:
        return None
    return MotionHeading(float(np.mod(out.offset, 2 * np.pi)), out.std, out.end, out.distance,
                         out.n)


def _heading_from_course(imu, gnss, all_gnss, windows, res, min_speed, w_mean,
                         why: str = "") -> float:
    """Heading at the end of the static window: the course over ground at the first usable
    GNSS epoch faster than ``min_speed`` minus the heading change the gyros measured since
    (``why``: the reason gyrocompassing was not used, for the message)."""
    if gnss is None or "vel_e" not in gnss.columns:
        raise ConfigError(f"the IMU cannot gyrocompass{' (' + why + ')' if why else ''}: give "
                          "initialization.heading_deg or GNSS velocity",
                          column="initialization.heading_deg")
    t_last = float(imu.index[-1])
    k = _moving_epochs(gnss, min_speed, res.time, t_last, strict=True)
    if not k.size:
        raise _no_moving_epoch(gnss, all_gnss, windows, min_speed, res.time, t_last,
                               "cannot get the heading from the GNSS course")
    k = int(k[0])
    tm = float(gnss.index[k])
    course = float(np.arctan2(gnss["vel_e"].iloc[k], gnss["vel_n"].iloc[k]))
    seg = time_slice(imu, res.time, tm)
    if w_mean is not None and GYRO_COLS[0] in seg.columns:  # remove the static gyro bias
        seg = seg.copy()
        seg[GYRO_COLS] = seg[GYRO_COLS].to_numpy() - w_mean
    lat = float(gnss["lat"].iloc[0])
    x = NavState.from_euler(lat, float(gnss["lon"].iloc[0]), float(gnss["height"].iloc[0]),
                            (0, 0, 0), res.roll, res.pitch, 0.0, time=res.time)
    m = mechanize(seg, x, fix_height=True)
    return float(np.mod(course - m["heading"].iloc[-1], 2 * np.pi))


__all__ = ["Initialization", "gnss_moving_intervals", "initialize"]
