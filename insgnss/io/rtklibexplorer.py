"""Raw IMU logs of the rtklibexplorer GNSS_IMU data (``imu_*.csv`` + RTKLIB ``.tag``).

Format (data README, ``shared/data/gnss-imu-rtklibexplorer``): no header, comma-separated
``ax, ay, az`` [g], ``wx, wy, wz`` [deg/s], ``t`` [ms since IMU power-up]. The time of each
row is obtained exactly as the data author's ``convert_imu_file.py`` does:

1. the first and last line are skipped (they may be partial);
2. the millisecond counter is mapped linearly onto the time-tag span::

       t = start + (ms - ms[0]) * (tick[-1] / 1000) / (ms[-1] - ms[0])

   where ``start`` is the GPST start of the ``.tag`` file and ``tick[-1]`` its last tick
   [ms] (:func:`insgnss.io.rtklib.read_rtklib_tag`);
3. an optional ``time_offset`` is added (the author uses ``imu_t_off = -0.125`` s for the
   drive, a logging delay; the reader's default is 0 so that the raw span matches the README).

Mounting: the author's config gives the sensor-to-vehicle rotation as roll, pitch, yaw in
Groves' passive convention between the raw sensor axes (treated as FRD) and the vehicle FRD
frame: ``f_vehicle_frd = Euler_to_CTM(rpy) f_sensor`` with ``rpy = (180, 0, 180) + (0, -6.79,
5.35)`` deg for the drive (README) and ``(180, 0, -90)`` for the walk. The reader converts this
to insgnss' body RFU with :func:`insgnss.io.imu_csv.mounting_matrix` (``sensor_axes="frd"``,
``euler_convention="passive"``), i.e. ``M = euler_to_dcm(rpy)^T P_SWAP``. At rest the raw
``az`` is about +1 g; the body RFU ``accel_z`` is then about +9.8 m/s^2 (specific force up).

1 g is 9.80665 m/s^2 by default (the author multiplies by the local normal-gravity magnitude;
pass ``g=`` to do the same).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ConfigError, TimeOrderError
from ..imu import G0
from ..validate import (
    GapPolicy,
    check_finite,
    check_time_order,
    parse_numeric,
    read_rows,
    require_rows,
)
from .gpstime import from_gps_seconds
from .imu_csv import imu_table_from_arrays, mounting_matrix
from .rtklib import read_rtklib_tag

#: column names of the raw file (data README)
RAW_COLUMNS = ("ax", "ay", "az", "wx", "wy", "wz", "t_ms")
#: declared settings of the two recordings (data README / the author's configs)
DRIVE_0708 = {"mounting_rpy_deg": (180.0, -6.79, 185.35), "time_offset": -0.125, "rate_hz": 100.0}
WALK_0827 = {"mounting_rpy_deg": (180.0, 0.0, -90.0), "time_offset": 0.0, "rate_hz": 1000.0 / 6.0}
#: largest accepted relative difference between the tag span and the ms-counter span
MAX_CLOCK_RATIO_ERROR = 0.01


def rtklibexplorer_mounting(rpy_deg: Sequence[float]) -> np.ndarray:
    """Raw-sensor-to-body(RFU) matrix for the author's passive FRD ``rpy`` [deg]."""
    return mounting_matrix(None, rpy_deg, sensor_axes="frd", euler_convention="passive")


def read_rtklibexplorer_imu(
    path: str | os.PathLike,
    *,
    mounting_rpy_deg: Sequence[float],
    tag_path: str | os.PathLike | None = None,
    time_offset: float = 0.0,
    rate_hz: float | None = None,
    gap_policy: GapPolicy | None = None,
    duplicates: str = "drop",
    check_units: bool = True,
    g: float = G0,
    skip_first_last: bool = True,
    time_base: str = "gps",
) -> pd.DataFrame:
    """Read a raw rtklibexplorer IMU log into a body-RFU rate IMU table.

    Parameters
    ----------
    path : path
        ``imu_*.csv``.
    mounting_rpy_deg : 3 floats
        Declared mounting (roll, pitch, yaw) [deg], author's convention (module docstring);
        ``DRIVE_0708["mounting_rpy_deg"]`` for the drive.
    tag_path : path, optional
        Time-tag file (default ``path + ".tag"``).
    time_offset : float
        Added to every time stamp [s] (``DRIVE_0708["time_offset"]`` = -0.125).
    rate_hz, gap_policy, duplicates, check_units, g
        As :func:`insgnss.io.imu_csv.imu_table_from_arrays`.
    skip_first_last : bool
        Skip the first and last line as the author's converter does.
    time_base : {"gps", "sow", "unix_gpst"}
        Time base of the index (GPS seconds by default).

    Returns
    -------
    DataFrame ``gyro_* accel_*`` (rad/s, m/s^2, body RFU) indexed by time; attrs as the
    generic reader plus ``tag_start``, ``tag_end`` (GPS s) and ``time_offset``.
    """
    if time_base not in ("gps", "sow", "unix_gpst"):
        raise ConfigError("unknown time base", column="time_base",
                          expected="'gps', 'sow' or 'unix_gpst'", found=repr(time_base))
    try:
        offset = float(time_offset)
    except (TypeError, ValueError):
        offset = np.nan
    if not np.isfinite(offset):
        raise ConfigError("time offset must be a finite number of seconds", column="time_offset",
                          found=repr(time_offset))
    M = rtklibexplorer_mounting(mounting_rpy_deg)
    path = Path(path)
    rows = read_rows(path, comment=(), delimiter=",", trim=skip_first_last)
    values = parse_numeric(rows, RAW_COLUMNS, delimiter=",")
    line_no = rows.line_no
    check_finite(values, RAW_COLUMNS, line_no, path)
    require_rows(len(values), 2, path, row=int(line_no[0]), what="IMU samples")
    ms = values[:, 6]
    if np.any(np.diff(ms) < 0):
        check_time_order(ms, line_no, path, column="t_ms")  # raises at the first backward step
    if ms[-1] <= ms[0]:
        raise TimeOrderError("the millisecond counter does not advance", file=path,
                             row=int(line_no[-1]), column="t_ms",
                             expected=f"a last value > {ms[0]:g}", found=f"{ms[-1]:g}")
    tag = read_rtklib_tag(tag_path if tag_path is not None else Path(str(path) + ".tag"))
    span = float(tag.ticks[-1]) / 1000.0
    ratio = span / ((ms[-1] - ms[0]) / 1000.0)
    if not abs(ratio - 1.0) <= MAX_CLOCK_RATIO_ERROR:
        raise TimeOrderError("the time-tag span does not match the IMU counter span (wrong .tag?)",
                             file=tag.file, column="tick",
                             expected=f"{(ms[-1] - ms[0]) / 1000.0:.3f} s "
                                      f"(+-{MAX_CLOCK_RATIO_ERROR:.0%})",
                             found=f"{span:.3f} s")
    t_gps = tag.start + (ms - ms[0]) * (span / (ms[-1] - ms[0])) + offset
    t = from_gps_seconds(t_gps, time_base)
    df = imu_table_from_arrays(
        t, values[:, 3:6], values[:, 0:3], gyro_unit="deg/s", accel_unit="g", mounting=M,
        file=path, line_no=line_no, names=("t_ms", "wx", "wy", "wz", "ax", "ay", "az"),
        rate_hz=rate_hz, gap_policy=gap_policy, duplicates=duplicates, check_units=check_units,
        g=g, time_base=time_base, fmt="rtklibexplorer-imu")
    df.attrs.update(tag_start=tag.start, tag_end=tag.end, time_offset=offset,
                    mounting_rpy_deg=[float(a) for a in mounting_rpy_deg])
    return df
