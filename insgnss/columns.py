"""Column names of the trajectory tables, the output column groups and the output rate.

A trajectory table (forward or smoothed solution, mechanization output, simulated truth) is
indexed by time [s] and holds

- navigation (:data:`NAV_COLS`): ``lat lon height`` [rad, rad, m] (geodetic, WGS84),
  ``vel_e vel_n vel_u`` [m/s] (ENU), ``roll pitch heading`` [rad] (``R_b^l = Rz(-A) Rx(p) Ry(r)``,
  heading clockwise from north);
- their standard deviations (:data:`STD_COLS`): ``east_std north_std up_std`` [m] (position
  error in the local level frame, not of lat/lon), ``vel_*_std`` [m/s], ``roll_std pitch_std
  heading_std`` [rad];
- estimated parameters with their standard deviations: gyro and accelerometer biases
  ``gyro_bias_x ..`` [rad/s, m/s^2], scale factors ``gyro_scale_x ..`` [-], extra states (lever
  arm, odometer scale, ...), each with a ``*_std`` column.

and row labels (:data:`ROW_LABEL_COLS`: ``segment``, the part of a split run a row belongs
to), which every output keeps.

The output groups of ``[outputs] columns`` (docs/jobs.md) select among these:
``"nav"``, ``"std"``, ``"params"`` (every column that is neither navigation nor one of its
standard deviations: biases, scale factors, extra states and their stds) and ``"all"``.
The default, :data:`DEFAULT_OUTPUT_GROUPS`, is navigation with its standard deviations: what
a user plots and compares; the parameters are for filter analysis and are written on request.

``[outputs] rate_hz`` (:func:`output_rate`) is the rate of the written trajectories: a number
[Hz], ``"imu"`` (every sample) or ``"auto"`` (the default): :data:`DEFAULT_OUTPUT_RATE` = 10 Hz
for vehicles (the ``standard`` process preset), every sample for the foot-mounted INS
(``foot`` preset: steps reach ~30 m/s^2 within 0.1 s, and foot-INS scorers compare sample by
sample). 10 Hz keeps the linear-interpolation error between written samples, ``a dt^2 / 8``,
at 4 mm for 3 m/s^2 (a car turning or braking; 1 cm at 8 m/s^2), below the accuracy of an RTK
reference, while writing 10 to 40 times fewer rows than a 100-400 Hz IMU. The forward solution
jumps at each GNSS or control-point update, so the writers also keep the samples on either side
of those epochs (:func:`insgnss.io.native.decimation_rows`): a scorer interpolating the files
at the GNSS epochs (an RTK reference from the same receiver, as for drive_0708) sees the values
of the IMU-rate solution, and the drive_0708 scorer's numbers are identical. (A reference denser
than the output rate, such as a simulated truth at the IMU rate, is interpolated between
written samples, within ``a dt^2 / 8``.)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

#: navigation solution: position (geodetic), ENU velocity, attitude
NAV_COLS = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]
#: one-sigma of the navigation solution (ENU position metres, not lat/lon)
STD_COLS = ["east_std", "north_std", "up_std", "vel_e_std", "vel_n_std", "vel_u_std",
            "roll_std", "pitch_std", "heading_std"]
#: row labels, written with every column group
ROW_LABEL_COLS = ["segment"]
#: names of ``[outputs] columns``
OUTPUT_GROUPS = ("nav", "std", "params", "all")
#: default ``[outputs] columns``
DEFAULT_OUTPUT_GROUPS = ("nav", "std")
#: default ``[outputs] rate_hz`` [Hz] (module docstring)
DEFAULT_OUTPUT_RATE = 10.0


def output_rate(value, preset: str = "standard") -> float | None:
    """``[outputs] rate_hz`` as a rate [Hz], or None for every IMU sample.

    ``"imu"`` and None mean every sample; ``"auto"`` the default of the process ``preset``
    (module docstring).

    Raises
    ------
    ValueError
        Unless ``value`` is a positive finite number, ``"imu"`` or ``"auto"``.
    """
    if isinstance(value, str) and value.strip().lower() == "auto":
        return None if preset == "foot" else DEFAULT_OUTPUT_RATE
    if value is None or (isinstance(value, str) and value.strip().lower() == "imu"):
        return None
    ok = isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < math.inf
    if not ok:
        raise ValueError('output rate must be a positive number [Hz], "imu" or "auto", '
                         f"got {value!r}")
    return float(value)


def output_columns(columns: Iterable[str], groups: Sequence[str]) -> list[str]:
    """The columns of a table (in its order) that belong to the output ``groups``.

    Parameters
    ----------
    columns : iterable of str
        Columns of the trajectory table.
    groups : sequence of str
        Any of :data:`OUTPUT_GROUPS`.

    Raises
    ------
    ValueError
        For a group name not in :data:`OUTPUT_GROUPS`.
    """
    bad = [g for g in groups if g not in OUTPUT_GROUPS]
    if bad:
        raise ValueError(f"unknown output column group {bad[0]!r}: expected one of "
                         f"{', '.join(OUTPUT_GROUPS)}")
    columns = list(columns)
    if "all" in groups:
        return columns
    nav_std = set(NAV_COLS) | set(STD_COLS) | set(ROW_LABEL_COLS)
    keep = set(ROW_LABEL_COLS)
    if "nav" in groups:
        keep |= set(NAV_COLS)
    if "std" in groups:
        keep |= set(STD_COLS)
    return [c for c in columns if c in keep or ("params" in groups and c not in nav_std)]
