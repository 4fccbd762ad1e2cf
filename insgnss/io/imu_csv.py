"""Generic IMU CSV reader: declared columns, units, time scale and sensor-to-body mounting.

Model
-----
A row holds a time stamp and three gyro and three accelerometer readings in the **sensor**
axes, in the declared units:

- gyro: ``rad/s`` or ``deg/s`` (rates), ``rad`` or ``deg`` (angle increments);
- accelerometer: ``m/s^2`` or ``g`` (rates, 1 g = 9.80665 m/s^2 unless declared otherwise),
  ``m/s`` (velocity increments);
- time: ``s``, ``ms``, ``us`` or ``ns``; ``t = time_value * unit + time_offset`` [s]; or
  ``sample``: the time column is a sample index ``k`` (integers, e.g. gaitmap's or an index
  column written by pandas) and ``t = k / rate_hz + time_offset`` with the declared rate.

Header: ``header_rows`` lines (after comment lines) name the columns. With more than one
(pandas ``MultiIndex`` columns, spreadsheet exports with merged group cells) the name of a
column is its non-empty level cells joined with ``"_"`` (``left_sensor`` over ``acc_x`` gives
``left_sensor_acc_x``); an empty cell of an upper level continues the group to its left (a
merged cell), the last level is never filled. A column may also be declared by its levels
(a list ``["left_sensor", "acc_x"]``) or by its 0-based index.

Rates and increments cannot be mixed; the output is an insgnss IMU table
(:mod:`insgnss.imu`): ``gyro_* accel_*`` (rad/s, m/s^2) or ``dtheta_* dv_*`` (rad, m/s), in the
**body frame right-forward-up**, indexed by time [s].

Mounting (sensor -> body RFU), ``v_b = M v_s`` applied to both triads, with
``M = R_euler @ P_axes @ A``:

1. ``A`` = axis map, e.g. ``"y,x,-z"``: body-like axis i is the signed sensor axis named in
   position i (``"y,x,-z"`` turns FRD into RFU). It must be a proper rotation (det +1).
2. ``P_axes`` = ``P_SWAP`` (:mod:`insgnss.attitude`) if ``sensor_axes="frd"`` (the mapped
   triad is forward-right-down-like), identity for ``"rfu"``.
3. ``R_euler`` from mounting Euler angles (roll, pitch, yaw) [deg], the sensor's attitude
   relative to the body in the insgnss convention ``R = euler_to_dcm(roll, pitch, yaw)``
   (``euler_convention="active"``; for FRD triads these are the usual yaw-pitch-roll ZYX angles
   of KF-GINS/pyins, since the angles coincide), or its transpose for Groves' passive
   ``Euler_to_CTM`` convention (``"passive"``), in which ``v_body_frd = C(rpy) v_sensor_frd``.

Validation (:mod:`insgnss.validate`): missing columns, non-numeric cells, NaN/inf, time order,
duplicated stamps (dropped with a warning by default), declared rate, gaps (policy), and
magnitude plausibility of the declared units. Every error names file, line, column.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from ..attitude import P_SWAP, euler_to_dcm
from ..earth import PRESSURE_RANGE
from ..errors import ConfigError, InputFormatError, InvalidValueError
from ..imu import ACCEL_COLS, DEG, DTHETA_COLS, DV_COLS, G0, GYRO_COLS
from ..validate import (
    GapPolicy,
    TextRows,
    apply_gap_policy,
    check_finite,
    check_imu_units,
    check_rate,
    check_time_order,
    find_gaps,
    finish_attrs,
    parse_numeric,
    read_rows,
    require_rows,
)

#: gyro units: name -> (scale to rad or rad/s, is_increment)
GYRO_UNITS = {"rad/s": (1.0, False), "deg/s": (DEG, False), "rad": (1.0, True), "deg": (DEG, True)}
#: accelerometer units: name -> (scale to m/s^2 or m/s in units of g if None, is_increment)
ACCEL_UNITS = {"m/s^2": (1.0, False), "m/s2": (1.0, False), "g": (None, False), "m/s": (1.0, True)}
#: time units -> seconds (``"sample"``: a sample index, divided by the declared rate)
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "sample": None}
#: separator of the level names of a multi-row header
HEADER_JOIN = "_"

#: sensor slots of the column mapping
SLOTS = ("time", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
#: optional barometer slots, copied into the IMU table: static pressure [Pa] or barometric
#: height [m] (for :mod:`insgnss.filter.height_aiding`)
BARO_SLOTS = ("pressure", "baro_height")

_ALIASES = {"dtheta_x": "gyro_x", "dtheta_y": "gyro_y", "dtheta_z": "gyro_z",
            "dv_x": "accel_x", "dv_y": "accel_y", "dv_z": "accel_z"}


def _choice(value, table: Mapping, key: str):
    if not isinstance(value, str) or value not in table:
        raise ConfigError("unknown value", column=key, expected="one of " + ", ".join(table),
                          found=repr(value))
    return table[value]


def axis_map_matrix(spec: str) -> np.ndarray:
    """Matrix ``A`` of an axis map such as ``"y,x,-z"`` (``v_mapped = A v_sensor``).

    Entry i names the signed sensor axis that becomes mapped axis i. Raises ConfigError unless
    the map is a signed permutation with determinant +1.
    """
    if not isinstance(spec, str):
        raise ConfigError("axis map must be a string like 'y,x,-z'", column="axis_map",
                          found=repr(spec))
    parts = [p.strip().lower() for p in spec.replace(" ", "").split(",")]
    A = np.zeros((3, 3))
    seen = set()
    for i, p in enumerate(parts):
        sign = -1.0 if p.startswith("-") else 1.0
        name = p.lstrip("+-")
        if len(parts) != 3 or name not in ("x", "y", "z") or name in seen or len(p) > 2:
            raise ConfigError("invalid axis map", column="axis_map",
                              expected="three signed, distinct axes like 'y,x,-z'", found=repr(spec))
        seen.add(name)
        A[i, "xyz".index(name)] = sign
    if np.linalg.det(A) < 0:
        raise ConfigError("axis map is a reflection (left-handed)", column="axis_map",
                          expected="a proper rotation (determinant +1), e.g. flip one more sign",
                          found=repr(spec))
    return A


def mounting_matrix(axis_map: str | None = None, euler_deg: Sequence[float] | None = None, *,
                    sensor_axes: str = "rfu", euler_convention: str = "active") -> np.ndarray:
    """Sensor-to-body(RFU) matrix ``M`` (see the module docstring): ``v_b = M v_s``."""
    M = np.eye(3) if axis_map is None else axis_map_matrix(axis_map)
    if sensor_axes not in ("rfu", "frd"):
        raise ConfigError("unknown sensor axes", column="sensor_axes", expected="'rfu' or 'frd'",
                          found=repr(sensor_axes))
    if sensor_axes == "frd":
        M = P_SWAP @ M
    if euler_deg is not None:
        try:
            e = np.asarray(euler_deg, dtype=float)
        except (TypeError, ValueError):
            e = np.array([np.nan])
        if e.shape != (3,) or not np.all(np.isfinite(e)):
            raise ConfigError("mounting angles must be three finite numbers (roll, pitch, yaw "
                              "in degrees)", column="mounting_euler_deg", found=repr(euler_deg))
        if euler_convention not in ("active", "passive"):
            raise ConfigError("unknown Euler convention", column="euler_convention",
                              expected="'active' or 'passive'", found=repr(euler_convention))
        R = euler_to_dcm(*np.radians(e))
        M = (R if euler_convention == "active" else R.T) @ M
    return M


def imu_table_from_arrays(
    t: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    *,
    gyro_unit: str,
    accel_unit: str,
    mounting: np.ndarray | None = None,
    file: str | os.PathLike | None = None,
    line_no: np.ndarray | None = None,
    names: Sequence[str] = SLOTS,
    rate_hz: float | None = None,
    gap_policy: GapPolicy | None = None,
    duplicates: str = "drop",
    check_units: bool = True,
    g: float = G0,
    time_base: str = "unspecified",
    fmt: str = "imu-csv",
    rate_tolerance: float = 0.05,
) -> pd.DataFrame:
    """Validate sensor-axis IMU arrays in declared units and build a body-RFU IMU table.

    Parameters
    ----------
    t : (N,) array
        Time [s] (already scaled and offset).
    gyro, accel : (N, 3) arrays
        Sensor-axis readings in ``gyro_unit`` / ``accel_unit`` (see module docstring).
    mounting : (3, 3) array, optional
        Sensor-to-body(RFU) matrix (:func:`mounting_matrix`); identity if None.
    file, line_no, names
        Where the data came from, for messages: line numbers of the rows and the 7 column
        names (time, 3 gyro, 3 accel) as the file calls them.
    rate_hz : float, optional
        Declared sample rate; checked against the median interval (``rate_tolerance``).
    gap_policy : GapPolicy, optional
        Gap handling (default ``GapPolicy()``: bridge <= 1 s with a warning, error beyond).
    duplicates : {"drop", "error"}
        Repeated time stamps: drop (warning, ``attrs["dropped_duplicates"]``) or error.
    check_units : bool
        Run the magnitude plausibility checks of the declared units.
    g : float
        Value of 1 g for ``accel_unit="g"`` [m/s^2].
    time_base : str
        Declared time base, stored in ``attrs["time_base"]``.

    Returns
    -------
    DataFrame indexed by ``time`` with rate or increment columns; ``attrs``: ``source``,
    ``format``, ``time_base``, ``source_rows``, ``dropped_duplicates``, ``gaps``, ``segments``,
    ``nominal_dt``, ``mounting``, ``units``.
    """
    gscale, g_inc = _choice(gyro_unit, GYRO_UNITS, "gyro_unit")
    ascale, a_inc = _choice(accel_unit, ACCEL_UNITS, "accel_unit")
    if g_inc != a_inc:
        raise ConfigError("gyro and accelerometer must both be rates or both increments",
                          column="gyro_unit/accel_unit", found=f"{gyro_unit!r} and {accel_unit!r}")
    if ascale is None:
        if not isinstance(g, (int, float)) or not 5.0 < float(g) < 15.0:
            raise ConfigError("invalid value of g", column="g", expected="about 9.8 m/s^2",
                              found=repr(g))
        ascale = float(g)
    gap_policy = GapPolicy() if gap_policy is None else gap_policy
    if not isinstance(gap_policy, GapPolicy):
        raise ConfigError("gap_policy must be a GapPolicy", column="gap_policy",
                          found=repr(gap_policy))
    t = np.asarray(t, float)
    gyro = np.asarray(gyro, float).reshape(-1, 3)
    accel = np.asarray(accel, float).reshape(-1, 3)
    n = t.size
    if line_no is None:
        line_no = np.arange(n, dtype=np.int64) + 1
    line_no = np.asarray(line_no, np.int64)
    names = list(names)
    check_finite(np.column_stack([t, gyro, accel]), names, line_no, file)
    require_rows(n, 2, file, row=int(line_no[0]) if n else None, what="IMU samples")

    keep, dropped = check_time_order(t, line_no, file, column=names[0], duplicates=duplicates)
    if dropped:
        t, gyro, accel, line_no = t[keep], gyro[keep], accel[keep], line_no[keep]
        require_rows(t.size, 2, file, row=int(line_no[0]), what="IMU samples")
    gyro = gyro * gscale
    accel = accel * ascale

    nominal = check_rate(t, line_no, file, rate_hz, column=names[0], tolerance=rate_tolerance)
    if check_units:
        if g_inc:
            dt = np.diff(t)
            dt = np.concatenate([[dt[0]], dt])[:, None]
            check_imu_units(gyro / dt, accel / dt, line_no, file, gyro_names=names[1:4],
                            accel_names=names[4:7], gyro_unit=gyro_unit, accel_unit=accel_unit)
        else:
            check_imu_units(gyro, accel, line_no, file, gyro_names=names[1:4],
                            accel_names=names[4:7], gyro_unit=gyro_unit, accel_unit=accel_unit)
    gaps = find_gaps(t, line_no, nominal, gap_policy.factor)
    gaps, segments = apply_gap_policy(gaps, gap_policy, file, float(t[0]), float(t[-1]),
                                      column=names[0])

    M = np.eye(3) if mounting is None else np.asarray(mounting, float)
    if M.shape != (3, 3) or not np.allclose(M @ M.T, np.eye(3), atol=1e-9) \
            or np.linalg.det(M) < 0:
        raise ConfigError("mounting matrix must be a 3x3 rotation", column="mounting",
                          found=repr(mounting))
    data = np.column_stack([gyro @ M.T, accel @ M.T])
    cols = (DTHETA_COLS + DV_COLS) if g_inc else (GYRO_COLS + ACCEL_COLS)
    df = pd.DataFrame(data, index=pd.Index(t, name="time"), columns=cols)
    return finish_attrs(df, file=file, fmt=fmt, time_base=time_base, line_no=line_no,
                        time_column=names[0], dropped_duplicates=dropped, gaps=gaps,
                        segments=segments, nominal_dt=float(nominal),
                        mounting=M.tolist(), units={"gyro": gyro_unit, "accel": accel_unit})


def _header_cells(line: str, delimiter: str | None) -> list[str]:
    return [h.strip().strip('"').strip("'").strip() for h in line.split(delimiter)]


def header_names(lines: Sequence[str], delimiter: str | None = ","
                 ) -> tuple[list[str], list[tuple[str, ...]]]:
    """Column names and level tuples of a header of one or more rows.

    The name of a column is its non-empty cells, top level first, joined with
    :data:`HEADER_JOIN`; an empty cell of an upper level continues the group to its left
    (a merged spreadsheet cell). With one row the names are the cells.
    """
    rows = [_header_cells(line, delimiter) for line in lines]
    width = max(len(r) for r in rows)
    rows = [r + [""] * (width - len(r)) for r in rows]
    for r in rows[:-1]:  # merged group cells: continue the group to the left
        for j in range(1, width):
            if not r[j] and rows[-1][j]:
                r[j] = r[j - 1]
    levels = [tuple(r[j] for r in rows) for j in range(width)]
    names = [HEADER_JOIN.join(c for c in lv if c) for lv in levels]
    return names, levels


def _resolve_columns(columns: Mapping | None, header: list[str] | None, file, header_line,
                     increments: bool, levels: list[tuple[str, ...]] | None = None
                     ) -> tuple[list[int], list[str]]:
    """Field indices and display names of the 7 slots and an optional barometer slot (a slot
    names a column, its header levels as a list, or a 0-based field index)."""
    if columns is None:
        if header is None:
            return list(range(7)), list(SLOTS)
        default = ["time"] + (DTHETA_COLS + DV_COLS if increments else GYRO_COLS + ACCEL_COLS)
        columns = dict(zip(SLOTS, default, strict=True))
    if not isinstance(columns, Mapping):
        raise ConfigError("columns must be a mapping of slot -> column name or index",
                          column="columns", found=repr(columns))
    mapping = {}
    for k, v in columns.items():
        slot = _ALIASES.get(k, k)
        if slot not in SLOTS + BARO_SLOTS:
            raise ConfigError("unknown column slot", column=f"columns.{k}",
                              expected="one of " + ", ".join(SLOTS + BARO_SLOTS),
                              found=repr(k))
        mapping[slot] = v
    if all(b in mapping for b in BARO_SLOTS):
        raise ConfigError("give one barometer column", column="columns",
                          expected="pressure or baro_height", found="both")
    missing = [s for s in SLOTS if s not in mapping]
    if missing:
        raise ConfigError("column mapping incomplete", column="columns",
                          expected="all of " + ", ".join(SLOTS), found="missing " + ", ".join(missing))
    idx, names = [], []
    for s in SLOTS + tuple(b for b in BARO_SLOTS if b in mapping):
        v = mapping[s]
        if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
            if v < 0:
                raise ConfigError("column index must be >= 0", column=f"columns.{s}", found=repr(v))
            idx.append(int(v))
            names.append(header[v] if header is not None and v < len(header) else f"{s} (field {v + 1})")
            continue
        if isinstance(v, (list, tuple)) and v and all(isinstance(c, str) for c in v):
            if levels is None or len(v) != len(levels[0]):
                raise ConfigError("a column given by its header levels needs a header of as "
                                  "many rows", column=f"columns.{s}",
                                  expected=f"{0 if levels is None else len(levels[0])} level "
                                  "names", found=repr(v))
            hits = [j for j, lv in enumerate(levels) if lv == tuple(v)]
            label = HEADER_JOIN.join(c for c in v if c)
        elif isinstance(v, str):
            if header is None:
                raise ConfigError("column names need a header line; give 0-based indices",
                                  column=f"columns.{s}", found=repr(v))
            hits = [j for j, h in enumerate(header) if h == v]
            label = v
        else:
            raise ConfigError("column must be a name, a list of header levels or a 0-based "
                              "index", column=f"columns.{s}", found=repr(v))
        if not hits:
            raise InputFormatError("missing column", file=file, row=header_line, column=label,
                                   expected=f"a column named {v!r}", found=", ".join(header))
        if len(hits) > 1:
            raise InputFormatError("column name is not unique", file=file, row=header_line,
                                   column=label, expected="one column of that name",
                                   found=f"fields {', '.join(str(j + 1) for j in hits)}")
        idx.append(hits[0])
        names.append(label)
    return idx, names


def sample_index_time(k: np.ndarray, rate_hz, line_no: np.ndarray, file, column: str
                      ) -> np.ndarray:
    """Time [s] ``k / rate_hz`` of a sample-index column (``time_unit = "sample"``); the
    index must be integral and the rate declared."""
    try:
        rate = float(rate_hz)
    except (TypeError, ValueError):
        rate = np.nan
    if not (np.isfinite(rate) and rate > 0):
        raise ConfigError('time_unit = "sample" needs the declared sample rate',
                          column="rate_hz", expected="a positive number of Hz",
                          found=repr(rate_hz))
    bad = np.flatnonzero(np.abs(k - np.round(k)) > 1e-9 * np.maximum(1.0, np.abs(k)))
    if bad.size:
        i = bad[0]
        raise InputFormatError("sample index is not an integer", file=file,
                               row=int(line_no[i]), column=column,
                               expected='an integer sample index (time_unit = "sample")',
                               found=repr(float(k[i])))
    return np.round(k) / rate


def read_imu_csv(
    path: str | os.PathLike,
    *,
    columns: Mapping[str, str | int] | None = None,
    gyro_unit: str = "rad/s",
    accel_unit: str = "m/s^2",
    time_unit: str = "s",
    time_offset: float = 0.0,
    axis_map: str | None = None,
    mounting_euler_deg: Sequence[float] | None = None,
    sensor_axes: str = "rfu",
    euler_convention: str = "active",
    delimiter: str | None = ",",
    header: bool = True,
    header_rows: int = 1,
    comment: str | tuple[str, ...] = "#",
    rate_hz: float | None = None,
    gap_policy: GapPolicy | None = None,
    duplicates: str = "drop",
    check_units: bool = True,
    g: float = G0,
    time_base: str = "unspecified",
) -> pd.DataFrame:
    """Read a generic IMU CSV into a body-RFU IMU table (see the module docstring).

    Parameters
    ----------
    path : path
    columns : mapping, optional
        Slot -> column: slots ``time gyro_x gyro_y gyro_z accel_x accel_y accel_z`` (aliases
        ``dtheta_* dv_*``) map to header names (levels joined with ``"_"`` for a multi-row
        header), to lists of header levels, or to 0-based field indices. Default: the
        header names equal the slots (``time gyro_x ...`` or ``time dtheta_x ... dv_z``), or,
        without a header, fields 0-6 in slot order. Other columns are ignored. An optional
        slot ``pressure`` [Pa] or ``baro_height`` [m] copies a barometer column into the
        table under that name (checked: finite, pressure 20-110 kPa).
    gyro_unit, accel_unit, time_unit : str
        Declared units (``GYRO_UNITS``, ``ACCEL_UNITS``, ``TIME_UNITS``); ``time_unit =
        "sample"`` reads the time column as a sample index at ``rate_hz``.
    time_offset : float
        Added to the scaled time [s] (e.g. a logging delay).
    axis_map, mounting_euler_deg, sensor_axes, euler_convention
        Sensor-to-body mounting (:func:`mounting_matrix`).
    delimiter : str or None
        Field separator (None: whitespace).
    header : bool
        The first non-comment lines are a header.
    header_rows : int
        Number of header lines (> 1: multi-level names, see the module docstring).
    comment : str or tuple of str
        Prefixes of comment lines (skipped; they still count for line numbers).
    rate_hz, gap_policy, duplicates, check_units, g, time_base
        See :func:`imu_table_from_arrays`.
    """
    tscale = _choice(time_unit, TIME_UNITS, "time_unit")
    try:
        offset = float(time_offset)
    except (TypeError, ValueError):
        offset = np.nan
    if not np.isfinite(offset):
        raise ConfigError("time offset must be a finite number of seconds", column="time_offset",
                          found=repr(time_offset))
    if isinstance(header_rows, bool) or not isinstance(header_rows, (int, np.integer)) \
            or header_rows < 1:
        raise ConfigError("header_rows must be a positive integer", column="header_rows",
                          found=repr(header_rows))
    _, g_inc = _choice(gyro_unit, GYRO_UNITS, "gyro_unit")
    _choice(accel_unit, ACCEL_UNITS, "accel_unit")
    M = mounting_matrix(axis_map, mounting_euler_deg, sensor_axes=sensor_axes,
                        euler_convention=euler_convention)
    comment = (comment,) if isinstance(comment, str) else tuple(comment)
    rows = read_rows(path, comment=comment, header=header, delimiter=delimiter)
    head = levels = None
    if header:
        extra = int(header_rows) - 1
        if extra >= len(rows.lines):
            raise InputFormatError("no data rows after the header", file=path,
                                   row=rows.header_line, expected=f"{header_rows} header "
                                   "lines and data rows", found=f"{len(rows.lines) + 1} lines")
        head, levels = header_names([rows.header, *(rows.lines[:extra] if extra else ())],
                                    delimiter)
        if extra:
            rows = TextRows(rows.file, rows.lines[extra:], rows.line_no[extra:], rows.header,
                            rows.header_line, rows.comments)
    idx, names = _resolve_columns(columns, head, path, rows.header_line, g_inc, levels)
    values = parse_numeric(rows, names, delimiter=delimiter, usecols=idx,
                           ncols=len(head) if head is not None else None)
    if tscale is None:
        t = sample_index_time(values[:, 0], rate_hz, rows.line_no, path, names[0]) + offset
    else:
        t = values[:, 0] * tscale + offset
    df = imu_table_from_arrays(
        t, values[:, 1:4], values[:, 4:7], gyro_unit=gyro_unit, accel_unit=accel_unit,
        mounting=M, file=path, line_no=rows.line_no, names=names[:7], rate_hz=rate_hz,
        gap_policy=gap_policy, duplicates=duplicates, check_units=check_units, g=g,
        time_base=time_base, fmt="imu-csv")
    if len(names) > 7:
        _attach_baro(df, values[:, 7], rows.line_no, path, names[7],
                     next(b for b in BARO_SLOTS if b in (columns or {})))
    return df


def _attach_baro(df: pd.DataFrame, x: np.ndarray, line_no: np.ndarray, file, name: str,
                 slot: str) -> None:
    """Copy the barometer column into ``df`` (rows the reader kept), checking it."""
    kept = np.searchsorted(line_no, df.attrs["source_rows"])
    x = x[kept]
    bad = ~np.isfinite(x)
    if slot == "pressure":
        bad |= (x < PRESSURE_RANGE[0]) | (x > PRESSURE_RANGE[1])
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InvalidValueError("implausible barometer value", file=file,
                                row=int(df.attrs["source_rows"][i]), column=name,
                                expected="pressure 20-110 kPa in Pa" if slot == "pressure"
                                else "a finite height in m", found=repr(float(x[i])))
    df[slot] = x
