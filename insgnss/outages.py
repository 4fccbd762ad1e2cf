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


def periodic_windows(t_first: float, t_last: float, start: float, length: float, gap: float,
                     stop_before_end: float = 0.0) -> list[tuple[float, float]]:
    """Periodic outage windows ``[(S_k, E_k), ...]`` (see module docstring)."""
    if length <= 0 or gap < 0:
        raise ValueError(f"outage length must be > 0 and gap >= 0; got {length}, {gap}")
    t0, t1 = int(_us(t_first)), int(_us(t_last))
    s, L, period = int(_us(start)), int(_us(length)), int(_us(length + gap))
    stop = t1 - int(_us(stop_before_end))
    out = []
    S = t0 + s
    while S < stop:
        out.append((S / 1e6, min(S + L, stop) / 1e6))
        S += period
    return out


def in_windows(t, windows) -> np.ndarray:
    """Boolean mask: ``t`` inside any half-open window."""
    t_us = _us(t)
    mask = np.zeros(t_us.shape, bool)
    for a, b in windows:
        mask |= (t_us >= int(_us(a))) & (t_us < int(_us(b)))
    return mask


def window_index(t, windows) -> np.ndarray:
    """Index of the window containing each time, -1 outside all windows."""
    t_us = _us(t)
    idx = np.full(t_us.shape, -1, dtype=int)
    for k, (a, b) in enumerate(windows):
        idx[(t_us >= int(_us(a))) & (t_us < int(_us(b)))] = k
    return idx
