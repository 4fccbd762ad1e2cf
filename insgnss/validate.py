"""Shared input validation: one implementation of every check the readers and the pipeline run.

Every check locates the problem the way a user looks for it: the file, the **1-based line as an
editor shows it** (header and comment lines count), the column (as named in the file, or a
descriptive name for header-less formats), what was expected and what was found. One exception
class per class of problem (:mod:`insgnss.errors`):

=========================================  ===================================================
problem                                    raised
=========================================  ===================================================
missing file, empty file, not text,        :class:`~insgnss.errors.InputFormatError`
wrong field count, missing column,
non-numeric cell, too few rows
NaN / inf, value out of its valid range    :class:`~insgnss.errors.InvalidValueError`
time going backwards, duplicated time      :class:`~insgnss.errors.TimeOrderError`
(policy ``"error"``), epochs outside the
IMU span
gap longer than the policy bridges         :class:`~insgnss.errors.DataGapError`
sample rate != declared rate               :class:`~insgnss.errors.RateMismatchError`
magnitudes implausible for the declared    :class:`~insgnss.errors.UnitError`
unit (accel in g declared m/s^2, gyro in
deg/s declared rad/s)
bad argument (unknown unit, policy, axis   :class:`~insgnss.errors.ConfigError`
map), output path equal to an input
=========================================  ===================================================

Repairs the policies allow are announced with :class:`~insgnss.errors.InsgnssWarning` and
recorded in the table's ``attrs``:

- ``attrs["dropped_duplicates"]``: ``[{"row", "time"}]`` samples dropped because their time
  stamp repeated the previous one (the first is kept);
- ``attrs["gaps"]``: ``[{"row", "start", "end", "duration", "missing", "action"}]`` intervals
  longer than ``GapPolicy.factor`` nominal intervals, ``action`` = ``"bridged"`` or ``"split"``;
- ``attrs["segments"]``: ``[(t_start, t_end)]`` contiguous parts when long gaps split the data;
- ``attrs["outside_imu_span"]``: ``[{"row", "time"}]`` GNSS epochs trimmed by
  :func:`check_gnss_in_imu_span`.

Gap policy: intervals longer than ``factor`` (1.5) nominal sample intervals are gaps,
unless they are the clock's recurring jitter (:func:`jitter_envelope`: an interval length that at
least 1 % of the intervals reach is the logger's time-stamp jitter, not a lost sample).
Gaps up to ``max_bridge`` seconds (1.0 s) are bridged (the mechanization integrates across
them) with a warning; longer gaps are handled by ``long``: ``"error"`` (default, stop with
:class:`~insgnss.errors.DataGapError`), ``"split"`` (record segments; process each one) or
``"bridge"``.

Unit plausibility heuristics (only for the IMU, on the data converted to SI):

- the median specific-force norm must lie in [0.5 g, 2 g] (any IMU on Earth measures about
  1 g on average; data in g declared as m/s^2 gives about 1, increments give g * dt);
- while the accelerometers are still (rolling std of the norm over 11 samples < 0.2 m/s^2 and
  the norm within 10 % of g, at least 20 such samples), the median gyro norm must be below
  0.5 rad/s (28.6 deg/s); a car's raw deg/s log declared as rad/s gives about 2 "rad/s" there,
  real rad/s data at most about 0.1. Any rate above 100 rad/s is rejected outright.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import (
    ConfigError,
    DataGapError,
    InputFormatError,
    InsgnssWarning,
    InvalidValueError,
    RateMismatchError,
    TimeOrderError,
    UnitError,
)
from .imu import G0

# --------------------------------------------------------------------------------------------
# warnings
# --------------------------------------------------------------------------------------------


def warn(message: str, *, file=None, row: int | None = None, column=None, expected=None,
         found=None, stacklevel: int = 3) -> None:
    """Emit an :class:`InsgnssWarning` carrying a location."""
    warnings.warn(InsgnssWarning(message, file=file, row=row, column=column, expected=expected,
                                 found=found), stacklevel=stacklevel)


# --------------------------------------------------------------------------------------------
# text files
# --------------------------------------------------------------------------------------------


@dataclass
class TextRows:
    """Data lines of a text file and where they are.

    Attributes
    ----------
    file : Path
    lines : list of str
        Data lines, stripped, without blank and comment lines (and without the header).
    line_no : (N,) int array
        1-based line number of each data line as an editor shows it.
    header : str or None
        Header line (stripped) when one was requested.
    header_line : int or None
        Its line number.
    comments : list of (int, str)
        Comment lines and their line numbers (e.g. the RTKLIB ``%`` header).
    """

    file: Path
    lines: list[str]
    line_no: np.ndarray
    header: str | None = None
    header_line: int | None = None
    comments: list[tuple[int, str]] = field(default_factory=list)
    #: every field of every data line as float (NaN in empty cells), when the fast reader
    #: (:func:`read_rows`) parsed the whole file; ``None`` otherwise
    table: np.ndarray | None = None
    #: ``table`` has empty cells
    table_empty: bool = False
    #: field separator ``table`` was parsed with
    table_delimiter: str | None = None


def read_text(path: str | os.PathLike) -> str:
    """Read a UTF-8 text file; missing, unreadable, empty or binary files raise InputFormatError."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputFormatError("file not found", file=path) from None
    except OSError as e:
        raise InputFormatError(f"cannot read the file ({e.strerror or e})", file=path) from None
    if not data.strip():
        raise InputFormatError("file is empty", file=path, row=1, expected="data rows",
                               found="no data")
    nul = data.find(b"\x00")
    if nul >= 0:
        raise InputFormatError("binary data in a text file", file=path,
                               row=data.count(b"\n", 0, nul) + 1, expected="UTF-8 text",
                               found="a NUL byte")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputFormatError("not a UTF-8 text file", file=path,
                               row=data.count(b"\n", 0, e.start) + 1, expected="UTF-8 text",
                               found=f"byte 0x{data[e.start]:02x}") from None
    return text.removeprefix("\ufeff")


def split_lines(text: str, file, *, comment: tuple[str, ...] = ("#",), header: bool = False
                ) -> TextRows:
    """Split ``text`` into data lines with their editor line numbers.

    Blank lines and lines starting with one of ``comment`` are skipped (kept in ``comments``).
    With ``header=True`` the first remaining line is the header. Raises InputFormatError when no
    data line remains.
    """
    comment = tuple(c for c in comment if c)
    stripped = [line.strip() for line in text.split("\n")]
    if comment:
        keep = [i for i, line in enumerate(stripped) if line and not line.startswith(comment)]
        comments = [(i + 1, line) for i, line in enumerate(stripped)
                    if line and line.startswith(comment)]
    else:
        keep = [i for i, line in enumerate(stripped) if line]
        comments = []
    file = Path(file)
    head = head_no = None
    if header:
        if not keep:
            raise InputFormatError("no header line", file=file, row=1, expected="a header line",
                                   found="only blank or comment lines")
        head_no = keep[0] + 1
        head = stripped[keep[0]]
        keep = keep[1:]
    if not keep:
        row = (head_no + 1) if head_no else len(stripped)
        raise InputFormatError("no data rows", file=file, row=row, expected="at least one data row",
                               found="none")
    lines = [stripped[i] for i in keep]
    return TextRows(file, lines, np.asarray(keep, dtype=np.int64) + 1, head, head_no, comments)


# --- fast path: a clean numeric table parsed by pyarrow's CSV reader -------------------------
# The validating path above (``split_lines`` + :func:`parse_numeric`) handles every line in
# Python; for a clean file (one delimiter, no comment or blank line after the header, every
# field a number) pyarrow's multi-threaded C++ parser gives the same floats (both round
# correctly) 10-20x faster. Anything the fast path does not handle exactly as the validating
# path does makes it give up, and the validating path then reads the file and locates the
# problem with its usual message (file, line, column, expected, found).

#: characters a comment prefix may start with on the fast path: none of them can begin a number
_COMMENT_START = set("#%;!/*@$&'\"")


class _LazyLines(Sequence):
    """The data lines of a file read by the fast path, split only if someone asks for them
    (e.g. to locate a problem), through the validating path; the first line is kept."""

    def __init__(self, path, comment, header, trim, first: str, n: int):
        self._args = (path, comment, header, trim)
        self._first = first
        self._n = n
        self._lines = None

    def load(self) -> list[str]:
        """All data lines (split by the validating path; raises what it raises)."""
        if self._lines is None:
            self._lines = _split_rows(*self._args).lines
        return self._lines

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i):
        if isinstance(i, int) and i in (0, -self._n):
            return self._first
        return self.load()[i]

    def __iter__(self):
        return iter(self.load())


def _split_rows(path, comment, header, trim) -> TextRows:
    rows = split_lines(read_text(path), path, comment=comment, header=header)
    if trim:
        require_rows(len(rows.lines), 3, path, row=int(rows.line_no[-1]), what="lines")
        rows.lines = rows.lines[1:-1]
        rows.line_no = rows.line_no[1:-1]
    return rows


def read_rows(path: str | os.PathLike, *, comment: tuple[str, ...] = ("#",),
              header: bool = False, delimiter: str | None = ",", trim: bool = False,
              allocate=None) -> TextRows:
    """The data lines of a text file (:func:`read_text` + :func:`split_lines`), with every field
    already parsed as float (``TextRows.table``) when the file is a clean numeric table.

    ``trim=True`` drops the first and the last data line (partial lines of a logger that was
    started and stopped while writing; at least 3 lines are required). :func:`parse_numeric`
    takes its values from ``table`` when it can and otherwise parses ``lines``, which are
    split on first use; the result, and every error message, is the same either way.
    ``allocate(shape)``: where ``table`` is made (default ``numpy.empty``; an
    :class:`insgnss.io.spill.SpillAllocator` puts a long table on a memory-mapped file, whose
    pages are given back block by block as they are parsed).
    """
    comment = tuple(c for c in comment if c)
    rows = _clean_rows(Path(path), comment, header, delimiter, trim, allocate)
    return rows if rows is not None else _split_rows(path, comment, header, trim)


#: files larger than this are read and parsed in line-aligned blocks of about this size (bytes)
READ_BLOCK = 32 << 20
_WS = b" \t\r\n"


def _file_chunks(path: Path, start: int, stop: int, block: int):
    """Line-aligned chunks of ``path[start:stop]`` of about ``block`` bytes, each as
    ``(buffer, a, b)``: the bytes ``buffer[a:b]``.

    The file is read with ``readinto`` into one reused buffer (the part of a line cut by the
    block's end moved to its front): no chunk is copied or joined, which made a quarter of the
    reading time of a 100 MB log. A chunk is valid until the next one is asked for."""
    buf = bytearray(block)
    with open(path, "rb") as f:
        f.seek(start)
        left, have = stop - start, 0  # ``have``: bytes carried at the front of ``buf``
        while left > 0 or have:
            n = have
            if left > 0:
                if have == len(buf):  # one line longer than the buffer: a larger one
                    buf = bytearray(buf) + bytearray(len(buf))
                with memoryview(buf) as mv:
                    got = f.readinto(mv[have:have + min(len(buf) - have, left)])
                left = left - got if got else 0  # a file cut short: what was read
                n = have + got
            cut = n
            if left > 0:
                cut = buf.rfind(b"\n", 0, n) + 1
                if cut == 0:
                    have = n
                    continue
            yield buf, 0, cut
            have = n - cut
            buf[:have] = buf[cut:n]  # same length: the buffer is not resized


def _clean_rows(path: Path, comment, header, delimiter, trim, allocate=None
                ) -> TextRows | None:
    """:func:`read_rows` on pyarrow, or None when the file is not clean (see above).

    A file larger than :data:`READ_BLOCK` is read and parsed block by block (line-aligned),
    each block straight into the value table: the peak memory is the table plus one block,
    not the file's bytes, pyarrow's table and the values at once; the values are the same."""
    if delimiter is None or len(delimiter) != 1 or delimiter in " \t\r\n\"" \
            or any(c[0] not in _COMMENT_START for c in comment):
        return None
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            data = f.read(READ_BLOCK if size > READ_BLOCK else -1)  # the head of a large file
            tail = data
            if size > READ_BLOCK:
                f.seek(max(size - (1 << 16), 0))
                tail = f.read()
    except OSError:
        return None
    whole = len(data) >= size  # all of the file is in ``data``
    # lines before the data: blank, comment and header lines (a few, in Python)
    pos, line, comments, head, head_no = 0, 0, [], None, None
    while True:
        end = data.find(b"\n", pos)
        if end < 0 and not whole:
            return None  # a head without its first data line: the validating path
        try:
            text = data[pos:end if end >= 0 else len(data)].decode("utf-8").strip()
        except UnicodeDecodeError:
            return None
        line += 1
        if not text:
            pass
        elif comment and text.startswith(comment):
            comments.append((line, text))
        elif header and head is None:
            head, head_no = text, line
        else:
            break  # the first data line
        if end < 0:
            return None  # no data line: the validating path says what is missing
        pos = end + 1
    start, first_no = pos, line
    if trim:  # drop the first data line here and the last one below
        if end < 0:
            return None
        start, first_no = end + 1, line + 1
        body = len(tail.rstrip(_WS))
        if body == 0 and not whole:
            return None
        cut = tail.rfind(b"\n", 0, body)
        if cut < 0 and not whole:
            return None
        stop = cut + (size - len(tail))
        if stop <= start:
            return None
    else:
        stop = size
    nxt = data.find(b"\n", start, min(stop, len(data)))
    if nxt < 0 and not whole:
        return None
    first = data[start:nxt if nxt >= 0 else stop].decode("utf-8", "replace").strip()
    n_fields = first.count(delimiter) + 1
    if n_fields < 2:  # one column: a blank line would be a row of it
        return None

    def chunks():  # (buffer, a, b): the bytes buffer[a:b]
        if whole:
            yield data, start, stop
        else:
            yield from _file_chunks(path, start, stop, READ_BLOCK)

    def lone_cr(c, a=0, b=None) -> bool:  # a lone CR ends a line for pyarrow, not split_lines
        b = len(c) if b is None else b
        return c.find(b"\r", a, b) >= 0 and c.count(b"\r", a, b) != c.count(b"\r\n", a, b)

    if whole:
        if lone_cr(data):
            return None
        n_lines = data.count(b"\n", start, stop) + (0 if data[stop - 1:stop] == b"\n" else 1)
        paren = b"(" in data
    else:  # pass 1 over a large file: the line count and the same checks, block by block
        if lone_cr(data, 0, start) or lone_cr(tail, max(stop - (size - len(tail)), 0)):
            return None
        n_lines, paren, last = 0, False, b"\n"
        for c, a, b in chunks():
            if lone_cr(c, a, b):
                return None
            n_lines += c.count(b"\n", a, b)
            paren = paren or c.find(b"(", a, b) >= 0
            last = c[b - 1:b] if b > a else last
        n_lines += 0 if last == b"\n" else 1
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from .io.spill import release, trim_heap

    names = [f"f{i}" for i in range(n_fields)]
    opts = {"read_options": pacsv.ReadOptions(column_names=names),
            "parse_options": pacsv.ParseOptions(delimiter=delimiter, quote_char=False,
                                                escape_char=False, newlines_in_values=False,
                                                ignore_empty_lines=False),
            "convert_options": pacsv.ConvertOptions(
                column_types=dict.fromkeys(names, pa.float64()), null_values=[""],
                strings_can_be_null=False, quoted_strings_can_be_null=False),
            # the system allocator: the parse buffers go back to the system when a block's
            # table is freed, where pyarrow's default pool (mimalloc) keeps much of them
            "memory_pool": pa.system_memory_pool()}
    if n_lines == 0:
        return None
    # column-major: each column one contiguous copy
    values = (np.empty if allocate is None else allocate)((n_fields, n_lines)).T
    r0, any_null = 0, False
    for c, a, b in chunks():  # pass 2: parse block by block into the values
        try:
            with memoryview(c) as mv:
                tab = pacsv.read_csv(pa.py_buffer(mv[a:b]), **opts)
        except (pa.ArrowInvalid, pa.ArrowTypeError, ValueError):
            return None
        m = tab.num_rows
        if r0 + m > n_lines:
            return None
        nulls = [col.null_count for col in tab.columns]
        if all(nulls):  # a blank line is a row of empty cells for pyarrow; split_lines skips it
            blank = np.logical_and.reduce([col.is_null().to_numpy(zero_copy_only=False)
                                           for col in tab.columns])
            if blank.any():
                return None
        any_null = any_null or any(nulls)
        for j, col in enumerate(tab.columns):
            values[r0:r0 + m, j] = (col.fill_null(np.nan) if nulls[j] else col).to_numpy()
            release(values[:, j], r0, r0 + m)  # a mapped table: the block's pages go back
        r0 += m
        del tab
    trim_heap()
    n = r0
    if n != n_lines or n == 0:
        return None
    if paren and np.isnan(values).any():
        return None  # "nan(...)" is a NaN for pyarrow, not a number for numpy
    lines = _LazyLines(path, comment, header, trim, first, n)
    return TextRows(path, lines, np.arange(first_no, first_no + n, dtype=np.int64), head,
                    head_no, comments, table=values, table_empty=any_null,
                    table_delimiter=delimiter)


def _strict_float(cell: str) -> float:
    if "_" in cell:
        raise ValueError(cell)
    return float(cell)


def parse_numeric(rows: TextRows, names: Sequence[str], *, delimiter: str | None = ",",
                  usecols: Sequence[int] | None = None, ncols: int | None = None,
                  empty_nan: bool = False) -> np.ndarray:
    """Parse the data lines of ``rows`` as a float matrix, locating any problem.

    Parameters
    ----------
    rows : TextRows
    names : sequence of str
        Column names used in messages; ``names[j]`` names field ``usecols[j]`` (or field ``j``).
    delimiter : str or None
        Field separator; ``None`` splits on runs of whitespace.
    usecols : sequence of int, optional
        Fields to parse (0-based); other fields are not checked except for their count.
    ncols : int, optional
        Exact number of fields every line must have (default: ``len(names)`` without
        ``usecols``; with ``usecols`` at least ``max(usecols) + 1``).
    empty_nan : bool
        Empty (or blank) fields are NaN; otherwise they are non-numeric values.

    Returns
    -------
    (N, len(names)) float array (NaN/inf are returned as such; see :func:`check_finite`).
    """
    cols = list(range(len(names))) if usecols is None else list(usecols)
    exact = ncols if ncols is not None else (len(names) if usecols is None else None)
    if rows.table is not None and rows.table_delimiter == delimiter:
        nf = rows.table.shape[1]  # every line has nf fields (pyarrow checked)
        if (exact is None or nf == exact) and max(cols, default=-1) < nf \
                and (empty_nan or not rows.table_empty):
            return rows.table[:, cols] if cols != list(range(nf)) else rows.table
    if isinstance(rows.lines, _LazyLines):  # the validating path needs the lines
        rows = TextRows(rows.file, rows.lines.load(), rows.line_no, rows.header,
                        rows.header_line, rows.comments)
    lines = rows.lines
    if empty_nan and delimiter is not None:
        lines = [delimiter.join(f if f.strip() else "nan" for f in s.split(delimiter))
                 if (delimiter * 2 in s or s.endswith(delimiter) or s.startswith(delimiter))
                 else s for s in lines]
        rows = TextRows(rows.file, lines, rows.line_no, rows.header, rows.header_line,
                        rows.comments)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arr = np.loadtxt(lines, delimiter=delimiter, dtype=float, comments=None,
                             ndmin=2, usecols=cols if usecols is not None else None,
                             quotechar=None)
        ok = arr.shape == (len(rows.lines), len(cols))
        if ok and exact is not None and usecols is not None:
            # loadtxt does not check the total field count with usecols
            n = np.fromiter((len(s.split(delimiter)) for s in rows.lines), np.int64,
                            len(rows.lines))
            ok = bool(np.all(n == exact))
        if ok:
            return arr
    except (ValueError, IndexError, OverflowError, TypeError):
        pass
    return _diagnose_numeric(rows, names, cols, delimiter, exact)


def _diagnose_numeric(rows: TextRows, names, cols, delimiter, exact) -> np.ndarray:
    need = max(cols) + 1 if cols else 0
    out = np.empty((len(rows.lines), len(cols)))
    expected_fields = f"{exact} fields" if exact is not None else f"at least {need} fields"
    for i, line in enumerate(rows.lines):
        f = line.split(delimiter)
        if (exact is not None and len(f) != exact) or len(f) < need:
            raise InputFormatError("wrong number of fields", file=rows.file, row=int(rows.line_no[i]),
                                   expected=expected_fields, found=f"{len(f)} fields")
        for j, c in enumerate(cols):
            try:
                out[i, j] = _strict_float(f[c])
            except ValueError:
                raise InputFormatError("non-numeric value", file=rows.file,
                                       row=int(rows.line_no[i]), column=names[j],
                                       expected="a number", found=repr(f[c].strip()[:40])) from None
    return out


# --------------------------------------------------------------------------------------------
# values
# --------------------------------------------------------------------------------------------


def check_finite(values: np.ndarray, names: Sequence[str], line_no: np.ndarray, file, *,
                 columns: Sequence[int] | None = None) -> None:
    """Raise InvalidValueError at the first NaN or inf (row-major order) of ``values``, or of
    its ``columns`` (named ``names``), checked one column at a time: no copy of the columns."""
    values = np.asarray(values, float)
    if values.ndim == 1:
        values = values[:, None]
    cols = range(values.shape[1]) if columns is None else list(columns)
    first = None  # (row, position in cols) of the first non-finite value
    for j, c in enumerate(cols):
        bad = np.flatnonzero(~np.isfinite(values[:, c]))
        if bad.size and (first is None or bad[0] < first[0]):
            first = (int(bad[0]), j)
    if first is None:
        return
    i, j = first
    raise InvalidValueError("non-finite value", file=file, row=int(line_no[i]), column=names[j],
                            expected="a finite number", found=str(values[i, cols[j]]))


def check_range(values: np.ndarray, lo: float, hi: float, column: str, line_no: np.ndarray, file,
                *, unit: str = "") -> None:
    """Raise InvalidValueError at the first value outside ``[lo, hi]``."""
    values = np.asarray(values, float)
    bad = (values < lo) | (values > hi)
    if not bad.any():
        return
    i = int(np.flatnonzero(bad)[0])
    raise InvalidValueError("value out of range", file=file, row=int(line_no[i]), column=column,
                            expected=f"{lo:g} <= value <= {hi:g}{(' ' + unit) if unit else ''}",
                            found=f"{values[i]:g}")


def check_allowed(values: np.ndarray, allowed: Iterable[float], column: str, line_no: np.ndarray,
                  file) -> None:
    """Raise InvalidValueError at the first value not in ``allowed``."""
    allowed = np.asarray(sorted(allowed), float)
    bad = ~np.isin(np.asarray(values, float), allowed)
    if not bad.any():
        return
    i = int(np.flatnonzero(bad)[0])
    raise InvalidValueError("invalid value", file=file, row=int(line_no[i]), column=column,
                            expected="one of " + ", ".join(f"{a:g}" for a in allowed),
                            found=f"{float(values[i]):g}")


def require_rows(n: int, minimum: int, file, row: int | None = None, what: str = "samples") -> None:
    """Raise InputFormatError if fewer than ``minimum`` rows remain."""
    if n < minimum:
        raise InputFormatError(f"too few {what}", file=file, row=row,
                               expected=f"at least {minimum}", found=str(n))


# --------------------------------------------------------------------------------------------
# time
# --------------------------------------------------------------------------------------------

DUPLICATE_POLICIES = ("drop", "error")


def check_time_order(t: np.ndarray, line_no: np.ndarray, file, *, column: str = "time",
                     duplicates: str = "drop") -> tuple[np.ndarray, list[dict]]:
    """Time must increase strictly; repeated stamps are dropped (policy) or an error.

    Returns
    -------
    keep : (N,) bool array
        False for dropped duplicates.
    dropped : list of dict
        ``{"row", "time"}`` of every dropped sample (also announced by one warning).
    """
    if duplicates not in DUPLICATE_POLICIES:
        raise ConfigError("unknown duplicate policy", column="duplicates",
                          expected=" or ".join(DUPLICATE_POLICIES), found=repr(duplicates))
    t = np.asarray(t, float)
    d = np.diff(t)
    back = np.flatnonzero(d < 0)
    if back.size:
        k = int(back[0]) + 1
        raise TimeOrderError("time goes backwards", file=file, row=int(line_no[k]), column=column,
                             expected=f"a time after {float(t[k - 1])!r} (row {int(line_no[k - 1])})",
                             found=repr(float(t[k])))
    keep = np.ones(t.size, bool)
    dup = np.flatnonzero(d == 0) + 1
    if not dup.size:
        return keep, []
    k = int(dup[0])
    if duplicates == "error":
        raise TimeOrderError("duplicated time stamp", file=file, row=int(line_no[k]), column=column,
                             expected=f"a time after {float(t[k - 1])!r} (row {int(line_no[k - 1])})",
                             found=repr(float(t[k])))
    keep[dup] = False
    dropped = [{"row": int(line_no[i]), "time": float(t[i])} for i in dup]
    warn(f"{dup.size} sample(s) with a duplicated time stamp dropped (first kept)", file=file,
         row=int(line_no[k]), column=column, found=repr(float(t[k])))
    return keep, dropped


def nominal_interval(t: np.ndarray) -> float:
    """Median sample interval [s]."""
    return float(np.median(np.diff(np.asarray(t, float))))


def check_rate(t: np.ndarray, line_no: np.ndarray, file, rate_hz: float | None, *,
               column: str = "time", tolerance: float = 0.05) -> float:
    """Compare the measured rate (1 / median interval) with the declared ``rate_hz``.

    Returns the nominal interval [s]: ``1 / rate_hz`` when declared, else the median interval.
    Raises RateMismatchError when they differ by more than ``tolerance`` (relative).
    """
    dt = nominal_interval(t)
    if rate_hz is None:
        return dt
    try:
        rate_ok = float(rate_hz) > 0 and np.isfinite(float(rate_hz))
    except (TypeError, ValueError):
        rate_ok = False
    if not rate_ok:
        raise ConfigError("invalid declared sample rate", column="rate_hz",
                          expected="a positive number of Hz", found=repr(rate_hz))
    rate_hz = float(rate_hz)
    measured = 1.0 / dt
    if abs(measured / rate_hz - 1.0) > tolerance:
        raise RateMismatchError("sample rate does not match the declared rate", file=file,
                                row=int(line_no[1]), column=column,
                                expected=f"{rate_hz:g} Hz (+-{tolerance:.0%})",
                                found=f"{measured:.6g} Hz (median interval {dt:.6g} s)")
    return 1.0 / rate_hz


@dataclass(frozen=True)
class GapPolicy:
    """What to do with IMU gaps.

    Attributes
    ----------
    factor : float
        An interval longer than ``factor`` nominal intervals is a gap (1.5).
    max_bridge : float
        Gaps up to this duration [s] are bridged with a warning (1.0 s).
    long : {"error", "split", "bridge"}
        Longer gaps stop with DataGapError (default), split the data into segments
        (``attrs["segments"]``), or are bridged too.
    """

    factor: float = 1.5
    max_bridge: float = 1.0
    long: str = "error"

    def __post_init__(self):
        if self.long not in ("error", "split", "bridge"):
            raise ConfigError("unknown gap policy", column="gap_policy.long",
                              expected="'error', 'split' or 'bridge'", found=repr(self.long))
        for name in ("factor", "max_bridge"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
                raise ConfigError("invalid gap policy value", column=f"gap_policy.{name}",
                                  expected="a non-negative number", found=repr(v))
        if self.factor <= 1.0:
            raise ConfigError("invalid gap policy value", column="gap_policy.factor",
                              expected="a number > 1", found=repr(self.factor))


#: share of the sample intervals that must reach an interval length for it to count as the
#: clock's own jitter (recurring), not as a gap (find_gaps)
JITTER_SHARE = 0.01
#: fewest intervals from which the jitter envelope is measured (shorter tables: the nominal)
JITTER_MIN_INTERVALS = 100


def jitter_envelope(d: np.ndarray, nominal_dt: float) -> float:
    """Longest sample interval that recurs in the data: the ``1 - JITTER_SHARE`` quantile of the
    intervals shorter than two nominal intervals (a lost sample makes an interval of about two),
    or ``nominal_dt`` for a table with fewer than :data:`JITTER_MIN_INTERVALS` intervals.

    A logger that stamps samples with a millisecond counter read in a loop shows intervals of
    6, 7, 8 and 9 ms around a 6.6 ms mean (the rtklibexplorer walk: 816 intervals of 9 ms = 1.5
    median intervals); that is the clock's jitter, and no sample is missing.
    """
    d = np.asarray(d, float)
    bulk = d[(d > 0) & (d < 2.0 * nominal_dt)]
    if bulk.size < JITTER_MIN_INTERVALS:
        return float(nominal_dt)
    return max(float(np.quantile(bulk, 1.0 - JITTER_SHARE)), float(nominal_dt))


def gap_threshold(d: np.ndarray, nominal_dt: float, factor: float = 1.5) -> float:
    """Shortest interval [s] that is a gap: longer than ``factor`` nominal intervals and longer
    than the clock's recurring jitter (:func:`jitter_envelope`) by ``(factor - 1) / 2`` nominal
    intervals. For a clock without jitter this is ``factor * nominal_dt``."""
    env = jitter_envelope(d, nominal_dt)
    return max(factor * nominal_dt, env + 0.5 * (factor - 1.0) * nominal_dt)


def find_gaps(t: np.ndarray, line_no: np.ndarray, nominal_dt: float, factor: float = 1.5
              ) -> list[dict]:
    """Intervals longer than :func:`gap_threshold` (``factor * nominal_dt``, or more for a
    clock with recurring jitter: time-stamp jitter is not a gap).

    Returns ``[{"row", "start", "end", "duration", "missing"}]`` where ``row`` is the line of the
    sample that ends the gap and ``missing`` the estimated number of lost samples (from the
    mean interval of the samples that are not gaps).
    """
    t = np.asarray(t, float)
    d = np.diff(t)
    thr = gap_threshold(d, nominal_dt, factor)
    gap = d > thr
    idx = np.flatnonzero(gap)
    mean_dt = float(np.mean(d[~gap])) if np.any(~gap) else float(nominal_dt)
    return [{"row": int(line_no[k + 1]), "start": float(t[k]), "end": float(t[k + 1]),
             "duration": float(d[k]), "missing": int(max(round(d[k] / mean_dt) - 1, 1))}
            for k in idx]


def apply_gap_policy(gaps: list[dict], policy: GapPolicy, file, t0: float, t1: float, *,
                     column: str = "time") -> tuple[list[dict], list[tuple[float, float]]]:
    """Apply ``policy`` to the gaps found by :func:`find_gaps`.

    Returns the gap records (with ``action``) and the contiguous segments ``[(start, end)]``
    (one segment unless long gaps split the data). Raises DataGapError for a long gap under
    ``long="error"``; warns once for the bridged gaps.
    """
    records = []
    segments = []
    seg_start = t0
    for g in gaps:
        g = dict(g)
        if g["duration"] <= policy.max_bridge or policy.long == "bridge":
            g["action"] = "bridged"
        elif policy.long == "error":
            raise DataGapError(
                "data gap longer than the gap policy bridges", file=file, row=g["row"],
                column=column, expected=f"gaps <= {policy.max_bridge:g} s (gap_policy.max_bridge)",
                found=f"{g['duration']:.6g} s from {g['start']!r} to {g['end']!r}")
        else:
            g["action"] = "split"
            segments.append((seg_start, g["start"]))
            seg_start = g["end"]
        records.append(g)
    segments.append((seg_start, t1))
    bridged = [g for g in records if g["action"] == "bridged"]
    if bridged:
        worst = max(bridged, key=lambda g: g["duration"])
        warn(f"{len(bridged)} gap(s) bridged (longest {worst['duration']:.6g} s, "
             f"about {sum(g['missing'] for g in bridged)} sample(s) missing)", file=file,
             row=bridged[0]["row"], column=column)
    split = [g for g in records if g["action"] == "split"]
    if split:
        warn(f"data split into {len(segments)} segments at {len(split)} long gap(s)", file=file,
             row=split[0]["row"], column=column)
    return records, segments


def split_segments(df: pd.DataFrame) -> list[pd.DataFrame]:
    """The contiguous parts of a table read with ``GapPolicy(long="split")``."""
    if not len(df):
        return []
    segs = df.attrs.get("segments") or [(df.index[0], df.index[-1])]
    t = np.asarray(df.index, float)
    return [df.iloc[np.searchsorted(t, a, "left"):np.searchsorted(t, b, "right")] for a, b in segs]


def check_span(t: np.ndarray, line_no: np.ndarray, file, t0: float, t1: float, *,
               column: str = "time", policy: str = "trim", tolerance: float = 0.0,
               what: str = "IMU") -> tuple[np.ndarray, list[dict]]:
    """Epochs must lie inside ``[t0 - tolerance, t1 + tolerance]``.

    ``policy="trim"``: epochs outside are dropped with a warning (returned mask and records);
    an error only if no epoch is inside. ``policy="error"``: any epoch outside is an error.
    Raises TimeOrderError at the first epoch outside.
    """
    if policy not in ("trim", "error"):
        raise ConfigError("unknown span policy", column="span_policy",
                          expected="'trim' or 'error'", found=repr(policy))
    t = np.asarray(t, float)
    t0, t1 = float(t0), float(t1)
    outside = (t < t0 - tolerance) | (t > t1 + tolerance)
    if not outside.any():
        return np.ones(t.size, bool), []
    k = int(np.flatnonzero(outside)[0])
    if policy == "error" or outside.all():
        msg = f"epoch outside the {what} time span"
        if outside.all():
            msg = f"no epoch inside the {what} time span (different time bases?)"
        raise TimeOrderError(msg, file=file, row=int(line_no[k]), column=column,
                             expected=f"{t0!r} <= time <= {t1!r}", found=repr(float(t[k])))
    records = [{"row": int(line_no[i]), "time": float(t[i])} for i in np.flatnonzero(outside)]
    warn(f"{len(records)} epoch(s) outside the {what} time span dropped", file=file,
         row=records[0]["row"], column=column, expected=f"{t0!r} <= time <= {t1!r}",
         found=repr(records[0]["time"]))
    return ~outside, records


def source_rows(df: pd.DataFrame) -> np.ndarray | None:
    """Editor line numbers of the rows of a table as read (None if the table was reshaped)."""
    rows = df.attrs.get("source_rows")
    if rows is None or len(rows) != len(df):
        return None
    return np.asarray(rows)


def time_slice(table, start: float | None = None, stop: float | None = None):
    """Rows of a time-indexed table (strictly increasing index, as every reader returns) with
    ``start <= time <= stop`` (either bound open when None): ``table.loc[start:stop]``
    without pandas' label look-up, which builds a hash table of the whole index on first use
    (22 bytes per row; pandas does so below a million rows) and keeps it as long as the index
    lives."""
    t = table.index.to_numpy()
    i = 0 if start is None else int(np.searchsorted(t, start, side="left"))
    j = t.size if stop is None else int(np.searchsorted(t, stop, side="right"))
    return table.iloc[i:j]


def check_time_overlap(imu: pd.DataFrame, other: pd.DataFrame, what: str = "GNSS") -> None:
    """IMU and another input must overlap in time.

    Raises TimeOrderError naming both files and printing both spans when they do not (a file
    a day late, different time bases, a wrong time offset), so that no later step reports a
    symptom (no turning motion, no epoch to initialize from) instead of the cause.
    """
    ti, to = np.asarray(imu.index, float), np.asarray(other.index, float)
    if not ti.size or not to.size:
        return
    a0, a1, b0, b1 = float(ti[0]), float(ti[-1]), float(to[0]), float(to[-1])
    if b1 >= a0 and b0 <= a1:
        return
    src_i = imu.attrs.get("source", "IMU table")
    src_o = other.attrs.get("source", f"{what} table")
    apart = b0 - a1 if b0 > a1 else a0 - b1
    rows = source_rows(other)
    raise TimeOrderError(
        f"no overlap in time between the IMU and the {what} data: IMU from {a0!r} to {a1!r} s "
        f"({src_i}), {what} from {b0!r} to {b1!r} s ({src_o}), {apart:.6g} s apart "
        "(different time bases, a wrong date or a missing time offset?)", file=src_o,
        row=None if rows is None else int(rows[0]), column=other.attrs.get("time_column", "time"),
        expected=f"{what} epochs inside the IMU span {a0!r} to {a1!r} s",
        found=f"{b0!r} to {b1!r} s")


def check_time_bases(tables: dict[str, pd.DataFrame | None], declared: str = "unspecified", *,
                     file=None) -> None:
    """Every input's time base (``attrs["time_base"]``, set by its reader) must be the job's
    ``declared`` one, and two inputs must not be in different bases; ``"unspecified"`` (a
    native CSV, or a job that declares none) matches anything. Raises ConfigError naming
    ``job.time_base``, the inputs and their bases."""
    seen: list[tuple[str, str, str]] = []
    for name, df in tables.items():
        if df is None:
            continue
        base = df.attrs.get("time_base") or "unspecified"
        if base == "unspecified":
            continue
        src = str(df.attrs.get("source", name))
        if declared != "unspecified" and base != declared:
            raise ConfigError(f"the {name} time stamps are in another time base than the job "
                              "declares", file=file, column="job.time_base",
                              expected=repr(declared), found=f"{base!r} ({src})")
        for other, b, s in seen:
            if b != base:
                raise ConfigError(f"inputs in different time bases: the {other} ({s}) in {b!r}, "
                                  f"the {name} ({src}) in {base!r}", file=file,
                                  column="job.time_base", expected="one time base",
                                  found=f"{b!r} and {base!r}")
        seen.append((name, base, src))


def check_gnss_in_imu_span(gnss: pd.DataFrame, imu: pd.DataFrame, *, policy: str = "trim",
                           tolerance: float = 0.0) -> pd.DataFrame:
    """GNSS epochs outside the IMU time span: trimmed with a warning, or an error.

    The error and the warning name the GNSS file and line (``attrs["source"]``,
    ``attrs["source_rows"]``). The trimmed table records the dropped epochs in
    ``attrs["outside_imu_span"]``.
    """
    tg = np.asarray(gnss.index, float)
    ti = np.asarray(imu.index, float)
    require_rows(ti.size, 1, imu.attrs.get("source"), what="IMU samples")
    check_time_overlap(imu, gnss)
    rows = source_rows(gnss)
    if rows is None:
        rows = np.arange(tg.size) + 1
    keep, records = check_span(tg, rows, gnss.attrs.get("source"), float(ti[0]), float(ti[-1]),
                               column=gnss.attrs.get("time_column", "time"), policy=policy,
                               tolerance=tolerance)
    if not records:
        return gnss
    out = gnss.loc[keep].copy()
    out.attrs = dict(gnss.attrs)
    if "source_rows" in out.attrs and rows is not None:
        out.attrs["source_rows"] = rows[keep]
    out.attrs["outside_imu_span"] = records
    return out


# --------------------------------------------------------------------------------------------
# IMU unit plausibility
# --------------------------------------------------------------------------------------------

#: still-sample detector of the gyro unit check
STILL_WINDOW = 11
STILL_STD = 0.2  # [m/s^2]
STILL_MIN_SAMPLES = 20
MAX_STILL_GYRO = 0.5  # [rad/s]
MAX_GYRO = 100.0  # [rad/s]


def _rolling_std(x: np.ndarray, w: int) -> np.ndarray:
    """Centred rolling standard deviation (NaN near the ends), vectorised."""
    n = x.size
    out = np.full(n, np.nan)
    if n < w:
        return out
    x = x - np.median(x)
    c1 = np.concatenate([[0.0], np.cumsum(x)])
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    m = (c1[w:] - c1[:-w]) / w
    v = np.maximum((c2[w:] - c2[:-w]) / w - m * m, 0.0)
    out[w // 2: w // 2 + v.size] = np.sqrt(v)
    return out


def check_imu_units(gyro: np.ndarray, accel: np.ndarray, line_no: np.ndarray, file, *,
                    gyro_names: Sequence[str], accel_names: Sequence[str], gyro_unit: str,
                    accel_unit: str) -> None:
    """Reject magnitudes that do not fit the declared units (see the module docstring).

    ``gyro`` [rad/s] and ``accel`` [m/s^2] are rates after the declared unit conversion (for
    increment data: increments divided by the sample interval), in the sensor axes so that the
    columns match the file's.
    """
    fn = np.linalg.norm(accel, axis=1)
    med = float(np.median(fn))
    lo, hi = 0.5 * G0, 2.0 * G0
    if not lo <= med <= hi:
        if lo <= med * G0 <= hi:
            hint = "; the values look like g"
        elif lo <= med / G0 <= hi:
            hint = "; the values look like m/s^2 declared as g"
        elif med < lo:
            hint = "; the values look like increments or a smaller unit"
        else:
            hint = ""
        bad = np.flatnonzero((fn < lo) | (fn > hi))
        i = int(bad[0]) if bad.size else 0
        j = int(np.argmax(np.abs(accel[i])))
        raise UnitError(f"accelerometer magnitude implausible for the declared unit "
                        f"{accel_unit!r}{hint}", file=file, row=int(line_no[i]),
                        column=accel_names[j],
                        expected="a median specific force of 0.5-2 g (4.9-19.6 m/s^2)",
                        found=f"{med:.4g} m/s^2 after conversion from {accel_unit!r}")
    wn = np.linalg.norm(gyro, axis=1)
    hint = "; the values look like deg/s declared as rad/s" if gyro_unit == "rad/s" else ""
    over = np.flatnonzero(np.abs(gyro).max(axis=1) > MAX_GYRO)
    if over.size:
        i = int(over[0])
        j = int(np.argmax(np.abs(gyro[i])))
        raise UnitError(f"angular rate implausible for the declared unit {gyro_unit!r}{hint}",
                        file=file, row=int(line_no[i]), column=gyro_names[j],
                        expected=f"|rate| <= {MAX_GYRO:g} rad/s",
                        found=f"{gyro[i, j]:.4g} rad/s after conversion from {gyro_unit!r}")
    still = (_rolling_std(fn, STILL_WINDOW) < STILL_STD) & (np.abs(fn - G0) < 0.1 * G0)
    if still.sum() >= STILL_MIN_SAMPLES:
        med_w = float(np.median(wn[still]))
        if med_w > MAX_STILL_GYRO:
            i = int(np.flatnonzero(still & (wn > MAX_STILL_GYRO))[0])
            j = int(np.argmax(np.abs(gyro[i])))
            raise UnitError(
                f"angular rates too large while the accelerometers are still{hint}", file=file,
                row=int(line_no[i]), column=gyro_names[j],
                expected=f"a median |rate| below {MAX_STILL_GYRO:g} rad/s "
                         f"({np.degrees(MAX_STILL_GYRO):.1f} deg/s) on still samples",
                found=f"{med_w:.4g} rad/s after conversion from {gyro_unit!r}")


# --------------------------------------------------------------------------------------------
# outputs
# --------------------------------------------------------------------------------------------


def input_clash(path: str | os.PathLike, inputs: Iterable[str | os.PathLike | None]
                ) -> Path | None:
    """The input that ``path`` is, if any: the same resolved path (symlinks and ``..``
    followed) or the same file under another name (hard link: same device and inode)."""
    p = Path(path)
    rp = p.resolve()
    for q in inputs:
        if q is None:
            continue
        q = Path(q)
        if rp == q.resolve():
            return q
        try:
            if os.path.samefile(p, q):
                return q
        except OSError:  # one of them does not exist
            continue
    return None


def ensure_not_input(path: str | os.PathLike, inputs: Iterable[str | os.PathLike | None]) -> Path:
    """Refuse to write ``path`` if it is one of ``inputs`` (:func:`input_clash`).

    Returns ``Path(path)``. Raises ConfigError naming the clashing input.
    """
    p = Path(path)
    q = input_clash(p, inputs)
    if q is not None:
        raise ConfigError("refusing to overwrite an input file", file=p,
                          expected="an output path that is not an input",
                          found=f"the input {str(q)!r}")
    return p


class SourceRows(np.ndarray):
    """The file line of each row of a table read from a file (``attrs["source_rows"]``):
    a read-only int64 array that pandas' copies of the attrs share instead of copying (every
    slice, selection or arithmetic result of a DataFrame deep-copies its attrs: for a long log
    that was one array of 8 bytes per row per derived table). Indexing gives new arrays."""

    def __deepcopy__(self, memo):
        return self

    def __copy__(self):
        return self


def source_row_numbers(line_no) -> SourceRows:
    """``line_no`` as a shared, read-only :class:`SourceRows`: int32 (a file of fewer than
    2^31 lines, 4 bytes per row: 29 MB less for each 7.2 M-row table of a 10 h log at 200 Hz),
    int64 beyond."""
    line_no = np.asarray(line_no)
    small = line_no.size == 0 or (int(line_no.max()) < 2**31 and int(line_no.min()) >= 0)
    rows = np.array(line_no, np.int32 if small else np.int64).view(SourceRows)
    rows.flags.writeable = False
    return rows


def finish_attrs(df: pd.DataFrame, *, file, fmt: str, time_base: str, line_no: np.ndarray,
                 time_column: str = "time", **extra) -> pd.DataFrame:
    """Set the attrs every reader provides: source, format, time base, line numbers, records."""
    df.attrs.update({"source": str(file), "format": fmt, "time_base": time_base,
                     "time_column": time_column, "source_rows": source_row_numbers(line_no)})
    df.attrs.update(extra)
    return df
