"""KF-GINS / awesome-gins-datasets text formats.

Files are whitespace- (or comma-) separated numbers without a header; time is GPS seconds of
week (``sow``) except in ``.nav`` files, which carry the week.

IMU (``*.txt``, 7 columns)
    ``sow  dtheta_x dtheta_y dtheta_z [rad]  dv_x dv_y dv_z [m/s]`` in the IMU's
    forward-right-down axes; row k integrates over ``(t[k-1], t[k]]``. Read into an insgnss
    increment table in body RFU (``frd`` sensor axes, optional extra mounting).
GNSS (``GNSS-RTK.txt``, 7 or 13 columns)
    ``sow  lat lon [deg]  h [m]  std_n std_e std_d [m]`` and optionally
    ``vn ve vd [m/s]  std_vn std_ve std_vd [m/s]``.
Navigation result / reference (``*.nav``, 11 columns)
    ``week  sow  lat lon [deg]  h [m]  vn ve vd [m/s]  roll pitch yaw [deg]`` with the FRD body
    attitude relative to NED (yaw-pitch-roll ZYX). Converted with
    :func:`insgnss.attitude.euler_from_ned` / :func:`insgnss.attitude.euler_to_ned` and
    :func:`insgnss.attitude.ned_to_enu`.

Time: with ``week=`` given (or a non-zero week in a ``.nav`` file) the index is GPS seconds
(``attrs["time_base"] = "gps"``); otherwise it stays seconds of week (``"sow"``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..attitude import euler_from_ned, euler_to_ned, ned_to_enu
from ..errors import ConfigError, InputFormatError
from ..validate import (
    GapPolicy,
    check_finite,
    check_range,
    check_time_order,
    ensure_not_input,
    finish_attrs,
    parse_numeric,
    read_rows,
)
from .gpstime import WEEK_SECONDS, week_sow_from_gps_seconds
from .imu_csv import imu_table_from_arrays, mounting_matrix
from .native import atomic_write, fixed_decimal_text

IMU_COLUMNS = ("sow", "dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")
GNSS_COLUMNS = ("sow", "lat", "lon", "h", "std_n", "std_e", "std_d")
GNSS_VEL_COLUMNS = ("vn", "ve", "vd", "std_vn", "std_ve", "std_vd")
NAV_COLUMNS = ("week", "sow", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")


def _rows(path):
    rows = read_rows(path, comment=("#", "%"), delimiter=",")
    delimiter = "," if "," in rows.lines[0] else None
    return rows, delimiter


def _week(week) -> int | None:
    if week is None:
        return None
    if isinstance(week, bool) or not isinstance(week, (int, np.integer)) or not 0 <= week < 10000:
        raise ConfigError("GPS week must be an integer 0-9999", column="week", found=repr(week))
    return int(week)


def _time(sow: np.ndarray, week: int | None):
    if week is None:
        return sow, "sow", {}
    return sow + week * WEEK_SECONDS, "gps", {"gps_week": week}


def read_kfgins_imu(
    path: str | os.PathLike,
    *,
    week: int | None = None,
    axis_map: str | None = None,
    mounting_euler_deg: Sequence[float] | None = None,
    rate_hz: float | None = None,
    gap_policy: GapPolicy | None = None,
    duplicates: str = "drop",
    check_units: bool = True,
) -> pd.DataFrame:
    """Read a KF-GINS IMU increment file into a body-RFU increment table.

    The file's axes are FRD (``sensor_axes="frd"``); ``axis_map`` / ``mounting_euler_deg``
    (active convention, see :mod:`insgnss.io.imu_csv`) describe any further mounting.
    """
    week = _week(week)
    M = mounting_matrix(axis_map, mounting_euler_deg, sensor_axes="frd")
    rows, delim = _rows(path)
    values = parse_numeric(rows, IMU_COLUMNS, delimiter=delim)
    t, base, extra = _time(values[:, 0], week)
    df = imu_table_from_arrays(
        t, values[:, 1:4], values[:, 4:7], gyro_unit="rad", accel_unit="m/s", mounting=M,
        file=path, line_no=rows.line_no, names=IMU_COLUMNS, rate_hz=rate_hz,
        gap_policy=gap_policy, duplicates=duplicates, check_units=check_units, time_base=base,
        fmt="kfgins-imu")
    df.attrs.update(extra)
    return df


def read_kfgins_gnss(path: str | os.PathLike, *, week: int | None = None,
                     duplicates: str = "drop") -> pd.DataFrame:
    """Read a KF-GINS GNSS file (7 or 13 columns) into a GNSS table (ENU, radians)."""
    week = _week(week)
    rows, delim = _rows(path)
    n = len(rows.lines[0].split(delim))
    names = GNSS_COLUMNS + (GNSS_VEL_COLUMNS if n == 13 else ())
    v = parse_numeric(rows, names, delimiter=delim)
    line_no = rows.line_no
    check_finite(v, names, line_no, path)
    check_range(v[:, 1], -90, 90, "lat", line_no, path, unit="deg")
    check_range(v[:, 2], -180, 360, "lon", line_no, path, unit="deg")
    check_range(v[:, 3], -1e4, 1e6, "h", line_no, path, unit="m")
    for j in range(4, 7):
        check_range(v[:, j], 0, 1e7, names[j], line_no, path, unit="m")
    t, base, extra = _time(v[:, 0], week)
    out = {"lat": np.radians(v[:, 1]), "lon": np.radians(v[:, 2]), "height": v[:, 3],
           "east_std": v[:, 5], "north_std": v[:, 4], "up_std": v[:, 6]}
    if n == 13:
        for j in range(10, 13):
            check_range(v[:, j], 0, 1e4, names[j], line_no, path, unit="m/s")
        venu = ned_to_enu(v[:, 7:10])
        out.update(vel_e=venu[:, 0], vel_n=venu[:, 1], vel_u=venu[:, 2],
                   vel_e_std=v[:, 11], vel_n_std=v[:, 10], vel_u_std=v[:, 12])
    keep, dropped = check_time_order(t, line_no, path, column="sow", duplicates=duplicates)
    df = pd.DataFrame(out, index=pd.Index(t, name="time"))
    if dropped:
        df, line_no = df.loc[keep], line_no[keep]
    return finish_attrs(df, file=path, fmt="kfgins-gnss", time_base=base, line_no=line_no,
                        time_column="sow", dropped_duplicates=dropped, **extra)


def read_kfgins_nav(path: str | os.PathLike, *, week: int | None = None,
                    duplicates: str = "drop") -> pd.DataFrame:
    """Read a KF-GINS ``.nav`` result/reference into a trajectory table.

    Columns ``lat lon height vel_e vel_n vel_u roll pitch heading`` (radians, m, m/s). The index
    is GPS seconds when the file's week (or ``week=``) is non-zero, else seconds of week.
    """
    week = _week(week)
    rows, delim = _rows(path)
    v = parse_numeric(rows, NAV_COLUMNS, delimiter=delim)
    line_no = rows.line_no
    check_finite(v, NAV_COLUMNS, line_no, path)
    check_range(v[:, 0], 0, 9999, "week", line_no, path)
    check_range(v[:, 1], 0, 2 * WEEK_SECONDS, "sow", line_no, path, unit="s")
    check_range(v[:, 2], -90, 90, "lat", line_no, path, unit="deg")
    check_range(v[:, 3], -180, 360, "lon", line_no, path, unit="deg")
    check_range(v[:, 4], -1e4, 1e6, "h", line_no, path, unit="m")
    check_range(v[:, 8], -180, 180, "roll", line_no, path, unit="deg")
    check_range(v[:, 9], -90, 90, "pitch", line_no, path, unit="deg")
    check_range(v[:, 10], -360, 360, "yaw", line_no, path, unit="deg")
    file_week = v[:, 0]
    if week is not None:
        t, base, extra = v[:, 1] + week * WEEK_SECONDS, "gps", {"gps_week": week}
    elif np.all(file_week > 0):
        t = file_week * WEEK_SECONDS + v[:, 1]
        base, extra = "gps", {"gps_week": int(file_week[0])}
    else:
        t, base, extra = v[:, 1], "sow", {}
    venu = ned_to_enu(v[:, 5:8])
    roll, pitch, heading = euler_from_ned(*np.radians(v[:, 8:11]).T)
    out = {"lat": np.radians(v[:, 2]), "lon": np.radians(v[:, 3]), "height": v[:, 4],
           "vel_e": venu[:, 0], "vel_n": venu[:, 1], "vel_u": venu[:, 2],
           "roll": roll, "pitch": pitch, "heading": heading}
    keep, dropped = check_time_order(t, line_no, path, column="sow", duplicates=duplicates)
    df = pd.DataFrame(out, index=pd.Index(t, name="time"))
    if dropped:
        df, line_no = df.loc[keep], line_no[keep]
    return finish_attrs(df, file=path, fmt="kfgins-nav", time_base=base, line_no=line_no,
                        time_column="sow", dropped_duplicates=dropped, **extra)


def write_kfgins_nav(df: pd.DataFrame, path: str | os.PathLike, *, week: int | None = None,
                     protect: Sequence[str | os.PathLike] = ()) -> os.PathLike:
    """Write a trajectory table as a KF-GINS ``.nav`` file (atomically).

    Needs ``lat lon height vel_e vel_n vel_u roll pitch heading``. Week and seconds of week
    come from GPS-second times (``attrs["time_base"] == "gps"``, the default assumption for
    times > 1e7 s); for seconds-of-week tables the week is ``week=`` or ``attrs["gps_week"]``
    (0 if unknown). ``protect`` lists input files that must not be overwritten.
    """
    need = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise InputFormatError("trajectory table lacks columns for a .nav file", column=missing[0],
                               expected=", ".join(need), found=", ".join(map(str, df.columns)))
    ensure_not_input(path, [*protect, df.attrs.get("source")])
    t = np.asarray(df.index, float)
    base = df.attrs.get("time_base")
    if base == "gps" or (base not in ("sow",) and t.size and t[0] > 1e7):
        wk, sow = week_sow_from_gps_seconds(t)
    else:
        w = _week(week) if week is not None else int(df.attrs.get("gps_week", 0) or 0)
        wk, sow = np.full(t.size, w), t
    cols = _nav_columns(df, wk, sow)
    return atomic_write(path, lambda p: _write_nav_text(cols, p))


#: decimals of the .nav columns: week integer, sow 6 [s], lat/lon 10 [deg] (0.01 mm), h and
#: velocities 5 [m, m/s], roll/pitch/yaw 8 [deg]
NAV_DECIMALS = (0, 6, 10, 10, 5, 5, 5, 5, 8, 8, 8)


def _nav_columns(df: pd.DataFrame, wk: np.ndarray, sow: np.ndarray) -> list[np.ndarray]:
    """The 11 .nav columns (week, sow, lat lon [deg], h, v_NED, roll pitch yaw [deg, NED/FRD])."""
    vned = ned_to_enu(df[["vel_e", "vel_n", "vel_u"]].to_numpy(float))
    r, p, y = euler_to_ned(df["roll"].to_numpy(float), df["pitch"].to_numpy(float),
                           df["heading"].to_numpy(float))
    return [np.asarray(wk, float), np.asarray(sow, float), np.degrees(df["lat"].to_numpy(float)),
            np.degrees(df["lon"].to_numpy(float)), df["height"].to_numpy(float),
            vned[:, 0], vned[:, 1], vned[:, 2], np.degrees(r), np.degrees(p), np.degrees(y)]


def _write_nav_text(cols: list[np.ndarray], path, rows: int = 1 << 17) -> None:
    """Space-separated fixed-decimal text, one line per epoch, byte-identical to
    ``np.savetxt(path, np.column_stack(cols), fmt=["%d", "%.6f", ...], delimiter=" ")``,
    formatted and written by pyarrow a batch of rows at a time."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    names = [f"c{j}" for j in range(len(cols))]
    opts = pacsv.WriteOptions(include_header=False, delimiter=" ", quoting_style="none")
    schema = pa.schema([(n, pa.string()) for n in names])
    with pacsv.CSVWriter(str(path), schema, write_options=opts) as w:
        for i in range(0, len(cols[0]), rows):
            w.write_batch(pa.RecordBatch.from_arrays(
                [fixed_decimal_text(c[i:i + rows], d) for c, d in zip(cols, NAV_DECIMALS,
                                                                      strict=True)],
                names=names))
