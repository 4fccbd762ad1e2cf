"""Epoch schedule of the filter engine.

Filter *epochs* are the times of the measurements handled by the Python update path plus a grid
every ``epoch_interval`` seconds where those are further apart (so that the stored covariances
and the smoother have nodes during long outages; :func:`gap_grid`) and the first and last IMU
times. How a measurement time becomes an epoch depends on
the process model:

- ``split=True`` (strapdown): times closer than ``tol`` to an IMU sample are moved onto it, the
  others stay between samples (the mechanization splits that IMU interval); epochs closer than
  ``tol`` are merged;
- ``split=False`` (RISS, whose inputs are window averages at the samples): the epoch is the IMU
  sample at or before the measurement time (measurements more than two IMU intervals after the
  last sample at or before them are dropped), the grid is every ``round(epoch_interval / dt)``
  samples, and the measurement sees the nominal extrapolated to its own time.

High-rate measurements (the compiled path, :mod:`.highrate`) are events at the IMU sample
nearest their time; a segment between two epochs that contains one is run sample by sample in
compiled code (a *dense* segment: every IMU sample there is a smoother node).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..aot import entry
from ..jit import njit

__all__ = ["EPOCH_GRIDS", "Schedule", "build_schedule", "gap_grid", "snap"]

#: where the epoch grid is laid (:class:`insgnss.filter.engine.FilterConfig` ``epoch_grid``)
EPOCH_GRIDS = ("gaps", "always")


@dataclass
class Schedule:
    """Epochs and events.

    Attributes
    ----------
    epochs : (E,) array
        Epoch times.
    ev_m, ev_r, ev_t : (K,) arrays
        Measurement index, row in that measurement and time of each Python-path event, sorted
        by epoch (then measurement, then row).
    ptr : (E + 1,) array
        Events of epoch ``e`` are ``ptr[e] .. ptr[e+1]-1``.
    hr_ptr : (N + 1,) array
        High-rate events at IMU sample ``j`` are ``hr_ptr[j] .. hr_ptr[j+1]-1`` of
        ``hr_m`` (high-rate measurement index) and ``hr_r`` (its row).
    dense : (E,) bool array
        Segment ``(epochs[e-1], epochs[e]]`` holds high-rate events.
    dense_samples : int
        IMU samples inside dense segments (their nodes).
    """

    epochs: np.ndarray
    ev_m: np.ndarray
    ev_r: np.ndarray
    ev_t: np.ndarray
    ptr: np.ndarray
    hr_ptr: np.ndarray
    hr_m: np.ndarray
    hr_r: np.ndarray
    dense: np.ndarray
    dense_samples: int

    @property
    def n_epochs(self) -> int:
        return self.epochs.size


def snap(t, x, tol):
    """Move the times ``x`` onto the nearest of the increasing times ``t`` (an IMU sample, an
    epoch; a tie to the earlier) when closer than ``tol`` (inclusive); the others stay."""
    x = np.asarray(x, float)
    if t.size < 2:
        near = np.zeros(x.shape, np.int64)
    else:
        j = np.clip(np.searchsorted(t, x), 1, t.size - 1)
        near = np.where(np.abs(t[j] - x) < np.abs(t[j - 1] - x), j, j - 1)
    return np.where(np.abs(t[near] - x) <= tol, t[near], x)


def gap_grid(grid, times, interval: float, tol: float) -> np.ndarray:
    """Which times of the epoch grid ``grid`` (increasing, its first and last the first and
    last epoch) are needed: those inside a gap between the measurement epochs ``times``
    longer than ``interval`` (+ ``tol``), and the first and the last. Elsewhere the
    measurement epochs are nodes close enough, and a grid epoch would only split a covariance
    propagation (which sub-steps by itself) and add a smoother node."""
    keep = np.ones(grid.size, bool)
    if grid.size <= 2 or not np.size(times):
        return keep
    tm = np.unique(np.concatenate([np.asarray(times, float), grid[[0, -1]]]))
    k = np.clip(np.searchsorted(tm, grid, side="right"), 1, tm.size - 1)
    keep[1:-1] = (tm[k] - tm[k - 1])[1:-1] > interval + tol
    return keep


def _split_epochs(t, times, epoch_interval, tol, in_gaps=True):
    t0, t1 = t[0], t[-1]
    evs = []
    for k, tm in enumerate(times):
        rows = np.nonzero((tm >= t0 - tol) & (tm <= t1 + tol))[0]
        evs.append((np.full(rows.size, k), rows, snap(t, np.clip(tm[rows], t0, t1), tol)))
    n_grid = int(np.floor((t1 - t0) / epoch_interval + 1e-9))
    grid = snap(t, np.append(t0 + epoch_interval * np.arange(n_grid + 1), t1), tol)
    ev_m, ev_r, ev_t = _cat(evs)
    if in_gaps:
        grid = grid[gap_grid(grid, ev_t, epoch_interval, tol)]
    ep = np.unique(np.concatenate([grid, ev_t]))
    ep = ep[np.concatenate([[True], np.diff(ep) > tol])]  # merge epochs closer than tol
    ev_e = np.clip(np.searchsorted(ep, ev_t - tol), 0, ep.size - 1)
    return ep, ev_e, ev_m, ev_r, ep[ev_e]  # the event is at its (merged) epoch


def _sample_epochs(t, times, epoch_interval, in_gaps=True):
    dt = float(np.median(np.diff(t)))
    evs = []
    for k, tm in enumerate(times):
        idx = np.searchsorted(t, tm + 1e-9, side="right") - 1
        rows = np.nonzero((idx >= 1) & (tm - t[np.maximum(idx, 0)] < 2.0 * dt))[0]
        evs.append((np.full(rows.size, k), rows, tm[rows]))
    ev_m, ev_r, ev_t = _cat(evs)
    ev_j = np.searchsorted(t, ev_t + 1e-9, side="right") - 1
    step = max(int(round(epoch_interval / dt)), 1)
    grid = np.arange(0, t.size, step)
    if in_gaps:
        grid = grid[gap_grid(t[grid], t[ev_j], epoch_interval, 0.5 * dt)]
    idx = np.union1d(grid, ev_j)
    if idx[-1] != t.size - 1:
        idx = np.append(idx, t.size - 1)
    ev_e = np.searchsorted(idx, ev_j)
    return t[idx], ev_e, ev_m, ev_r, ev_t


def _cat(evs):
    if not evs:
        return np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
    return (np.concatenate([e[0] for e in evs]).astype(np.int64),
            np.concatenate([e[1] for e in evs]).astype(np.int64),
            np.concatenate([e[2] for e in evs]).astype(float))


def build_schedule(t: np.ndarray, times: list, epoch_interval: float, tol: float,
                   split: bool = True, high_rate_times: list | None = None,
                   grid_in_gaps: bool = True) -> Schedule:
    """Epoch schedule for IMU times ``t``, the epoch times of the Python-path measurements
    (``times``, one array per measurement) and of the high-rate ones (module docstring);
    ``grid_in_gaps=False`` keeps every time of the epoch grid (:func:`gap_grid`)."""
    times = [np.asarray(x, float) for x in times]
    if split:
        ep, ev_e, ev_m, ev_r, ev_t = _split_epochs(t, times, epoch_interval, tol, grid_in_gaps)
    else:
        ep, ev_e, ev_m, ev_r, ev_t = _sample_epochs(t, times, epoch_interval, grid_in_gaps)
    order = np.lexsort((ev_r, ev_m, ev_e))
    ev_e, ev_m, ev_r, ev_t = ev_e[order], ev_m[order], ev_r[order], ev_t[order]
    ptr = np.searchsorted(ev_e, np.arange(ep.size + 1))
    hr_ptr, hm_a, hr_a, dense, n_dense = _high_rate_events(
        t, ep, [np.asarray(tm, float) for tm in high_rate_times or []], tol)
    return Schedule(ep, ev_m, ev_r, ev_t, ptr, hr_ptr, hm_a, hr_a, dense, n_dense)


def _high_rate_events(t, ep, times: list, tol: float):
    """High-rate events at the IMU sample nearest their time (row 0 is the initial state: never
    an event), ordered by (sample, measurement, row): ``hr_ptr, hr_m, hr_r``, the dense flags of
    the epoch segments and the number of IMU samples inside dense segments."""
    k = len(times)
    sizes = np.array([x.size for x in times], np.int64)
    ptr = np.zeros(k + 1, np.int64)
    np.cumsum(sizes, out=ptr[1:])
    allt = np.concatenate(times) if k else np.empty(0)
    return _hr_events_kernel(t, ep, allt, ptr, tol)


@entry
@njit(cache=True)
def _hr_events_kernel(t, ep, allt, ptr, tol):
    """Compiled core of :func:`_high_rate_events` (``allt``: the times of every high-rate
    measurement, measurement ``k`` at ``ptr[k]:ptr[k+1]``): the nearest sample of each event
    (ties to the later one), a stable counting sort by sample (events of one sample keep the
    measurement, then row, order), and the segments of ``ep`` that hold an event."""
    n = t.shape[0]
    ne = allt.shape[0]
    jev = np.full(ne, -1, np.int64)
    count = np.zeros(n + 1, np.int64)
    j = 0  # np.searchsorted(t, x) (left), by a forward scan while the times increase
    x_prev = np.inf
    for e in range(ne):
        x = allt[e]
        if not (x > t[0] - tol and x <= t[-1] + tol):
            continue
        if x < x_prev:
            j = np.searchsorted(t, x)
        else:
            while j < n and t[j] < x:
                j += 1
        x_prev = x
        j = min(max(j, 1), n - 1)
        if abs(t[j] - x) > abs(t[j - 1] - x):
            j -= 1
        if j >= 1:
            jev[e] = j
            count[j + 1] += 1
    hr_ptr = np.cumsum(count)
    fill = hr_ptr[:-1].copy()
    total = hr_ptr[n]
    hm = np.empty(total, np.int64)
    hr = np.empty(total, np.int64)
    for m in range(ptr.shape[0] - 1):
        for e in range(ptr[m], ptr[m + 1]):
            j = jev[e]
            if j >= 0:
                q = fill[j]
                hm[q] = m
                hr[q] = e - ptr[m]
                fill[j] = q + 1
    # the events of one sample in (measurement, row) order: already, as the rows of each
    # measurement are visited in increasing order and the measurements in order
    n_ep = ep.shape[0]
    dense = np.zeros(n_ep, np.bool_)
    # segment e holds samples with ep[e-1] < t_j <= ep[e]
    s = 0  # np.searchsorted(ep, t[j]) (left), advanced with j
    for j in range(1, n):
        while s < n_ep and ep[s] < t[j]:
            s += 1
        if hr_ptr[j + 1] > hr_ptr[j] and s >= 1 and s < n_ep:
            dense[s] = True
    n_dense = 0
    for e in range(1, n_ep):
        if dense[e]:
            lo = np.searchsorted(t, ep[e - 1], side="right")
            hi = np.searchsorted(t, ep[e], side="right")
            n_dense += hi - lo
    return hr_ptr, hm, hr, dense, n_dense
