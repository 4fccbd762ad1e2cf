"""Innovation gating and gate recovery of the filter engine (one implementation, used by the
Python update path and by the compiled high-rate path alike).

Gate
----
A measurement with innovation ``z`` (the predicted error state is zero after the closed-loop
reset, so the innovation equals ``z``) and innovation covariance ``S = H P H^T + R`` has the
normalized innovation squared ``NIS = z^T S^-1 z``, chi-square distributed with ``dof =
len(z)`` degrees of freedom for a consistent filter. It is accepted when ``NIS <= chi2.ppf(p,
dof)`` (:func:`insgnss.stats.chi2_ppf`); ``p`` is the measurement's ``gate_probability``, else
the per-type value of the configuration, else its default; ``None`` or 0 disables the gate.

Gate recovery
-------------
When every measurement of one type has been rejected for longer than ``recovery`` seconds (an
unbroken run of at least 3 rejections, with no gap longer than ``recovery`` between two of them),
the covariance is taken to be wrong, not the measurements: the navigation block of ``P``
(the process model's leading ``n_nav`` states) is inflated by factors of 2 until the
measurement sits at half its gate, and it is applied (logged ``recovered``). A gap longer than
the recovery time without rejections (e.g. between two stops for ZUPT) starts a new streak, so
sparse measurements are not force-applied.

Recovery applies only to absolute measurements that can re-anchor the state
(:attr:`~insgnss.filter.measurements.Measurement.recoverable`: GNSS position and velocity,
control points, pseudoranges and Doppler): after an outage, a wrong covariance is corrected by
such a fix. A constraint that is only approximately true - the non-holonomic constraint in a
skidding turn, a ZUPT on a vehicle that creeps, an odometer on a slipping wheel - is never forced
in: its persistent rejection means the constraint is violated, and inflating ``P`` to accept
it turns the attitude to fit a wrong measurement (seen on a real car log: 16 deg of heading in 2.5 s). The
engine passes ``recovery = -1`` (never) for those types. After a recovery the runaway-NIS
windows restart (:mod:`.health`).

The streak state of all measurement types is one array ``streak[type] = (first, last, count)``
(``count = 0``: no streak), so both update paths share it.

Labelled rows
-------------
A model that gives one measurement per satellite at an epoch (pseudorange, Doppler) labels
its rows (``row_label``). Each (type, label) keeps its own streak (a further row of the
array), so the age of a streak is the unbroken rejection history of one satellite, never one
inherited from another. A labelled streak recovers only when the type as a whole is lost
(:func:`type_lost`: no measurement of the type accepted for longer than the recovery time):
one satellite rejected while the others are accepted is a bad measurement (multipath, a
wrong ephemeris), not a wrong covariance, and is never forced through.
"""

from __future__ import annotations

import numpy as np

from ..aot import entry
from ..jit import njit
from ..stats import chi2_ppf
from .linalg import _innovation_cov, cholesky_into

__all__ = ["GateTable", "gate_step", "inflate_for", "innovation_nis", "nis", "nis3", "nis_into",
           "type_lost", "ACCEPT", "REJECT", "RECOVER"]

REJECT, ACCEPT, RECOVER = 0, 1, 2


class GateTable:
    """Chi-square thresholds per (probability, dof) (:func:`insgnss.stats.chi2_ppf` solves each
    once)."""

    def __init__(self, default: float | None, per_type: dict | None = None):
        self.default = default
        self.per_type = dict(per_type or {})

    def probability(self, m) -> float | None:
        """Gating probability of measurement model ``m`` (its own, per type, or default)."""
        p = getattr(m, "gate_probability", None)
        if p is None:
            p = self.per_type.get(m.name, self.default)
        return p

    def threshold(self, p: float | None, dof: int) -> float:
        """``chi2.ppf(p, dof)``; ``inf`` when gating is disabled (``p`` None or 0)."""
        if not p:
            return np.inf
        return chi2_ppf(float(p), int(dof))  # remembered there (one solve per (p, dof))


@njit(cache=True)
def nis_into(S, y, L, w):
    """Normalised innovation squared ``y^T S^-1 y`` by Cholesky (scratch ``L`` (m, m), ``w``
    (m,) at least); NaN if S is not PD."""
    m = y.shape[0]
    if not cholesky_into(S, L, m):
        return np.nan
    out = 0.0
    for i in range(m):
        v = y[i]
        for q in range(i):
            v -= L[i, q] * w[q]
        w[i] = v / L[i, i]
        out += w[i] * w[i]
    return out


@njit(cache=True)
def nis3(S, o, y):
    """:func:`nis_into` of the 3 x 3 block ``S[o:o+3, o:o+3]`` and ``y[o:o+3]`` (a ZUPT or
    ZARU), written out: the same operations in the same order (the same number), without the
    loops and views of the general size; NaN if the block is not PD."""
    v = S[o, o]
    if not v > 0.0:
        return np.nan
    l00 = np.sqrt(v)
    l10 = S[o + 1, o] / l00
    v = S[o + 1, o + 1] - l10 * l10
    if not v > 0.0:
        return np.nan
    l11 = np.sqrt(v)
    l20 = S[o + 2, o] / l00
    l21 = (S[o + 2, o + 1] - l20 * l10) / l11
    v = S[o + 2, o + 2] - l20 * l20 - l21 * l21
    if not v > 0.0:
        return np.nan
    l22 = np.sqrt(v)
    w0 = y[o] / l00
    out = w0 * w0
    w1 = (y[o + 1] - l10 * w0) / l11
    out += w1 * w1
    w2 = (y[o + 2] - l20 * w0 - l21 * w1) / l22
    out += w2 * w2
    return out


@entry
@njit(cache=True)
def nis(S, y):
    """Normalised innovation squared ``y^T S^-1 y`` by Cholesky; NaN if S is not PD."""
    m = y.shape[0]
    return nis_into(S, y, np.empty((m, m)), np.empty(m))


@entry
@njit(cache=True)
def innovation_nis(H, P, R, z):
    """``(S, NIS)`` of one measurement: ``S = H P H^T + R`` (symmetric, skipping the zeros of
    ``H``; :func:`.linalg._innovation_cov`, as the high-rate path forms it) and
    ``z^T S^-1 z`` (NaN if ``S`` is not positive definite), in one compiled call."""
    m, n = H.shape
    HP = np.empty((m, n))
    S = np.empty((m, m))
    _innovation_cov(H, P, R, m, HP, S)
    return S, nis_into(S, z, np.empty((m, m)), np.empty(m))


@entry
@njit(cache=True)
def gate_step(streak, tid, time, nis_value, thr, recovery):
    """Gate decision for one measurement of type ``tid`` at ``time``.

    Returns ``ACCEPT`` (NIS inside the gate; ends the type's rejection streak), ``REJECT`` or
    ``RECOVER`` (the streak is older than ``recovery`` seconds: inflate P and apply; the streak
    ends). ``recovery < 0`` disables recovery. NaN NIS (S not positive definite) is rejected
    without starting a streak.
    """
    if nis_value <= thr:
        streak[tid, 2] = 0.0
        return ACCEPT
    if not np.isfinite(nis_value):
        return REJECT
    if streak[tid, 2] == 0.0 or (recovery >= 0.0 and time - streak[tid, 1] > recovery):
        streak[tid, 0] = time
        streak[tid, 2] = 0.0
    streak[tid, 1] = time
    streak[tid, 2] += 1.0
    if recovery >= 0.0 and streak[tid, 2] >= 3.0 and time - streak[tid, 0] > recovery:
        streak[tid, 2] = 0.0
        return RECOVER
    return REJECT


def type_lost(last_accept: float, time: float, recovery: float) -> bool:
    """A labelled row may recover (module docstring, "Labelled rows"): no measurement of its
    type was accepted within the last ``recovery`` seconds (``recovery < 0``: never)."""
    return recovery >= 0.0 and time - last_accept > recovery


@njit(cache=True)
def inflate_for(P, H, R, z, thr, n_nav):
    """Scale the navigation block (states ``0 .. n_nav-1``) of ``P`` in place by factors of 2
    (rows and columns by sqrt 2) until ``z`` has NIS <= thr / 2 (at most 60 times; nothing if
    ``H`` does not see the navigation states). Returns the final ``S = H P H^T + R``."""
    m, n = H.shape
    seen = False
    for i in range(m):
        for k in range(n_nav):
            if H[i, k] != 0.0:
                seen = True
    HP = np.empty((m, n))
    S = np.empty((m, m))
    r2 = np.sqrt(2.0)
    for it in range(61):
        _innovation_cov(H, P, R, m, HP, S)
        if it == 60 or not seen or nis(S, z) <= 0.5 * thr:
            break
        for i in range(n_nav):
            for k in range(n):
                P[i, k] *= r2
                P[k, i] *= r2
    return S
