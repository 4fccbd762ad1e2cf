"""Odometer reader: forward speed or distance increments from a CSV file, with declared units.

Output table (insgnss convention): a DataFrame indexed by time [s] (name ``time``) with either

- ``speed`` [m/s], the forward speed at the time stamp (signed: negative when reversing), or
- ``distance`` [m], the distance travelled over ``(t[k-1], t[k]]`` (row 0: the interval before
  the first stamp, usually 0).

Units are declared, never guessed: speed in ``m/s``, ``km/h``, ``mph`` or ``knots``; distance in
``m``, ``km``, ``ft`` or ``pulses`` (with ``pulses_per_metre``). A *native* insgnss table
(``format="native"``, the default: ``time`` + ``speed`` [m/s] or ``distance`` [m], as written by
:func:`write_odometer` and ``insgnss simulate``) declares SI units by its format; a generic CSV
(``format="csv"``) must declare ``unit``. Distance may also be given as a
cumulative odometer reading (``cumulative=True``); it is then differenced. Every value is checked:
missing columns, non-numeric cells, NaN/inf, non-increasing or duplicated time stamps, gaps longer
than ``max_gap``, and speeds beyond ``max_speed`` (the usual symptom of km/h declared as m/s).
Errors name the file, the 1-based row (header = row 1) and the column.

:func:`validate_odometer` applies the same checks to a DataFrame built elsewhere (simulation).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataGapError, InputFormatError, InvalidValueError, TimeOrderError, UnitError

#: unit -> factor to SI (m/s for speed, m for distance)
SPEED_UNITS = {"m/s": 1.0, "km/h": 1000.0 / 3600.0, "mph": 0.44704, "knots": 1852.0 / 3600.0}
DISTANCE_UNITS = {"m": 1.0, "km": 1000.0, "ft": 0.3048, "pulses": None}

#: default plausibility limit for a land vehicle [m/s] (324 km/h)
MAX_SPEED = 90.0


def _first_bad_row(mask: np.ndarray) -> int:
    """1-based file row (header is row 1) of the first True in ``mask``."""
    return int(np.flatnonzero(mask)[0]) + 2


def read_odometer(
    path: str | os.PathLike,
    *,
    quantity: str | None = None,
    kind: str | None = None,
    format: str = "native",
    unit: str | None = None,
    time_column: str = "time",
    value_column: str | None = None,
    pulses_per_metre: float | None = None,
    cumulative: bool = False,
    max_gap: float | None = None,
    max_speed: float = MAX_SPEED,
    delimiter: str = ",",
) -> pd.DataFrame:
    """Read an odometer CSV file.

    Parameters
    ----------
    path : path
        CSV file with a header row.
    quantity, kind : {"speed", "distance"}
        What the value column holds (``kind`` is the job-file name of the same setting;
        default ``"speed"``).
    format : {"native", "csv"}
        ``native``: SI units by definition (``unit`` may be omitted, must be SI if given);
        ``csv``: any column names and a declared ``unit``.
    unit : str
        Declared unit: speed ``m/s km/h mph knots``; distance ``m km ft pulses``.
    time_column : str
        Name of the time column [s].
    value_column : str, optional
        Name of the value column (default: ``quantity``).
    pulses_per_metre : float, optional
        Wheel-encoder resolution, required with ``unit="pulses"``.
    cumulative : bool
        Distance is a cumulative reading (differenced into increments; row 0 becomes 0).
    max_gap : float, optional
        Largest allowed spacing of time stamps [s]; larger raises :class:`DataGapError`.
    max_speed : float
        Plausibility limit [m/s] for speeds and for distance / interval.
    delimiter : str
        Field separator.

    Returns
    -------
    DataFrame
        Indexed by ``time`` [s], column ``speed`` [m/s] or ``distance`` [m].
    """
    path = Path(path)
    if quantity is not None and kind is not None and quantity != kind:
        raise InputFormatError("quantity and kind disagree", file=path, found=(quantity, kind))
    quantity = quantity or kind or "speed"
    if format not in ("native", "csv"):
        raise InputFormatError("unknown odometer format", file=path, expected="'native' or 'csv'",
                               found=repr(format))
    if format == "native":
        si = "m/s" if quantity == "speed" else "m"
        if unit not in (None, si):
            raise UnitError("a native odometer table is SI", file=path, expected=si, found=unit)
        unit = si
    if quantity not in ("speed", "distance"):
        raise InputFormatError("unknown odometer quantity", file=path, expected="'speed' or "
                               "'distance'", found=repr(quantity))
    units = SPEED_UNITS if quantity == "speed" else DISTANCE_UNITS
    if unit is None or unit not in units:
        raise UnitError(f"odometer {quantity} unit must be declared", file=path,
                        expected=sorted(units), found=repr(unit))
    if unit == "pulses" and not (pulses_per_metre and pulses_per_metre > 0):
        raise UnitError("unit 'pulses' needs a positive pulses_per_metre", file=path,
                        found=pulses_per_metre)
    col = value_column or quantity
    try:
        raw = pd.read_csv(path, sep=delimiter, dtype=str, skipinitialspace=True, na_filter=False)
    except pd.errors.EmptyDataError:
        raise InputFormatError("file is empty", file=path, expected="a CSV with a header") from None
    except FileNotFoundError:
        raise InputFormatError("file not found", file=path) from None
    raw.columns = [c.strip() for c in raw.columns]
    for c in (time_column, col):
        if c not in raw.columns:
            raise InputFormatError("missing column", file=path, row=1, column=c,
                                   expected=[time_column, col], found=list(raw.columns))
    if len(raw) == 0:
        raise InputFormatError("no data rows", file=path, row=2)
    arrays = {}
    for c in (time_column, col):
        vals = pd.to_numeric(raw[c].str.strip(), errors="coerce").to_numpy(float)
        bad = np.isnan(vals) & ~raw[c].str.strip().str.lower().isin(["nan", "inf", "-inf"])
        if np.any(bad):
            r = _first_bad_row(bad)
            raise InputFormatError("non-numeric value", file=path, row=r, column=c,
                                   expected="a number", found=repr(raw[c].iloc[r - 2]))
        arrays[c] = vals
    t = arrays[time_column]
    x = arrays[col]
    if unit == "pulses":
        x = x / float(pulses_per_metre)
    else:
        x = x * units[unit]
    if cumulative:
        if quantity != "speed":
            x = np.concatenate([[0.0], np.diff(x)])
        else:
            raise InputFormatError("cumulative=True applies to distance only", file=path)
    df = pd.DataFrame({quantity: x}, index=pd.Index(t, name="time"))
    return validate_odometer(df, file=path, max_gap=max_gap, max_speed=max_speed,
                             column_names={"time": time_column, quantity: col})


def validate_odometer(
    odometer: pd.DataFrame,
    *,
    file=None,
    max_gap: float | None = None,
    max_speed: float = MAX_SPEED,
    column_names: dict | None = None,
) -> pd.DataFrame:
    """Check an odometer table (see module docstring) and return it (as float, sorted index).

    Raises :class:`InputFormatError`, :class:`InvalidValueError`, :class:`TimeOrderError`,
    :class:`DataGapError` or :class:`UnitError` naming the row and column of the first problem.
    Rows are reported 1-based with the header as row 1 (as in the file).
    """
    names = {"time": "time", "speed": "speed", "distance": "distance"}
    names.update(column_names or {})
    has_speed = "speed" in odometer.columns
    has_dist = "distance" in odometer.columns
    if has_speed == has_dist:
        raise InputFormatError("odometer table needs exactly one of 'speed' or 'distance'",
                               file=file, found=list(odometer.columns))
    q = "speed" if has_speed else "distance"
    t = np.asarray(odometer.index, float)
    x = odometer[q].to_numpy(float)
    if t.size < 2:
        raise InputFormatError("odometer needs at least two rows", file=file, found=t.size)
    for arr, c in ((t, "time"), (x, q)):
        bad = ~np.isfinite(arr)
        if np.any(bad):
            r = _first_bad_row(bad)
            raise InvalidValueError("NaN or infinite value", file=file, row=r, column=names[c],
                                    expected="a finite number", found=arr[r - 2])
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0]) + 1
        kind = "duplicated" if dt[i - 1] == 0 else "decreasing"
        raise TimeOrderError(f"{kind} time stamp", file=file, row=i + 2, column=names["time"],
                             expected=f"> {t[i - 1]!r}", found=t[i])
    if max_gap is not None and np.any(dt > max_gap):
        i = int(np.flatnonzero(dt > max_gap)[0]) + 1
        raise DataGapError(f"gap of {dt[i - 1]:.3f} s in the odometer", file=file, row=i + 2,
                           column=names["time"], expected=f"<= {max_gap} s", found=dt[i - 1])
    speed = np.abs(x) if q == "speed" else np.abs(x[1:]) / dt
    bad = speed > max_speed
    if np.any(bad):
        j = int(np.flatnonzero(bad)[0])
        row = j + 2 + (0 if q == "speed" else 1)
        raise UnitError(f"implausible odometer {q} for a land vehicle (wrong unit declared?)",
                        file=file, row=row, column=names[q],
                        expected=f"speed <= {max_speed} m/s", found=f"{speed[j]:.3f} m/s")
    return pd.DataFrame({q: x}, index=pd.Index(t, name="time"))


def speed_to_distance(odometer: pd.DataFrame) -> pd.DataFrame:
    """Speed table to distance increments (trapezoidal; row 0 = 0)."""
    t = np.asarray(odometer.index, float)
    v = odometer["speed"].to_numpy(float)
    d = np.zeros_like(v)
    d[1:] = 0.5 * (v[1:] + v[:-1]) * np.diff(t)
    return pd.DataFrame({"distance": d}, index=pd.Index(t, name="time"))


def write_odometer(odometer: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write an odometer table as a native insgnss CSV (``time`` + ``speed`` or ``distance``)."""
    from .native import write_table

    validate_odometer(odometer)
    return write_table(odometer, path)
