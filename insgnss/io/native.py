"""insgnss' own CSV tables: the DataFrame conventions written to text.

A native table is a CSV with a header; the first column is ``time`` [s] (the index), the other
columns carry the DataFrame's column names. Columns that hold angles in radians inside insgnss
(``lat lon roll pitch heading`` and their ``*_std``) are written in degrees with a ``_deg``
suffix (``lat_deg``, ``heading_std_deg``) and read back to radians, so that the files are readable
by people and unambiguous for programs. Everything else is SI as in the DataFrame.

Writes are atomic (temporary file in the same folder, then rename) and never replace an input.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputFormatError

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


def to_file_columns(df: pd.DataFrame) -> pd.DataFrame:
    """Copy of ``df`` with angle columns converted to degrees and renamed ``*_deg``."""
    out = df.copy()
    for c in ANGLE_COLUMNS:
        if c in out.columns:
            out[c] = np.degrees(out[c].to_numpy(float))
            out = out.rename(columns={c: f"{c}_deg"})
    return out


def from_file_columns(df: pd.DataFrame) -> pd.DataFrame:
    """Inverse of :func:`to_file_columns`."""
    out = df.copy()
    for c in ANGLE_COLUMNS:
        if f"{c}_deg" in out.columns:
            out[f"{c}_deg"] = np.radians(out[f"{c}_deg"].to_numpy(float))
            out = out.rename(columns={f"{c}_deg": c})
    return out


def csv_writer(out: pd.DataFrame) -> Callable[[Path], None]:
    """A function writing ``out`` (index first, as ``time``) to a CSV path.

    Uses pyarrow's C++ CSV writer (shortest round-trip floats, NaN as ``nan``; ~20x faster
    than pandas for IMU-rate tables) and falls back to pandas with 15 significant digits.
    """
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:  # pragma: no cover - pyarrow is a dependency
        return lambda p: out.to_csv(p, float_format="%.15g", na_rep="nan")
    cols = {str(out.index.name or "time"): pa.array(np.asarray(out.index, float))}
    for c in out.columns:
        v = out[c].to_numpy()
        cols[str(c)] = pa.array(v, from_pandas=False) if v.dtype.kind == "f" else \
            pa.array(v.astype(str) if v.dtype.kind == "O" else v)
    table = pa.table(cols)
    opts = pacsv.WriteOptions(quoting_style="none", quoting_header="none")
    return lambda p: pacsv.write_csv(table, str(p), write_options=opts)


def write_table(df: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write a time-indexed DataFrame as a native insgnss CSV (atomically)."""
    out = to_file_columns(df)
    out.index = pd.Index(np.asarray(df.index, float), name="time")
    return atomic_write(path, csv_writer(out))


def read_table(path: str | os.PathLike, required: list[str] | None = None) -> pd.DataFrame:
    """Read a native insgnss CSV back into a time-indexed DataFrame (radians inside)."""
    path = Path(path)
    try:
        df = pd.read_csv(path)
    except pd.errors.EmptyDataError:
        raise InputFormatError("file is empty", file=path, expected="a CSV with a header") from None
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
