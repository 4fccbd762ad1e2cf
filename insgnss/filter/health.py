"""Health checks of the filter engine: non-finite state, covariance not positive definite,
runaway normalized innovations (one implementation for the Python and compiled update paths).

Runaway NIS: for one measurement type, the median normalized innovation ``NIS / dof`` (before
gating, so rejected measurements count) over the last ``window`` seconds must not exceed
``bound`` once the window holds measurements at ``min_count`` distinct epochs (times): a type
with one row per satellite (a pseudorange) gives ten rows at one epoch, which say as much about
a diverged filter as one position fix, so the count is of epochs, not rows. A consistent filter has a
median ``NIS / dof`` below 1 (about 0.45-0.8 for 1-3 dof); a median beyond 25 means the
measurements sit 5 sigma away most of the time: the filter diverged or its noise model is badly
wrong, and its solution should not be trusted silently. The median is evaluated at most once per
second per type.

After a gate recovery (:mod:`.gating`: the covariance was inflated, the state re-anchored) the
windows of all types restart empty (:func:`runaway_restart`): the NIS values before it describe
the state that was abandoned, so a run that recovered is stopped only if the median stays above
``bound`` over at least ``min_count`` epochs *after* the recovery.

Only measurements that judge the filter are watched: when a run has absolute measurements
(:attr:`~insgnss.filter.measurements.Measurement.recoverable`, e.g. GNSS), the constraints
(NHC, a vehicle's ZUPT, odometer) are not - their persistent rejection while the GNSS is accepted
means the constraint is violated (a skidding turn, a lever arm left out), which the gate and the
rejection counts of the summary report, not a diverged filter. Without absolute measurements
every type is watched. (An unwatched type keeps ``+inf`` as the time of its last check.)

The Python wrappers raise :class:`insgnss.errors.FilterHealthError`; the engine catches it and
returns what was computed up to the last good epoch.

What preceded it (:func:`imu_outlier_note`): a divergence is often set off by one bad IMU
sample (a 5000 deg/s gyro spike integrates to a 50 deg attitude jump at 100 Hz). The message
then names the largest angular rate and the largest specific force in the ``window`` seconds
before the failure when it exceeds :data:`OUTLIER_FACTOR` times the recording's robust level
(its 99.9th percentile of ``|omega|`` or ``|f|``: a single sample does not move it), with its
time and value, and points at ``inputs.imu.spike_policy``.
"""

from __future__ import annotations

import numpy as np

from ..aot import entry
from ..errors import FilterHealthError
from ..jit import njit
from .linalg import cholesky_into

__all__ = ["check_covariance", "covariance_fault", "finite_navigation", "RunawayNis",
           "imu_outlier_note", "with_imu_note"]

#: an IMU sample this many times the recording's 99.9th percentile is named as an outlier
OUTLIER_FACTOR = 5.0


@entry
@njit(cache=True)
def covariance_fault(x, P, full):
    """0 if every element of ``x`` and ``P`` is finite and (``full``) ``P`` has a Cholesky
    factorisation; 1 if one is not finite; 2 if ``P`` is not positive definite. One compiled
    call per check (the numpy form, two sums, a test and the Cholesky, cost about 5 us of
    Python overhead at each of an epoch's two checks)."""
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return 1
    n = P.shape[0]
    for i in range(n):
        for k in range(P.shape[1]):
            if not np.isfinite(P[i, k]):
                return 1
    if full and not cholesky_into(P, np.empty((n, n)), n):
        return 2
    return 0


@entry
@njit(cache=True)
def finite_navigation(pos, vel, C):
    """True when the strapdown nominal (position, velocity, attitude matrix) is finite."""
    for i in range(3):
        if not (np.isfinite(pos[i]) and np.isfinite(vel[i])):
            return False
        for k in range(3):
            if not np.isfinite(C[i, k]):
                return False
    return True


def check_covariance(x, P, time: float, what: str, full: bool = True) -> None:
    """Raise FilterHealthError if ``x`` or ``P`` is non-finite or (``full``) ``P`` is not
    positive definite (:func:`covariance_fault`)."""
    code = covariance_fault(x, P, bool(full))
    if code == 1:
        raise FilterHealthError(f"filter state became non-finite at t = {time:.6f} s ({what})",
                                found="NaN/inf in x or P")
    if code == 2:
        raise FilterHealthError(
            f"covariance is not positive definite at t = {time:.6f} s ({what})",
            found="Cholesky factorisation failed")


def nominal_error(time: float) -> FilterHealthError:
    """The error raised when the nominal state (mechanization) became non-finite."""
    return FilterHealthError(
        f"nominal state became non-finite at t = {time:.6f} s (mechanization; non-finite IMU "
        "data?)", found="NaN/inf in position/velocity/attitude")


@njit(cache=True)
def _small_median(a, n):
    """Median of ``a[:n]`` (sorted in place; no NaN), the value ``np.median`` gives: the middle
    element, or ``(a + b) / 2`` of the two middle ones. An insertion sort of the few values of
    a runaway-NIS window (at most its capacity, 64): numba's ``np.median`` (quickselect) costs
    about 1.5-2 s of compile on an empty cache, this a tenth of that."""
    for i in range(1, n):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v
    half = n >> 1
    if n & 1:
        return a[half]
    return (a[half - 1] + a[half]) / 2


@entry
@njit(cache=True)
def runaway_push(buf_t, buf_v, state, tid, time, nnis, window, min_count, bound, scratch):
    """Record one normalized NIS of type ``tid``; return the window median if it exceeds
    ``bound`` (the check runs at most once per second per type), else -1.

    ``buf_t, buf_v`` (types, capacity): ring buffers of (time, NIS/dof); ``state`` (types, 3):
    (head, count, time of the last check). Values older than ``window`` are dropped; a full
    buffer drops its oldest value (the capacity is sized for the densest window). The median
    is taken once the window holds values at ``min_count`` distinct times (epochs).
    """
    cap = buf_t.shape[1]
    head = int(state[tid, 0])
    cnt = int(state[tid, 1])
    if not np.isfinite(nnis):
        nnis = np.inf
    # drop values older than the window (and the oldest if full)
    while cnt > 0 and (buf_t[tid, head] < time - window or cnt == cap):
        head = (head + 1) % cap
        cnt -= 1
    k = (head + cnt) % cap
    buf_t[tid, k] = time
    buf_v[tid, k] = nnis
    cnt += 1
    state[tid, 0] = head
    state[tid, 1] = cnt
    if cnt < min_count or time - state[tid, 2] < 1.0:
        return -1.0
    # the window must span min_count distinct epochs (times are pushed in order)
    epochs = 0
    last = -np.inf
    for i in range(cnt):
        ti = buf_t[tid, (head + i) % cap]
        if ti != last:
            epochs += 1
            last = ti
        scratch[i] = buf_v[tid, (head + i) % cap]
    if epochs < min_count:
        return -1.0
    state[tid, 2] = time
    med = _small_median(scratch, cnt)
    if med > bound:
        return med
    return -1.0


@entry  # called from Python too (a gate recovery): an export, not numba's import
@njit(cache=True)
def runaway_restart(state):
    """Empty the runaway-NIS windows of all types (after a gate recovery; module docstring)."""
    for tid in range(state.shape[0]):
        state[tid, 1] = 0.0


class RunawayNis:
    """Runaway-NIS monitor of all measurement types (module docstring); ``window=None``
    disables it; ``watched`` (bool per type, default all) selects the types checked."""

    def __init__(self, n_types: int, window: float | None, bound: float, min_count: int,
                 capacity: int = 64, watched=None):
        self.enabled = window is not None
        self.window = float(window) if window is not None else np.inf
        self.bound = float(bound)
        self.min_count = int(min_count)
        cap = max(int(capacity), self.min_count, 2)
        self.buf_t = np.zeros((max(n_types, 1), cap))
        self.buf_v = np.zeros((max(n_types, 1), cap))
        self.state = np.zeros((max(n_types, 1), 3))
        self.state[:, 2] = -np.inf
        if watched is not None:  # unwatched types are never checked (module docstring)
            self.state[:len(watched), 2] = np.where(np.asarray(watched, bool), -np.inf, np.inf)
        self.scratch = np.empty(cap)

    def push(self, tid: int, name: str, time: float, nnis: float) -> None:
        """Record one value; raise FilterHealthError when the median runs away."""
        if not self.enabled:
            return
        med = runaway_push(self.buf_t, self.buf_v, self.state, tid, time, nnis, self.window,
                           self.min_count, self.bound, self.scratch)
        if med >= 0.0:
            raise self.error(tid, name, time, med)

    def restart(self) -> None:
        """Empty the windows of all types (after a gate recovery)."""
        runaway_restart(self.state)

    def error(self, tid: int, name: str, time: float, med: float) -> FilterHealthError:
        """The error for a runaway median ``med`` of type ``tid`` (``name``) at ``time``."""
        return FilterHealthError(
            f"runaway NIS at t = {time:.6f} s: the median NIS/dof of the {name!r} measurements over "
            f"the last {self.window:g} s is {med:.4g} (filter diverged or measurement noise "
            "far too small)", column=name, expected=f"a median NIS/dof <= {self.bound:g}",
            found=f"{med:.4g} over {int(self.state[tid, 1])} measurements at "
                  f"{self.epochs(tid)} epochs")

    def epochs(self, tid: int) -> int:
        """Distinct times among the values of type ``tid`` in its window."""
        cap = self.buf_t.shape[1]
        head, cnt = int(self.state[tid, 0]), int(self.state[tid, 1])
        return int(np.unique(self.buf_t[tid, (head + np.arange(cnt)) % cap]).size)


def imu_outlier_note(t, gyro, accel, t_fail: float, window: float) -> str:
    """The largest gyro and accelerometer outliers among the IMU samples (times ``t``, angular
    rates ``gyro`` [rad/s] and specific forces ``accel`` [m/s^2], (N, 3) or None) in the
    ``window`` seconds before ``t_fail`` (module docstring), as a sentence ("" when none
    exceeds :data:`OUTLIER_FACTOR` times the recording's level)."""
    t = np.asarray(t, float)
    sel = np.flatnonzero((t > t_fail - window) & (t <= t_fail + 1e-9))
    parts = []
    for what, x, unit, scale in (("gyro", gyro, "deg/s", np.degrees(1.0)),
                                 ("accelerometer", accel, "m/s^2", 1.0)):
        if x is None or not sel.size:
            continue
        x = np.asarray(x, float) * scale
        mag = np.linalg.norm(x, axis=1)
        level = float(np.nanpercentile(mag, 99.9))
        if not np.isfinite(level) or level <= 0:
            continue
        k = int(sel[np.nanargmax(mag[sel])])
        if mag[k] > OUTLIER_FACTOR * level:
            v = ", ".join(f"{c:.4g}" for c in x[k])
            sym = "omega" if what == "gyro" else "f"
            parts.append(f"the {what} sample at t = {t[k]:.6f} s, |{sym}| = {mag[k]:.4g} "
                         f"{unit} ({v}), {mag[k] / level:.3g} times the recording's 99.9th "
                         f"percentile {level:.4g} {unit}")
    if not parts:
        return ""
    return (f"; in the {window:g} s before, the IMU data holds an outlier: "
            + " and ".join(parts)
            + " (a single-sample spike? inputs.imu.spike_policy = \"bridge\" repairs those)")


def with_imu_note(exc: FilterHealthError, t, gyro, accel, t_fail: float, window: float
                  ) -> FilterHealthError:
    """``exc`` with :func:`imu_outlier_note` appended to its message (itself if none)."""
    note = imu_outlier_note(t, gyro, accel, t_fail, window)
    if not note:
        return exc
    return FilterHealthError(exc.message + note, file=exc.file, row=exc.row, column=exc.column,
                             expected=exc.expected, found=exc.found)
