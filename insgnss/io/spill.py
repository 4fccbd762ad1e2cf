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
"""

from __future__ import annotations

import math
import os
import tempfile
import weakref
from pathlib import Path

import numpy as np

__all__ = ["SPILL_PREFIX", "SpillAllocator"]

#: prefix of the mapped files (hidden; removed at once on POSIX)
SPILL_PREFIX = ".insgnss-store-"


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
