"""Sanity checks for the most common set-up mistakes, each with a message that names the likely
cause and the key that fixes it.

The readers already reject values no declared unit can explain (``insgnss.validate``: a
specific force far from 1 g, rates above 0.5 rad/s at rest). The checks here use what only
the job knows - that a window is still, the IMU grade, the levelled attitude - to catch the
mistakes that pass those bounds:

- **Upside-down or sideways body frame.** At rest the vehicle (body) frame is upright, so the
  levelled roll lies within a few degrees of zero. ``|roll| > 90 deg`` means the body up axis
  points down: the axis map or the mounting is wrong (a forward-right-down sensor declared as
  right-forward-up levels at roll = 180 deg). ``|pitch| > 70 deg`` means the forward axis is
  nearly vertical (two axes swapped).
- **deg/s declared as rad/s.** At rest a gyro measures the Earth rate
  ``omega_ie = 7.29e-5 rad/s`` plus its bias. Data in deg/s declared as rad/s reads 57.3 times
  more: a consumer MEMS gyro with a 0.1-1 deg/s offset then reads 0.1-1 "rad/s" at rest, far
  above the Earth rate and above any bias the filter's IMU model allows; the white noise is
  57.3 times the grade's as well. The check compares the mean rate at rest with
  :data:`GYRO_REST_MAX` (or five times the model's bias bound when that is larger) and reports
  both ratios.
- **Latitude in degrees where radians are meant.** A native table's ``lat`` column is in
  radians (``lat_deg`` holds degrees); ``|lat| > pi/2`` cannot be radians.
- **A static window that reaches into motion** (:func:`static_window_error`): the message
  says how long the IMU is still and names ``initialization.static_duration``.

References: Groves (2013), *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
Systems*, 2nd ed., sections 5.6 (alignment) and 4.4 (MEMS sensor errors).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .earth import OMEGA_E
from .errors import AlignmentError, InvalidValueError, UnitError
from .imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS, ImuErrorModel, is_increment_table

#: largest mean angular rate [rad/s] accepted at rest without a model that allows more
#: (1.15 deg/s: 270 times the Earth rate, 11 times the consumer grade's turn-on bias; deg/s
#: data declared as rad/s reads 57.3 times its offset, so 0.02 "rad/s" is an offset of only
#: 0.35 deg/s)
GYRO_REST_MAX = 0.02
#: levelled roll beyond which the body up axis points down [rad]
MAX_UPRIGHT_ROLL = np.radians(90.0)
#: levelled pitch beyond which the forward axis is nearly vertical [rad]
MAX_UPRIGHT_PITCH = np.radians(70.0)
#: block length of :func:`still_duration` [s]
STILL_BLOCK = 0.5


def _rates(imu: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, angular rate [rad/s] and specific force [m/s^2] of a rate or increment table."""
    t = imu.index.to_numpy(float)
    if is_increment_table(imu):
        dt = np.diff(t)[:, None]
        return t[1:], imu[DTHETA_COLS].to_numpy(float)[1:] / dt, \
            imu[DV_COLS].to_numpy(float)[1:] / dt
    return t, imu[GYRO_COLS].to_numpy(float), imu[ACCEL_COLS].to_numpy(float)


def check_upright(roll: float, pitch: float, *, what: str, file=None,
                  column: str | None = "inputs.imu.axis_map") -> None:
    """Raise :class:`~insgnss.errors.AlignmentError` when a levelled attitude at rest is
    upside down or pitched up to the vertical (module docstring).

    ``roll``, ``pitch`` [rad]; ``what`` says where they come from (``"static levelling"``).
    """
    r, p = float(roll), float(pitch)
    if abs(r) > MAX_UPRIGHT_ROLL:
        raise AlignmentError(
            f"{what} gives roll {np.degrees(r):.1f} deg: the body up axis points down. The axis "
            "map or the mounting is wrong (a forward-right-down sensor declared as "
            "right-forward-up levels at roll 180 deg: declare inputs.imu.axis_map = "
            "\"y,x,-z\" or inputs.imu.sensor_axes = \"frd\", or the mounting_deg of the sensor)",
            file=file, column=column, expected=f"|roll| <= {np.degrees(MAX_UPRIGHT_ROLL):.0f} "
            "deg for a vehicle at rest", found=f"{np.degrees(r):.1f} deg")
    if abs(p) > MAX_UPRIGHT_PITCH:
        raise AlignmentError(
            f"{what} gives pitch {np.degrees(p):.1f} deg: the body forward axis is nearly "
            "vertical. Two axes are probably swapped in the axis map or the mounting",
            file=file, column=column, expected=f"|pitch| <= {np.degrees(MAX_UPRIGHT_PITCH):.0f} "
            "deg for a vehicle at rest", found=f"{np.degrees(p):.1f} deg")


def check_gyro_at_rest(imu: pd.DataFrame, model: ImuErrorModel | None = None, *, file=None,
                       column: str = "inputs.imu.gyro_unit",
                       max_accel_std: float | None = None) -> None:
    """Raise :class:`~insgnss.errors.UnitError` when the mean angular rate of a still window
    is far above the Earth rate and the bias the IMU model allows (module docstring): the
    likely cause is gyro data in deg/s declared as rad/s.

    ``imu`` is a window meant to be still (rates or increments, body RFU); with
    ``max_accel_std`` [m/s^2] the check runs only when the accelerometers show it still over
    the whole window (:func:`still_duration` without a rate limit: the gyros are the suspects).
    ``model`` is the filter's IMU error model (its bias bound and white noise are compared).
    """
    t, w, _ = _rates(imu)
    if t.size < 2:
        return
    if max_accel_std is not None and \
            still_duration(imu, max_accel_std, np.inf) < t[-1] - t[0] - STILL_BLOCK:
        return
    mean = float(np.linalg.norm(w.mean(axis=0)))
    bound = 0.0 if model is None else float(np.hypot(model.gyro_bias, model.gyro_bias_instability))
    limit = max(GYRO_REST_MAX, 5.0 * bound)
    if mean <= limit:
        return
    dt = float(np.median(np.diff(t)))
    noise = float(np.sqrt(np.mean(np.var(w, axis=0))))
    text = (f"the gyros read {mean:.4g} rad/s ({np.degrees(mean):.3g} deg/s) at rest over "
            f"{t[-1] - t[0]:.1f} s from t = {t[0]:.3f} s, {mean / OMEGA_E:.0f} times the Earth "
            f"rate ({OMEGA_E:.3g} rad/s)")
    if model is not None and model.gyro_arw > 0:
        expected_noise = model.gyro_arw / np.sqrt(dt)
        text += (f"; their white noise is {noise:.3g} rad/s per sample, "
                 f"{noise / expected_noise:.0f} times the {model.name} grade's")
    text += (". The gyro data is probably in deg/s declared as rad/s (declare "
             "inputs.imu.gyro_unit = \"deg/s\"); if the gyros really have this offset, declare "
             "it: filter.imu_model.gyro_bias_deg_h")
    raise UnitError(text, file=file, column=column,
                    expected=f"a mean rate at rest below {limit:.3g} rad/s",
                    found=f"{mean:.4g} rad/s")


def check_latitude_radians(table: pd.DataFrame | None, *, file=None, what: str = "table") -> None:
    """Raise :class:`~insgnss.errors.InvalidValueError` when a ``lat`` column (radians inside
    insgnss) holds values beyond +-pi/2: degrees written into a radians column (name it
    ``lat_deg`` in a native CSV)."""
    if table is None or "lat" not in table.columns or not len(table):
        return
    lat = table["lat"].to_numpy(float)
    bad = np.flatnonzero(np.abs(lat) > np.pi / 2)
    if not bad.size:
        return
    lines = table.attrs.get("source_rows")
    row = int(lines[bad[0]]) if lines is not None and len(lines) == len(table) else None
    raise InvalidValueError(
        f"latitude {lat[bad[0]]:.6g} in the {what} cannot be radians (|lat| <= pi/2): the "
        "values look like degrees. A native CSV holds degrees in a column named 'lat_deg' "
        "('lat' is radians)", file=file or table.attrs.get("source"), row=row, column="lat",
        expected="|lat| <= 1.5708 rad", found=f"{lat[bad[0]]:.6g}")


def still_duration(imu: pd.DataFrame, max_accel_std: float, max_rate_std: float,
                   block: float = STILL_BLOCK) -> float:
    """How long [s] the IMU is still from its first sample: the start of the first block of
    ``block`` seconds whose specific force or angular rate varies by more than the limits
    [m/s^2, rad/s] (1-sigma over all axes) or whose mean departs from the mean of the first
    block by more than them (a smooth acceleration varies little within a block)."""
    t, w, f = _rates(imu)
    if t.size < 4:
        return 0.0
    n = max(2, int(round(block / float(np.median(np.diff(t))))))
    nb = t.size // n
    if nb == 0:
        return 0.0
    fb, wb = f[:nb * n].reshape(nb, n, 3), w[:nb * n].reshape(nb, n, 3)
    fs = np.sqrt(np.var(fb, axis=1).sum(axis=1))
    ws = np.sqrt(np.var(wb, axis=1).sum(axis=1))
    fm, wm = fb.mean(axis=1), wb.mean(axis=1)
    fd = np.linalg.norm(fm - fm[0], axis=1)
    wd = np.linalg.norm(wm - wm[0], axis=1)
    moving = np.flatnonzero((fs > max_accel_std) | (ws > max_rate_std) | (fd > max_accel_std)
                            | (wd > max_rate_std))
    if not moving.size:
        return float(t[-1] - t[0])
    return float(t[moving[0] * n] - t[0])


def static_window_error(exc: AlignmentError, window: pd.DataFrame, duration: float,
                        max_accel_std: float, max_rate_std: float, *, file=None
                        ) -> AlignmentError:
    """The error of a static alignment whose window is not still: when the IMU is still
    for only part of the window, say for how long and name ``initialization.static_duration``;
    else ``exc`` unchanged."""
    still = still_duration(window, max_accel_std, max_rate_std)
    t0 = float(window.index[0])
    if still >= min(duration, float(window.index[-1]) - t0) - STILL_BLOCK:
        return exc
    hint = (f"the IMU is still only for the first {still:.1f} s from t = {t0:.3f} s, and the "
            f"static window is {duration:g} s long: set initialization.static_duration to at "
            f"most {max(np.floor(still) - 1.0, 1.0):g} s (or use initialization.method = "
            "\"gnss_velocity\" or \"given\")" if still >= 2.0 else
            f"the IMU is not still at the start (t = {t0:.3f} s): a static alignment needs the "
            "vehicle at rest; use initialization.method = \"gnss_velocity\" or \"given\", or "
            "initialization.start_time at a still period")
    return AlignmentError(f"{exc.message}: {hint}", file=file,
                          column="initialization.static_duration", expected=exc.expected,
                          found=exc.found)


__all__ = ["GYRO_REST_MAX", "MAX_UPRIGHT_PITCH", "MAX_UPRIGHT_ROLL", "check_gyro_at_rest",
           "check_latitude_radians", "check_upright", "static_window_error", "still_duration"]
