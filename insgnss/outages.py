"""GNSS outage schedules: explicit windows or periodic (start, length, gap, stop before end).

Windows are half-open ``[start, end)`` in the job's time base. The periodic rule is the data
author's rule used by the drive benchmark (shared/eval/README.md): the first outage starts
``start`` seconds after the first GNSS epoch, lasts ``length``, is followed by ``gap`` seconds of
GNSS; outages start strictly before ``stop = last epoch - stop_before_end`` and are cut at
``stop``. The arithmetic is done in integer microseconds so that epoch times
that sit exactly on a boundary are classified without rounding surprises.
"""

from __future__ import annotations

import numpy as np


def _us(x) -> np.ndarray:
    return np.round(np.asarray(x, dtype=float) * 1e6).astype(np.int64)


#: most windows :func:`periodic_windows` builds (a schedule beyond this is a unit mistake, and
#: the list alone would take gigabytes)
MAX_WINDOWS = 10_000_000


def periodic_windows(t_first: float, t_last: float, start: float, length: float, gap: float,
                     stop_before_end: float = 0.0) -> list[tuple[float, float]]:
    """Periodic outage windows ``[(S_k, E_k), ...]`` (see module docstring).

    Raises ValueError unless ``length`` and ``gap`` are finite and at least one microsecond
    (the resolution of the arithmetic: a shorter period would never advance) and the schedule
    has at most :data:`MAX_WINDOWS` windows.
    """
    values = (t_first, t_last, start, length, gap, stop_before_end)
    if not all(np.isfinite(float(v)) for v in values):
        raise ValueError(f"outage schedule values must be finite; got {values}")
    t0, t1 = int(_us(t_first)), int(_us(t_last))
    s, L, G = int(_us(start)), int(_us(length)), int(_us(gap))
    if L < 1 or G < 1:
        raise ValueError(f"outage length and gap must be at least 1 microsecond; got "
                         f"{length!r} s and {gap!r} s")
    period = L + G
    stop = t1 - int(_us(stop_before_end))
    first = t0 + s
    n = max(0, -(-(stop - first) // period))  # starts S_k = first + k period < stop
    if n > MAX_WINDOWS:
        raise ValueError(f"{n} outage windows (length {length!r} s, gap {gap!r} s over "
                         f"{(t1 - t0) / 1e6:g} s); at most {MAX_WINDOWS}")
    S = first + period * np.arange(n, dtype=np.int64)
    E = np.minimum(S + L, stop)
    return list(zip((S / 1e6).tolist(), (E / 1e6).tolist(), strict=True))


def _disjoint(windows) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Starts, ends [us] and list order of the windows sorted by start, if none overlap."""
    a = _us([w[0] for w in windows]).reshape(-1)
    b = _us([w[1] for w in windows]).reshape(-1)
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    if np.any(a[1:] < b[:-1]):
        return None
    return a, b, order


#: times per block of :func:`window_index` (its temporaries stay small on a long log)
_BLOCK = 1 << 16


def _disjoint_blocks(t: np.ndarray, d):
    """Per block of :data:`_BLOCK` times of the flat ``t``: ``(i, k, inside)``, the block's
    first index, the position of the window starting last at or before each time in the sorted
    disjoint windows ``d`` (:func:`_disjoint`), and whether the time is inside it."""
    a, b, _ = d
    for i in range(0, t.size, _BLOCK):
        t_us = _us(t[i:i + _BLOCK])
        k = np.searchsorted(a, t_us, side="right") - 1
        yield i, k, (k >= 0) & (t_us < b[np.maximum(k, 0)])


def window_index(t, windows) -> np.ndarray:
    """Index of the window containing each time, -1 outside all windows (overlapping windows:
    the last one listed wins)."""
    t = np.asarray(t, dtype=float)
    if not len(windows):
        return np.full(t.shape, -1, dtype=int)
    d = _disjoint(windows)
    if d is not None:  # O((N + W) log W) for any number of windows, block by block
        idx = np.full(t.shape, -1, dtype=int)
        out = idx.reshape(-1)
        for i, k, inside in _disjoint_blocks(t.reshape(-1), d):
            out[i:i + _BLOCK][inside] = d[2][k[inside]]
        return idx
    t_us = _us(t)
    idx = np.full(t_us.shape, -1, dtype=int)
    for k, (a, b) in enumerate(windows):
        idx[(t_us >= int(_us(a))) & (t_us < int(_us(b)))] = k
    return idx


def in_windows(t, windows) -> np.ndarray:
    """Boolean mask: ``t`` inside any half-open window."""
    t = np.asarray(t, dtype=float)
    d = _disjoint(windows) if len(windows) else None
    if d is not None:  # block by block into the mask (no window index of the whole length)
        mask = np.empty(t.shape, bool)
        out = mask.reshape(-1)
        for i, _, inside in _disjoint_blocks(t.reshape(-1), d):
            out[i:i + inside.size] = inside
        return mask
    if len(windows):
        t_us = _us(t)
        mask = np.zeros(t_us.shape, bool)
        for a, b in windows:
            mask |= (t_us >= int(_us(a))) & (t_us < int(_us(b)))
        return mask
    return np.zeros(t.shape, bool)
