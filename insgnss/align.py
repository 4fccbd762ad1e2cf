"""Initial alignment: accelerometer levelling, gyrocompassing, heading from GNSS velocity or a
tilt-compensated magnetometer.

Static coarse alignment (Noureldin et al. 2013 section 5.6; Groves 2013
section 5.6). At rest the mean specific force and angular rate in the body frame (RFU) are::

    f^b = C_l^b (0, 0, g)              ->  roll  = atan2(-f_x, f_z)
                                           pitch = atan2(f_y, sqrt(f_x^2 + f_z^2))
    w^b = C_l^b (0, we cos L, we sin L)  -> levelled w' = Rx(p) Ry(r) w^b  (eqs. 3-4)
                                           heading = atan2(-w'_x, w'_y)    (eq. 5)

(the ``asin`` forms of the levelling equations are equivalent for |tilt| < 90 deg; ``atan2`` keeps full
precision near +-90 deg and needs no ``sign(f_z)``).

Expected accuracy (Groves eqs. 5.107-5.108): the tilt error is dominated by the horizontal
accelerometer bias, ``sigma_tilt ~ sigma_ba / g``; the heading error by the east gyro bias,
``sigma_A ~ sigma_bg / (we cos L)`` (plus white-noise terms shrinking with sqrt(T)).

Gyrocompassing needs a gyro bias well below the horizontal Earth rate (15 deg/h cos L): it
works with navigation and ring-laser/FOG tactical grades and is impossible with MEMS gyros,
tactical MEMS included (in-run stability of about 1 deg/h, but a turn-on bias of tens to hundreds
of deg/h; consumer parts 10-1000 deg/h). For those the heading comes from GNSS velocity once
moving, a magnetometer, or is given; :func:`default_heading_source` picks per grade.

In-motion heading alignment (:func:`heading_in_motion`): the free-inertial path after a static
levelling, computed with heading 0, is the true path turned about its start by the heading;
matching it to the GNSS displacements gives the IMU's own heading (no side-slip assumption),
each epoch weighted by the modelled inertial drift over the distance travelled
(:func:`free_inertial_drift_std`).

Feasibility from the data (:func:`gyrocompass_check`): the preset's bias is a claim about the
part, the parked window is evidence. Gyrocompassing is used only when both allow the heading
sigma it would report:

1. the bias plus the white noise of the mean, with the noise *measured* in the window (engine
   vibration included), ``sqrt(sigma_bg^2 + s_w^2 / N)``, is below
   :data:`GYROCOMPASS_MAX_BIAS_RATIO` of the horizontal Earth rate ``we cos L``;
2. the levelled horizontal mean rate agrees with the Earth rate: ``| |w_h| - we cos L |`` is a
   lower bound of the horizontal gyro bias, so when it exceeds the same fraction the gyros are
   demonstrably biased beyond what gyrocompassing tolerates, whatever the preset says (a parked
   MEMS unit reading 130 deg/h horizontally, 12 x Earth rate, would be 30-35 deg off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .attitude import Rx, Ry, euler_to_dcm
from .earth import OMEGA_E, normal_gravity
from .errors import AlignmentError
from .imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS, ImuErrorModel, is_increment_table

#: largest gyro bias (1-sigma) for which gyrocompassing is chosen by default, as a fraction of
#: the horizontal Earth rate: at 0.25 the heading error is about 14 deg (1-sigma), still a
#: usable start for a filter; consumer MEMS gyros are 10-100x above it.
GYROCOMPASS_MAX_BIAS_RATIO = 0.25


@dataclass
class AlignmentResult:
    """Result of an alignment: angles [rad], their expected 1-sigma [rad], and the DCM."""

    roll: float
    pitch: float
    heading: float
    roll_std: float
    pitch_std: float
    heading_std: float
    heading_source: str
    time: float
    C: np.ndarray

    def as_degrees(self) -> dict:
        return {k: float(np.degrees(getattr(self, k))) for k in
                ("roll", "pitch", "heading", "roll_std", "pitch_std", "heading_std")}


def level(f_mean) -> tuple[float, float]:
    """Roll and pitch [rad] from the mean specific force in the body frame (RFU)."""
    fx, fy, fz = np.asarray(f_mean, float)
    return float(np.arctan2(-fx, fz)), float(np.arctan2(fy, np.hypot(fx, fz)))


def level_moving(f_mean, accel_enu, heading: float, iterations: int = 4
                 ) -> tuple[float, float]:
    """Roll and pitch [rad] of a moving vehicle from the mean specific force ``f_mean`` (body
    RFU) and the mean kinematic acceleration ``accel_enu`` [m/s^2] over the same interval (from
    GNSS velocity), with the heading known.

    ``f^b = C_l^b (a^l + (0, 0, g))``: levelling ``f^b`` alone (:func:`level`) tilts the
    attitude by ``atan(a / g)`` - 14 deg at 2.5 m/s^2 of braking. The body-frame acceleration
    ``C_l^b a^l`` is removed with the attitude of the previous iteration and the rest
    levelled; the error contracts by ``|a| / g`` per iteration, so a few iterations suffice
    for a land vehicle. With ``accel_enu = 0`` this is :func:`level`.
    """
    f = np.asarray(f_mean, float)
    a = np.asarray(accel_enu, float)
    r, p = level(f)
    for _ in range(iterations):
        C = euler_to_dcm(r, p, heading)
        r, p = level(f - C.T @ a)  # the rest is C_l^b (0, 0, g): vertical up
    return r, p


def gyrocompass(w_mean, roll: float, pitch: float) -> float:
    """Heading [rad, 0..2pi) from the mean angular rate of a static IMU (gyrocompassing)."""
    wl = Rx(pitch) @ Ry(roll) @ np.asarray(w_mean, float)
    return float(np.mod(np.arctan2(-wl[0], wl[1]), 2 * np.pi))


def magnetic_heading(mag, roll: float, pitch: float, declination: float = 0.0) -> float:
    """Tilt-compensated magnetometer heading [rad]; ``mag`` in the body frame (RFU), any unit.

    The levelled field ``Rx(p) Ry(r) m`` has its horizontal part along magnetic north, so the
    same formula as gyrocompassing applies; the declination (east positive) is added.
    """
    ml = Rx(pitch) @ Ry(roll) @ np.asarray(mag, float)
    return float(np.mod(np.arctan2(-ml[0], ml[1]) + declination, 2 * np.pi))


def heading_from_velocity(vel_e, vel_n, min_speed: float = 2.0):
    """Course over ground [rad] from ENU velocity; NaN where the horizontal speed < min_speed.

    Equals the vehicle heading for a land vehicle without side slip (body y = forward).
    """
    ve, vn = np.asarray(vel_e, float), np.asarray(vel_n, float)
    hdg = np.mod(np.arctan2(ve, vn), 2 * np.pi)
    return np.where(np.hypot(ve, vn) >= min_speed, hdg, np.nan)


def can_gyrocompass(model: ImuErrorModel, lat: float) -> bool:
    """True if the gyro bias is small enough for gyrocompassing at latitude ``lat``."""
    horizontal = OMEGA_E * abs(np.cos(lat))
    bias = np.hypot(model.gyro_bias, model.gyro_bias_instability)
    return bool(bias < GYROCOMPASS_MAX_BIAS_RATIO * horizontal)


@dataclass
class GyrocompassCheck:
    """Outcome of :func:`gyrocompass_check`: ``feasible``, the expected heading 1-sigma of a
    gyrocompass [rad] from the preset bias and the measured noise, the levelled horizontal
    mean rate measured and the horizontal Earth rate [rad/s], and ``reason`` (why not; empty
    when feasible)."""

    feasible: bool
    heading_std: float
    measured_horizontal: float
    earth_horizontal: float
    reason: str = ""


def gyrocompass_check(model: ImuErrorModel, lat: float, w: np.ndarray, roll: float,
                      pitch: float) -> GyrocompassCheck:
    """Can the static samples ``w`` (N, 3) [rad/s, body RFU], levelled with ``roll, pitch``,
    give a heading by gyrocompassing at latitude ``lat``? (module docstring, tests 1-2).

    The white-noise term uses the sample standard deviation of ``w`` per axis (largest
    horizontal-plane value after levelling), so vibration of a running engine counts.
    """
    w = np.asarray(w, float)
    horizontal = OMEGA_E * abs(np.cos(lat))
    limit = GYROCOMPASS_MAX_BIAS_RATIO * horizontal
    L = Rx(pitch) @ Ry(roll)
    wl = w @ L.T
    n = max(wl.shape[0], 1)
    noise = float(np.max(np.std(wl[:, :2], axis=0))) / np.sqrt(n) if wl.shape[0] > 1 else 0.0
    bias = float(np.hypot(model.gyro_bias, model.gyro_bias_instability))
    sigma = float(np.hypot(bias, noise))
    wh = float(np.hypot(*wl[:, :2].mean(0)))
    excess = abs(wh - horizontal)
    hdg_std = sigma / horizontal if horizontal > 0 else np.inf
    dh = np.degrees(3600.0)
    if horizontal <= 0 or not np.isfinite(hdg_std):
        reason = "the horizontal Earth rate vanishes at the pole"
    elif bias >= limit:
        reason = (f"the gyro bias of the IMU model ({bias * dh:.3g} deg/h, "
                  f"{model.name or 'custom'}) is above {GYROCOMPASS_MAX_BIAS_RATIO:g} x the "
                  f"horizontal Earth rate ({horizontal * dh:.3g} deg/h)")
    elif sigma >= limit:
        reason = (f"the gyro noise measured in the static window ({noise * dh:.3g} deg/h on the "
                  f"mean of {n} samples, with the bias {bias * dh:.3g} deg/h) is above "
                  f"{GYROCOMPASS_MAX_BIAS_RATIO:g} x the horizontal Earth rate "
                  f"({horizontal * dh:.3g} deg/h)")
    elif excess >= limit + 3.0 * sigma:
        reason = (f"the parked gyros read {wh * dh:.3g} deg/h horizontally against an Earth "
                  f"rate of {horizontal * dh:.3g} deg/h: a gyro bias of at least "
                  f"{excess * dh:.3g} deg/h, far above the {bias * dh:.3g} deg/h of the IMU "
                  f"model ({model.name or 'custom'}); gyrocompassing would be wrong by tens of "
                  "degrees")
    else:
        return GyrocompassCheck(True, float(hdg_std), wh, horizontal)
    return GyrocompassCheck(False, float(hdg_std), wh, horizontal, reason)


def default_heading_source(model: ImuErrorModel, lat: float) -> str:
    """``"gyrocompass"`` for navigation/tactical grades, ``"given"`` otherwise (consumer MEMS:
    use a given heading, GNSS velocity or a magnetometer)."""
    return "gyrocompass" if can_gyrocompass(model, lat) else "given"


def static_means(imu: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """``(w_mean, f_mean, w, f, T)``: mean angular rate [rad/s] and specific force [m/s^2] of
    a static window (rates as recorded, increments over their interval), the samples and the
    window length [s]."""
    t = np.asarray(imu.index, float)
    if t.size < 2:
        raise AlignmentError("alignment window holds fewer than 2 IMU samples",
                             expected=">= 2 samples", found=t.size)
    if is_increment_table(imu):
        dt = np.diff(t)[:, None]
        w = imu[DTHETA_COLS].to_numpy(float)[1:] / dt
        f = imu[DV_COLS].to_numpy(float)[1:] / dt
    else:
        w = imu[GYRO_COLS].to_numpy(float)
        f = imu[ACCEL_COLS].to_numpy(float)
    return w.mean(0), f.mean(0), w, f, float(t[-1] - t[0])


def check_static(f: np.ndarray, w: np.ndarray, g: float, model: ImuErrorModel | None,
                 dt: float, *, max_accel_std: float | None = None,
                 max_rate: float | None = None, t0: float = 0.0) -> None:
    """Raise :class:`AlignmentError` if the samples do not look static.

    Thresholds: the specific force must vary by less than ``max_accel_std`` (1-sigma, all axes)
    (default: 5x the white noise of ``model`` plus 0.05 m/s^2 for vibration), its mean must be
    within 5 % of gravity, and the angular rate must vary by less than ``max_rate`` (default:
    1 deg/s or 5x the white gyro noise, whichever is larger).
    """
    norm = np.linalg.norm(f, axis=1)
    noise = 0.0 if model is None else model.accel_vrw / np.sqrt(dt)
    lim_f = max_accel_std if max_accel_std is not None else 0.05 + 5.0 * noise
    # motion first: a window that reaches into motion also has a mean norm away from g, and
    # blaming the units for it would send the user to the wrong fix
    fstd = float(np.sqrt(np.sum(np.var(f, axis=0))))
    if fstd > lim_f:
        raise AlignmentError(
            f"the alignment window starting at t={t0:.3f} s is not static: the specific force "
            f"varies by {fstd:.3f} m/s^2 (1-sigma)",
            expected=f"<= {lim_f:.3f} m/s^2", found=f"{fstd:.3f} m/s^2")
    if abs(norm.mean() - g) > 0.05 * g:
        raise AlignmentError(
            f"mean specific-force norm {norm.mean():.3f} m/s^2 is not gravity ({g:.3f} m/s^2) "
            "although the window is still: accelerometer units wrong (g declared as m/s^2, or "
            "increments declared as rates?)", expected="|f| ~ g", found=f"{norm.mean():.3f}")
    gyro_noise = 0.0 if model is None else model.gyro_arw / np.sqrt(dt)
    lim_w = max_rate if max_rate is not None else max(np.radians(1.0), 5.0 * gyro_noise)
    wstd = float(np.sqrt(np.sum(np.var(w, axis=0))))
    if wstd > lim_w:
        raise AlignmentError(
            f"the alignment window starting at t={t0:.3f} s is not static: the angular rate "
            f"varies by {np.degrees(wstd):.2f} deg/s (1-sigma)",
            expected=f"<= {np.degrees(lim_w):.2f} deg/s", found=f"{np.degrees(wstd):.2f} deg/s")


def alignment_std(model: ImuErrorModel, lat: float, duration: float, g: float = 9.80665,
                  heading_source: str = "gyrocompass") -> tuple[float, float, float]:
    """Expected 1-sigma roll, pitch and heading errors [rad] of a static coarse alignment.

    ``sigma_tilt = sqrt(sigma_ba^2 + VRW^2 / T) / g`` and, for gyrocompassing,
    ``sigma_A = sqrt(sigma_bg^2 + ARW^2 / T) / (we cos L)`` combined with the tilt-induced term
    ``sigma_tilt tan L`` (Groves eqs. 5.107-5.108). Other heading sources return NaN for the
    heading (their accuracy depends on the source).
    """
    T = max(duration, 1e-9)
    ba = np.hypot(model.accel_bias, model.accel_bias_instability)
    tilt = np.sqrt(ba**2 + model.accel_vrw**2 / T) / g
    if heading_source != "gyrocompass":
        return float(tilt), float(tilt), float("nan")
    bg = np.hypot(model.gyro_bias, model.gyro_bias_instability)
    hdg = np.sqrt((bg**2 + model.gyro_arw**2 / T) / (OMEGA_E * np.cos(lat)) ** 2
                  + (tilt * np.tan(lat)) ** 2)
    return float(tilt), float(tilt), float(hdg)


def coarse_align(
    imu: pd.DataFrame,
    lat: float,
    height: float = 0.0,
    *,
    model: ImuErrorModel | None = None,
    heading: float | None = None,
    heading_source: str | None = None,
    mag=None,
    declination: float = 0.0,
    gravity_model: str = "somigliana",
    check: bool = True,
    max_accel_std: float | None = None,
    max_rate_std: float | None = None,
) -> AlignmentResult:
    """Static coarse alignment over all samples of ``imu`` (select the window before calling).

    Parameters
    ----------
    imu : DataFrame
        Static IMU samples (rates or increments, body RFU).
    lat, height : float
        Position [rad, m].
    model : ImuErrorModel, optional
        IMU error model, used for the reported standard deviations, the stillness test and
        the default heading source. Without it the stds are NaN and gyrocompassing is used.
    heading : float, optional
        Given heading [rad] (``heading_source="given"``).
    heading_source : {"gyrocompass", "given", "magnetometer"}, optional
        Default: gyrocompass if the grade and the data allow it (:func:`gyrocompass_check`),
        else "given" (then ``heading`` is required).
    mag : array_like, optional
        Mean magnetometer vector in body RFU for ``heading_source="magnetometer"``.
    check : bool
        Raise :class:`AlignmentError` if the window is not static.
    max_accel_std : float, optional
        Stillness limit on the specific-force variation [m/s^2] (default: from the noise of
        ``model``; a parked car with the engine running needs ~0.5).
    max_rate_std : float, optional
        Stillness limit on the angular-rate variation [rad/s] (default 1 deg/s or 5x the white
        gyro noise).
    """
    w_mean, f_mean, w, f, T = static_means(imu)
    g = normal_gravity(lat, height, gravity_model)
    if check:
        dt = T / max(len(imu) - 1, 1)
        check_static(f, w, g, model, dt, t0=float(imu.index[0]), max_accel_std=max_accel_std,
                     max_rate=max_rate_std)
    roll, pitch = level(f_mean)
    why = f"gyro bias above {GYROCOMPASS_MAX_BIAS_RATIO:g} x the horizontal Earth rate"
    if heading_source is None:
        if heading is not None:
            heading_source = "given"
        elif mag is not None:
            heading_source = "magnetometer"
        elif model is None:
            heading_source = "gyrocompass"
        else:
            check_ = gyrocompass_check(model, lat, w, roll, pitch)
            heading_source = "gyrocompass" if check_.feasible else "given"
            why = check_.reason
    if heading_source == "gyrocompass":
        A = gyrocompass(w_mean, roll, pitch)
    elif heading_source == "magnetometer":
        if mag is None:
            raise AlignmentError("heading_source='magnetometer' needs the magnetometer vector")
        A = magnetic_heading(mag, roll, pitch, declination)
    elif heading_source == "given":
        if heading is None:
            raise AlignmentError(
                f"gyrocompassing is impossible here ({why}): give an initial heading, a "
                "magnetometer or use GNSS velocity heading", expected="heading=...",
                found="none")
        A = float(np.mod(heading, 2 * np.pi))
    else:
        raise AlignmentError(f"unknown heading source {heading_source!r}",
                             expected="gyrocompass, given or magnetometer", found=heading_source)
    if model is None:
        stds = (np.nan, np.nan, np.nan)
    else:
        stds = alignment_std(model, lat, T, g, heading_source)
    return AlignmentResult(roll, pitch, A, *stds, heading_source=heading_source,
                           time=float(imu.index[-1]), C=euler_to_dcm(roll, pitch, A))


@dataclass(frozen=True)
class MotionHeading:
    """Result of :func:`heading_in_motion`: the heading offset [rad] to add to the free-inertial
    run's heading, its 1-sigma [rad], the last epoch used, the GNSS displacement there [m] and
    the number of epochs fitted."""

    offset: float
    std: float
    end: float
    distance: float
    n: int


def free_inertial_drift_std(t, rotation, model: ImuErrorModel, static_duration: float,
                            g: float = 9.80665) -> np.ndarray:
    """Horizontal position error (1-sigma per axis, m) of a free-inertial run started at rest
    from a static levelling, at the times ``t`` [s since the start, increasing].

    ``rotation`` is the body's rotation angle [rad] from its start attitude at ``t``. The terms,
    each integrated twice from the specific-force error (Groves 2013 sec. 5.7 and 14.2):

    - velocity random walk: ``vrw t^1.5 / sqrt(3)``;
    - accelerometer bias: levelling absorbs it into the tilt while the body keeps its start
      attitude; a rotation ``theta`` turns the body-axis bias against the level-frame tilt by
      ``2 sin(theta / 2) sigma_ba`` (the same physics as a real turn); the in-run instability
      adds ``sigma_bi t^2 / 2``;
    - gyro: the bias left after removing the static mean (the mean's noise ``arw / sqrt(T)``
      and the in-run instability) tilts the platform linearly, ``g b t^3 / 6``; the angle random
      walk as ``g arw t^2.5 / sqrt(20)``.
    """
    t = np.asarray(t, float)
    rot = np.asarray(rotation, float)
    a_rot = model.accel_bias * 2.0 * np.abs(np.sin(0.5 * rot))
    # double integral of a(s): p(t) = int_0^t (t - s) a(s) ds (fully correlated, conservative)
    dt = np.diff(t, prepend=t[0])
    v = np.cumsum(a_rot * dt)
    p_rot = np.cumsum(v * dt)
    b_g = np.hypot(model.gyro_arw / np.sqrt(max(static_duration, 1e-3)),
                   model.gyro_bias_instability)
    terms = (model.accel_vrw * t ** 1.5 / np.sqrt(3.0), p_rot,
             0.5 * model.accel_bias_instability * t ** 2, g * b_g * t ** 3 / 6.0,
             g * model.gyro_arw * t ** 2.5 / np.sqrt(20.0))
    return np.sqrt(sum(x ** 2 for x in terms))


def heading_in_motion(t, ins_disp, gnss_disp, drift_std, gnss_std: float,
                      angle_std=None) -> MotionHeading | None:
    """In-motion heading alignment: the rotation about the vertical that maps the horizontal
    displacements of a free-inertial run (started with heading 0 from a static levelling) onto
    the GNSS displacements over the same epochs.

    A heading error ``psi`` at the start of a free-inertial run turns the whole computed path
    about the start point by ``psi`` (the gyros measure the turns; the levelled accelerometers
    the accelerations along the body axes), whatever the platform does: it needs no relation
    between the device's axes and the direction of travel (a hand-held device, a side-slipping
    or reversing vehicle). With the displacements as complex numbers ``z = north + i east``
    (argument = azimuth), each epoch is an azimuth measurement ``arg(y_k conj(x_k))`` with
    sigma ``s_k = hypot(drift_k, gnss_std) / |y_k|`` (plus ``angle_std``: e.g. the gyro scale
    factor times the angle turned). The fit uses the epochs up to the one of smallest ``s_k``
    (past it the inertial drift grows faster than the distance): the weighted circular mean
    ``psi = arg(sum w_k y_k conj(x_k) / |y_k conj(x_k)|)``, ``w_k = 1 / s_k^2``, with the
    sigma of fully correlated errors ``sum w_k s_k / sum w_k``, scaled up by the RMS of the
    normalised residuals when that exceeds 1.

    Parameters
    ----------
    t : array (n,)
        Epochs [s], increasing.
    ins_disp, gnss_disp : array (n, 2)
        East, north displacement [m] from the start of the free-inertial run (heading 0) and of
        the GNSS (the same antenna point).
    drift_std : array (n,)
        1-sigma per-axis position error of the free-inertial run (:func:`free_inertial_drift_std`).
    gnss_std : float
        1-sigma per-axis error of a GNSS displacement [m].
    angle_std : array (n,), optional
        Further azimuth error of each epoch [rad].

    Returns
    -------
    MotionHeading or None
        None when no epoch gives an azimuth sigma below 0.3 rad (too little motion).

    References
    ----------
    Groves 2013, sec. 14.2.3 (heading from GNSS velocity and the IMU); the attitude
    determination by vector matching of the optimisation-based alignment (Wu and Pan 2013,
    IEEE TAES 49(4)) reduced to the one unknown angle left after levelling.
    """
    t = np.asarray(t, float)
    x = np.asarray(ins_disp, float)
    y = np.asarray(gnss_disp, float)
    zx = x[:, 1] + 1j * x[:, 0]
    zy = y[:, 1] + 1j * y[:, 0]
    dist = np.abs(zy)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.hypot(np.asarray(drift_std, float), gnss_std) / dist
        if angle_std is not None:
            s = np.hypot(s, np.asarray(angle_std, float))
    ok = np.isfinite(s) & (s < 0.3) & (np.abs(zx) > 0)
    if not ok.any():
        return None
    k = int(np.flatnonzero(ok)[np.argmin(s[ok])])
    use = ok & (np.arange(t.size) <= k)
    w = 1.0 / s[use] ** 2
    u = zy[use] * np.conj(zx[use])
    u = u / np.abs(u)
    psi = float(np.angle(np.sum(w * u)))
    std = float(np.sum(w * s[use]) / np.sum(w))
    r = np.angle(u * np.exp(-1j * psi)) / s[use]
    std *= max(1.0, float(np.sqrt(np.mean(r ** 2))))
    return MotionHeading(psi, std, float(t[k]), float(dist[k]), int(use.sum()))
