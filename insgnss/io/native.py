"""insgnss' own CSV tables: the DataFrame conventions written to text.

A native table is a CSV with a header; the first column is ``time`` [s] (the index), the other
columns carry the DataFrame's column names. Columns that hold angles in radians inside insgnss
(``lat lon roll pitch heading`` and their ``*_std``) are written in degrees with a ``_deg``
suffix (``lat_deg``, ``heading_std_deg``) and read back to radians, so that the files are readable
by people and unambiguous for programs. Everything else is SI as in the DataFrame.

Writes are atomic (temporary file in the same folder, then rename) and never replace an input.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..columns import OUTPUT_GROUPS, output_columns
from ..columns import output_rate as _output_rate
from ..errors import ConfigError, InputFormatError

_UMASK = os.umask(0)
os.umask(_UMASK)

#: DataFrame columns (radians) written in degrees with a ``_deg`` suffix
ANGLE_COLUMNS = ("lat", "lon", "roll", "pitch", "heading", "roll_std", "pitch_std",
                 "heading_std", "yaw", "yaw_std", "wander_angle")


def atomic_write(path: str | os.PathLike, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp_path)`` and rename the result to ``path`` in one step.

    Either the complete new file or the previous file exists under ``path``; a crash or
    Ctrl-C in the middle leaves at most a temporary ``.<name>.*.tmp`` beside it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        write(tmp_path)
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp creates 0600; give the usual mode
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
    return path


def jsonable(x):
    """A structure with numpy scalars/arrays, tuples and non-finite floats made JSON-ready
    (non-finite floats become ``null``)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        return jsonable(x.item())
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write a text file atomically."""
    return atomic_write(path, lambda p: p.write_text(text))


def _file_names(columns) -> dict:
    """Angle column -> its file name with the ``_deg`` suffix (the others keep their names)."""
    return {c: f"{c}_deg" for c in columns if c in ANGLE_COLUMNS}


def to_file_columns(df: pd.DataFrame) -> pd.DataFrame:
    """Copy of ``df`` with angle columns converted to degrees and renamed ``*_deg`` (for
    pandas-based writers; the native writers convert batch by batch without a copy)."""
    out = df.copy()
    for c in ANGLE_COLUMNS:
        if c in out.columns:
            out[c] = np.degrees(out[c].to_numpy(float))
    return out.rename(columns=_file_names(out.columns))


def file_columns_back(names) -> list[str]:
    """The names inside of file column names: ``*_deg`` of an angle column without the suffix
    (its values are degrees in the file, radians inside); the others unchanged."""
    back = {f"{c}_deg": c for c in ANGLE_COLUMNS}
    return [back.get(c, c) for c in names]


def from_file_columns(df: pd.DataFrame) -> pd.DataFrame:
    """Inverse of :func:`to_file_columns`: ``*_deg`` columns in radians without the suffix."""
    names = file_columns_back(df.columns)
    back = [n for n, c in zip(names, df.columns, strict=True) if n != c]
    if not back:
        return df
    out = df.set_axis(names, axis=1)
    for c in back:
        out[c] = np.radians(out[c].to_numpy(float))
    return out


#: rows converted and written per batch (bounds the writers' extra memory: ~1 MB per column)
BATCH_ROWS = 1 << 17
#: ``df.attrs`` entries kept in a Parquet file's metadata (and restored by :func:`read_table`)
PARQUET_ATTRS = ("time_base", "gps_week")


def _arrow_column(v: np.ndarray):
    import pyarrow as pa

    if v.dtype.kind == "f":
        return pa.array(v, from_pandas=False)  # NaN stays a float NaN (written "nan"), no null
    return pa.array(v.astype(str) if v.dtype.kind in "OUT" else v)


def file_batches(df: pd.DataFrame, rows: int | None = None, index_name: str = "time"):
    """The native file columns of ``df`` as pyarrow record batches of ``rows`` rows
    (default :data:`BATCH_ROWS`).

    The index (named ``index_name``) first, then the columns; angle columns in degrees with the ``_deg``
    suffix. Only the angle columns of one batch are converted: the table is never copied.
    Returns ``(schema, iterator of batches)``.
    """
    import pyarrow as pa

    deg = _file_names(df.columns)
    names = [index_name, *(str(deg.get(c, c)) for c in df.columns)]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputFormatError("duplicate column in a table to write", column=dup,
                               expected="unique column names", found=", ".join(names))
    arrays = [np.asarray(df.index, float)]
    arrays += [df[c].to_numpy() for c in df.columns]
    angle = [False] + [c in ANGLE_COLUMNS for c in df.columns]
    rows = int(rows or BATCH_ROWS)

    def batch(i: int, j: int):
        cols = [_arrow_column(np.degrees(np.asarray(a[i:j], float)) if is_angle else a[i:j])
                for a, is_angle in zip(arrays, angle, strict=True)]
        return pa.RecordBatch.from_arrays(cols, names=names)

    def batches():
        from .spill import release

        for i in range(0, max(len(df), 1), rows):
            j = min(i + rows, len(df))
            yield batch(i, j)
            for a in arrays:  # a memory-mapped table (io/spill.py): its pages go back
                release(a, i, j)

    schema = batch(0, 0).schema
    return schema, batches()


def csv_writer(df: pd.DataFrame, index_name: str | None = None) -> Callable[[Path], None]:
    """A function writing the insgnss table ``df`` as a native CSV to a path.

    pyarrow's C++ CSV writer (shortest round-trip floats, NaN as ``nan``; ~20x faster than
    pandas for IMU-rate tables), fed batch by batch (:func:`file_batches`). The first column
    is the index, named ``index_name`` (default: the index's name, else ``time``).
    """
    index_name = str(index_name or df.index.name or "time")
    import pyarrow.csv as pacsv

    opts = pacsv.WriteOptions(quoting_style="none", quoting_header="none")

    def write(p: Path) -> None:
        schema, batches = file_batches(df, index_name=index_name)
        with pacsv.CSVWriter(str(p), schema, write_options=opts) as w:
            for b in batches:
                w.write_batch(b)

    return write


def parquet_writer(df: pd.DataFrame) -> Callable[[Path], None]:
    """A function writing the insgnss table ``df`` as a native Parquet file to a path: the
    columns of the CSV (``time``, angles in degrees ``*_deg``), float64, one row group per
    :data:`BATCH_ROWS` rows, and :data:`PARQUET_ATTRS` in the file's metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = {k: df.attrs[k] for k in PARQUET_ATTRS if df.attrs.get(k) is not None}

    def write(p: Path) -> None:
        schema, batches = file_batches(df)
        schema = schema.with_metadata({b"insgnss": json.dumps(jsonable(meta)).encode()})
        # no dictionary for float columns: their values hardly repeat, and trying costs 8x
        dictionary = [f.name for f in schema if not pa.types.is_floating(f.type)]
        with pq.ParquetWriter(str(p), schema, compression="snappy",
                              use_dictionary=dictionary) as w:
            for b in batches:
                w.write_batch(b)

    return write


def fixed_decimal_text(v: np.ndarray, decimals: int):
    """``f"{x:.{decimals}f}"`` (printf ``%.Nf``) for every value of ``v``, as a pyarrow string array.

    Identical to Python's (and ``np.savetxt``'s) formatting, at pyarrow speed (~20 M values/s
    instead of ~2 M): the value scaled by ``10**decimals`` is rounded to an integer and printed
    by pyarrow as a decimal with ``decimals`` digits. The few values where that rounding could
    differ from the exact decimal expansion that ``%f`` rounds (within a few ulp of a half),
    non-finite values and values beyond 18 digits are formatted by Python; values below 1e-6
    are written without an exponent and ``-0.000`` (a small negative value) keeps its sign, as
    ``%f`` does.
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    if not 0 <= decimals <= 12:
        raise ValueError(f"decimals must be 0..12, got {decimals}")
    v = np.ascontiguousarray(v, float)
    with np.errstate(invalid="ignore", over="ignore"):
        x = v * 10.0**decimals  # exact power of ten: x has one rounding error, <= ulp(x) / 2
        q = np.rint(x)
        frac = np.abs(x - np.floor(x) - 0.5)
        odd = ~(np.abs(q) < 1e17) | (frac <= np.abs(x) * 2.0**-50)
    q[odd] = 0.0
    u = q.astype(np.int64)
    text = pc.cast(pa.Array.from_buffers(pa.decimal64(18, decimals), v.size,
                                         [None, pa.py_buffer(u)]), pa.string())
    # |x| < 1e-6 with more than 6 decimals prints in exponent notation (5.2E-7) and a value
    # that rounds to zero loses its sign: write those as [-]0.<digits>
    small = (np.abs(u) < 10 ** (decimals - 6)) if decimals > 6 else (u == 0) & np.signbit(v)
    small &= ~odd
    if small.any():
        k = np.flatnonzero(small)
        if decimals:
            digits = pc.utf8_lpad(pc.cast(pa.array(np.abs(u[k])), pa.string()), decimals, "0")
            fixed = pc.binary_join_element_wise(
                pa.array(np.where(np.signbit(v[k]), "-0.", "0.")), digits, "")
        else:
            fixed = pa.array(np.full(k.size, "-0"))
        text = pc.replace_with_mask(text, pa.array(small), fixed)
    if odd.any():
        text = pc.replace_with_mask(text, pa.array(odd),
                                    pa.array([f"{z:.{decimals}f}" for z in v[odd]]))
    return text


def select_output_columns(df: pd.DataFrame, groups: Sequence[str]) -> pd.DataFrame:
    """The columns of a trajectory table in the output ``groups`` (``[outputs] columns``:
    ``nav std params all``, :mod:`insgnss.columns`); a view, not a copy."""
    try:
        cols = output_columns(df.columns, groups)
    except ValueError as exc:
        raise ConfigError(str(exc), column="outputs.columns", expected=list(OUTPUT_GROUPS),
                          found=list(groups)) from None
    return df if len(cols) == df.shape[1] else df[cols]


def output_rate(value: float | str | None, preset: str = "standard") -> float | None:
    """``[outputs] rate_hz`` as a rate [Hz], or None for every IMU sample
    (:func:`insgnss.columns.output_rate`; a :class:`ConfigError` naming the key)."""
    try:
        return _output_rate(float(value) if isinstance(value, np.integer | np.floating)
                            else value, preset)
    except ValueError as exc:
        raise ConfigError(str(exc), column="outputs.rate_hz", expected='> 0, "imu" or "auto"',
                          found=repr(value)) from None


def decimation_rows(t: np.ndarray, rate_hz: float | str | None,
                    keep_times: Iterable[np.ndarray] = (), preset: str = "standard"
                    ) -> np.ndarray | None:
    """Row numbers of a table at times ``t`` kept when writing it at ``rate_hz``.

    Kept: the first sample at or after each multiple of ``1 / rate_hz`` (so the output epochs
    do not depend on where the log starts), the first and the last sample, and for each time
    in ``keep_times`` the first sample at or after it and, unless that sample is at the time,
    the last one before it. With the aiding epochs as ``keep_times``, linear interpolation of
    the written table at those epochs gives what it gives on the full table (a forward
    solution jumps at each update; a scorer interpolating across the jump from decimated
    samples would score a different number), and between them the trajectory is smooth: the
    linear-interpolation error of a decimated table is ``a dt^2 / 8`` (4 mm at 10 Hz and
    3 m/s^2).

    Returns None when every row is kept (``rate_hz`` ``"imu"``/None, or at least the data rate).
    ``"auto"`` is the rate of the process ``preset`` (:func:`insgnss.columns.output_rate`).
    """
    rate = output_rate(rate_hz, preset)
    t = np.asarray(t, float)
    n = t.size
    if rate is None or n < 3:
        return None
    cell = np.floor(t * rate)
    keep = np.empty(n, bool)
    keep[0] = True
    np.not_equal(cell[1:], cell[:-1], out=keep[1:])
    keep[-1] = True
    for kt in keep_times:
        kt = np.asarray(kt, float)
        kt = kt[(kt > t[0]) & (kt <= t[-1])]
        after = np.searchsorted(t, kt, side="left")
        keep[after] = True
        keep[after[t[after] != kt] - 1] = True  # an epoch on a sample needs no bracket
    if keep.all():
        return None
    return np.flatnonzero(keep)


def decimate_table(df: pd.DataFrame, rate_hz: float | str | None,
                   keep_times: Iterable[np.ndarray] = (), preset: str = "standard"
                   ) -> pd.DataFrame:
    """``df`` at about ``rate_hz`` (``[outputs] rate_hz``; ``"imu"``: every sample), keeping
    the samples around ``keep_times`` (:func:`decimation_rows`). The table itself when every
    row is kept."""
    rows = decimation_rows(np.asarray(df.index, float), rate_hz, keep_times, preset)
    return df if rows is None else df.iloc[rows]


def write_table(df: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write a time-indexed DataFrame as a native insgnss table (atomically): CSV, or Parquet
    when ``path`` ends in ``.parquet`` (:func:`write_parquet`)."""
    if Path(path).suffix.lower() == ".parquet":
        return write_parquet(df, path)
    return atomic_write(path, csv_writer(df, index_name="time"))


def write_parquet(df: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write a time-indexed DataFrame as a native insgnss Parquet file (atomically).

    Same columns and units as the native CSV (:func:`read_table` reads both); binary float64,
    so values round-trip exactly, and pandas, polars, DuckDB or MATLAB read it directly.
    """
    return atomic_write(path, parquet_writer(df))


def read_table(path: str | os.PathLike, required: list[str] | None = None) -> pd.DataFrame:
    """Read a native insgnss table (CSV, or Parquet for ``*.parquet``) back into a time-indexed
    DataFrame (radians inside)."""
    path = Path(path)
    if path.suffix.lower() == ".parquet":
        df = _read_parquet(path)
    else:
        try:
            df = pd.read_csv(path)
        except pd.errors.EmptyDataError:
            raise InputFormatError("file is empty", file=path,
                                   expected="a CSV with a header") from None
    if "time" not in df.columns:
        raise InputFormatError("no 'time' column", file=path, row=1, expected="'time' first",
                               found=list(df.columns))
    df = from_file_columns(df.set_index("time"))
    if required:
        missing = [c for c in required if c not in df.columns]
        if missing:
            raise InputFormatError("missing columns", file=path, row=1,
                                   expected=required, found=list(df.columns))
    return df


def _read_parquet(path: Path) -> pd.DataFrame:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowInvalid, OSError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise InputFormatError(f"not a readable Parquet file: {exc}", file=path,
                               expected="a Parquet table written by insgnss or pandas") from None
    df = table.to_pandas()
    meta = (table.schema.metadata or {}).get(b"insgnss")
    if meta:
        df.attrs.update(json.loads(meta))
    return df
