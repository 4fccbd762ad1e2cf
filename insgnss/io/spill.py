"""Arrays in memory up to a limit, memory-mapped files beyond it.

The filter engine's node store (:class:`insgnss.filter.store.NodeStore`: per filter epoch the
covariances, the transition and the update rows the smoother needs) grows with the length of
the log. :class:`SpillAllocator` is the allocation function it is given: an array is made in
memory while the arrays it made and that are still alive take at most ``limit`` bytes, and
as a memory-mapped file in ``folder`` beyond that (``numpy.memmap``; the operating system
pages it in and out). The numbers are the same either way (float64 in both).

The file of a mapped array is removed right after it is mapped where the system allows it
(POSIX: the mapping stays valid and its disk space is freed with the array); elsewhere it is
removed when the array is released.

Resident pages
--------------
A mapped page that was written or read stays in the process's resident memory until the
mapping goes, however long ago it was used. :func:`release` gives back the pages of a range
of rows of a mapped array (``madvise(MADV_DONTNEED)`` on the shared file mapping: the
contents stay in the file and the system's page cache, and a later access reads them back);
on an array in memory it does nothing. Code that walks a long mapped array in blocks
(:func:`blocks`) releases each block after use, so the resident part stays at about one block
whatever the length of the log. The numbers are not affected.
"""

from __future__ import annotations

import math
import mmap
import os
import tempfile
import weakref
from pathlib import Path

import numpy as np

__all__ = ["BLOCK_BYTES", "SPILL_PREFIX", "SpillAllocator", "blocks", "is_mapped", "release",
           "release_frame", "trim_heap"]

#: prefix of the mapped files (hidden; removed at once on POSIX)
SPILL_PREFIX = ".insgnss-store-"

#: bytes per block of :func:`blocks` (a few MiB: large enough for vectorised work, small
#: against the arrays of a long log)
BLOCK_BYTES = 8 << 20


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


class SpillAllocator:
    """``allocate(shape, dtype)``: a new (uninitialized) array, in memory up to ``limit``
    bytes of live arrays, else memory-mapped in ``folder`` (the system's temporary folder
    when None or not an existing folder: nothing is created). ``spilled`` counts the bytes
    mapped so far, ``in_memory`` the bytes in memory now."""

    def __init__(self, limit: float, folder: str | os.PathLike | None = None):
        self.limit = float(limit)
        self.folder = Path(folder) if folder is not None else Path(tempfile.gettempdir())
        self.in_memory = 0
        self.spilled = 0

    def _release(self, nbytes: int) -> None:
        self.in_memory -= nbytes

    def __call__(self, shape, dtype=float) -> np.ndarray:
        shape = tuple(int(s) for s in np.atleast_1d(shape))
        dtype = np.dtype(dtype)
        nbytes = math.prod(shape) * dtype.itemsize
        if nbytes == 0 or self.in_memory + nbytes <= self.limit:
            a = np.empty(shape, dtype)
            self.in_memory += nbytes
            weakref.finalize(a, self._release, nbytes)
            return a
        folder = self.folder if self.folder.is_dir() else Path(tempfile.gettempdir())
        fd, path = tempfile.mkstemp(prefix=SPILL_PREFIX, suffix=".bin", dir=folder)
        try:
            mm = np.memmap(path, dtype=dtype, mode="w+", shape=shape)
        finally:
            os.close(fd)
        try:
            os.unlink(path)  # POSIX: the mapping stays; the space goes with the array
        except OSError:
            weakref.finalize(mm, _remove, path)
        self.spilled += nbytes
        return mm.view(np.ndarray)  # a plain array on the mapping (compiled code takes it)


def _mapping(a: np.ndarray) -> mmap.mmap | None:
    """The ``mmap`` an array's memory belongs to (None for an array in memory)."""
    x = a
    while x is not None:
        if isinstance(x, mmap.mmap):
            return x
        x = getattr(x, "base", None)
    return None


def is_mapped(a: np.ndarray) -> bool:
    """True for an array (or a view of one) on a memory-mapped file of :class:`SpillAllocator`."""
    return _mapping(a) is not None


def release(a: np.ndarray, start: int = 0, stop: int | None = None) -> None:
    """Give back the resident pages of rows ``start .. stop-1`` of a mapped array (module
    docstring, "Resident pages"); nothing for an array in memory or where the system has no
    ``madvise``. The pages the rows touch are released (a neighbouring row sharing a page is
    read back when next used); the contents are kept."""
    mm = _mapping(a)
    advice = getattr(mmap, "MADV_DONTNEED", None)
    if mm is None or advice is None or a.ndim == 0 or not len(a):
        return
    stop = len(a) if stop is None else min(int(stop), len(a))
    start = max(int(start), 0)
    if stop <= start:
        return
    base = np.frombuffer(mm, np.uint8).ctypes.data
    first = a.ctypes.data - base  # byte offset of a[0] in the mapping
    extent = a.itemsize + sum((m - 1) * st for m, st in zip(a.shape[1:], a.strides[1:],
                                                              strict=True))
    lo = first + start * a.strides[0]
    hi = first + (stop - 1) * a.strides[0] + extent
    page = mmap.PAGESIZE
    lo = lo // page * page
    hi = min(-(-hi // page) * page, len(mm))
    if hi > lo:
        try:
            mm.madvise(advice, lo, hi - lo)
        except (OSError, ValueError):
            pass


def release_frame(df, start: int = 0, stop: int | None = None) -> None:
    """:func:`release` rows ``start .. stop-1`` of every column of a DataFrame whose columns
    lie on a mapped file (a reader's table made by a :class:`SpillAllocator`); nothing for
    the columns in memory."""
    for c in range(df.shape[1] if len(df) else 0):
        release(df.iloc[:, c].to_numpy(), start, stop)


def blocks(n: int, row_bytes: int, block_bytes: int | None = None, start: int = 0,
           stop: int | None = None):
    """Row ranges ``(i, j)`` covering ``0 .. n-1`` in blocks of about ``block_bytes`` bytes
    (default :data:`BLOCK_BYTES`) of rows of ``row_bytes`` bytes each; only the blocks that
    hold a row of ``start .. stop-1`` (default: all), with the same bounds as all of them."""
    n, start = int(n), max(int(start), 0)
    stop = n if stop is None else min(int(stop), n)
    step = max(1, int(block_bytes or BLOCK_BYTES) // max(int(row_bytes), 1))
    for i in range(start // step * step, stop if stop > start else 0, step):
        yield i, min(i + step, n)


def trim_heap() -> None:
    """Give the C heap's free memory back to the system (glibc ``malloc_trim``; nothing where
    the C library has none), and the free memory pyarrow's own allocator keeps (its default
    pool, mimalloc or jemalloc, where the CSV writer's buffers go: 11 MB after writing the
    1 h / 200 Hz trajectories). After a stage that freed large temporaries (a reader's parse
    buffers, the evaluation's, a writer's), the freed memory would otherwise stay in the
    process."""
    import ctypes
    import sys

    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (AttributeError, OSError):
        pass
    pa = sys.modules.get("pyarrow")  # not imported for this: only a pool that was used
    if pa is not None:
        try:
            pa.default_memory_pool().release_unused()
        except (AttributeError, NotImplementedError, OSError):
            pass
