"""The engine's compiled high-rate path: updates at (up to) every IMU sample in numba.

ZUPT and ZARU at every IMU sample of a foot-mounted INS (200 Hz and more), or NHC and odometer
at the IMU rate, cost too much through the Python update path (tens of microseconds per epoch).
Measurement models built with ``high_rate=True`` (:class:`~.measurements.Zupt`,
:class:`~.measurements.Zaru`, :class:`~.measurements.BodyVelocity`) are applied here instead.
A segment between two filter epochs that holds such measurements (a *dense* segment,
:mod:`.schedule`) is run sample by sample in one compiled call, and every IMU sample of it is a
node of the smoother's store (:mod:`.store`):

1. *propagate*: the process model's interval step (:func:`.kernels.interval_step` for the LLF
   strapdown) advances the nominal over the IMU interval and gives ``F dt`` and the noise
   integrals; the covariance is propagated with the first-order transition of the interval,
   ``Phi = I + F dt``, ``Qd = G Q G^T dt`` (at the IMU rate the second-order term is below
   1e-3 of the first; KF-GINS and the OpenShoe/PyShoe filters use the same form), exploiting
   the sparsity of ``F``: ``P <- Phi P Phi^T + Qd`` in O(n nnz(F)) (through the 3x3 blocks of
   the short-term 15-state model, :func:`_propagate_short15`);
2. *update/gate*: each high-rate measurement at the sample gives ``(z, H, R)``
   (:func:`.measurements.evaluate_compiled`, the same implementation the Python path uses); it
   is gated against the predicted ``P`` (:func:`.gating.gate_step`, the chi-square thresholds
   of the engine's gate table, gate recovery with :func:`.gating.inflate_for`), checked by the
   runaway-NIS monitor (:func:`.health.runaway_push`) and logged; the accepted ones are
   applied one scalar row at a time when their noise is uncorrelated (diagonal ``R``: ZUPT,
   ZARU, NHC; :func:`_sequential_rows`, rank-one downdates from the rows of ``P`` at the
   non-zeros of ``H``, found once per sample (:func:`row_pattern`) for ``H P``, the blocks of
   ``S`` and the update; the
   smoother's stacked ``K`` and ``S^-1 z`` recovered exactly from ``P(k|k)``; not in a run
   that stores ``S^-1 H`` for smoothed covariances), else
   stacked into one update, ``P <- P - K S K^T`` as a symmetric rank-m downdate through the
   Cholesky factor of ``S`` (the optimal-gain form of the Joseph update at a third of its
   cost; :func:`_kalman_update`);
3. *feedback*: the error estimate is fed back into the nominal (:func:`.kernels.apply_feedback`)
   and reset;
4. *store*: the node (``Phi``, ``P(k|k-1)``, ``P(k|k)``, feedback, the update's ``H`` by its
   non-zeros (the row pattern), ``K, S^-1 H, S^-1 z``, the nominal parameters) and the
   IMU-rate nominal row.

A non-finite or non-positive-definite covariance or a runaway NIS stops the segment with a
status code; the engine turns it into :class:`insgnss.errors.FilterHealthError` and keeps the
nodes written before it.

Process models: the kernel advances the LLF strapdown nominal (``model id`` 0,
:class:`.strapdown_model.StrapdownModel`); another nominal representation (e.g. wander
azimuth) adds its id with its own interval step and feedback in :func:`_model_step` and
:func:`_model_feedback`.
"""

from __future__ import annotations

import time as _time

import numpy as np

from ..aot import entry
from ..errors import ConfigError, FilterHealthError
from ..jit import njit
from ..mechanization.strapdown import STEP_WORK_SHAPE
from . import gating, health
from .kernels import _euler_std, apply_feedback_into, interval_step, store_nav
from .linalg import _innovation_cov, cholesky_into, hp_rows, s_block, tri_solve
from .measurements import ZARU, ZUPT, Measurement, evaluate_compiled

__all__ = ["HighRate", "dense_segment"]

OK, NONFINITE, NOT_PD, RUNAWAY, RECOVERED = 0, 1, 2, 3, 4


# Numba IR-inlined (with kernels.interval_step): a separately compiled callee increfs and
# decrefs every array argument at each call (its error-status check keeps numba's refcount
# pruning from removing the pairs), about 30 atomic operations per IMU sample here; inlined,
# the foot-mounted loop runs ~9 % faster with bit-identical results (docs/zupt.md).
@njit(cache=True, inline="always")
def _model_step(
    model,
    dynamics,
    pos,
    vel,
    C,
    pnom,
    dth_j,
    dv_j,
    a,
    dt_s,
    i_sg,
    i_sa,
    gmodel,
    aupd,
    F,
    Qg,
    Qa,
    q_g,
    q_a,
    dyn,
    dthc,
    dvc,
    work,
):
    """Advance the nominal of process model ``model`` over one IMU interval, adding ``F dt``
    and the noise integrals (model 0: LLF strapdown with error model ``dynamics``)."""
    if model == 0:
        interval_step(
            pos,
            vel,
            C,
            pnom,
            dth_j,
            dv_j,
            a,
            dt_s,
            i_sg,
            i_sa,
            gmodel,
            aupd,
            F,
            Qg,
            Qa,
            q_g,
            q_a,
            dyn,
            dthc,
            dvc,
            work,
            dynamics,
        )


@njit(cache=True, inline="always")
def _model_feedback(model, pos, vel, C, pnom, x, work):
    """Closed-loop feedback of the error estimate ``x`` into the nominal (model 0: LLF;
    ``work`` (3, 3, 3) scratch)."""
    if model == 0:
        apply_feedback_into(pos, vel, C, pnom, x, work)


@njit(cache=True)
def _first_order_propagation(P, F, Qd, f_ptr, f_col, f_act, q_row, q_col, A, B, n=-1):
    """``P <- (I + F) P (I + F)^T + Qd`` (``F`` = F dt) in O(nnz(F) n).

    ``F`` is read at its structural non-zeros: the rows ``f_act[a]`` with the columns
    ``f_col[f_ptr[a]:f_ptr[a+1]]`` (:meth:`.strapdown_model.StrapdownModel.f_pattern`);
    ``Qd`` at the entries ``(q_row, q_col)``. With ``A = F[act] P``: ``B = P (I + F)^T = P +
    A^T`` (active columns), then ``P' = B + F B`` (active rows). ``A``, ``B``: scratch; ``n``:
    the state dimension (default from ``P``).
    """
    if n < 0:
        n = P.shape[0]
    na = f_act.shape[0]
    for a in range(na):  # A = F[act] P
        i = f_act[a]
        for j in range(n):
            A[a, j] = 0.0
        for q in range(f_ptr[a], f_ptr[a + 1]):
            c = f_col[q]
            v = F[i, c]
            for j in range(n):
                A[a, j] += v * P[c, j]
    for i in range(n):
        for j in range(n):
            B[i, j] = P[i, j]
    for a in range(na):
        i = f_act[a]
        for j in range(n):
            B[j, i] += A[a, j]
    for i in range(n):
        for j in range(n):
            P[i, j] = B[i, j]
    for a in range(na):
        i = f_act[a]
        for q in range(f_ptr[a], f_ptr[a + 1]):
            c = f_col[q]
            v = F[i, c]
            for j in range(n):
                P[i, j] += v * B[c, j]
    for q in range(q_row.shape[0]):
        P[q_row[q], q_col[q]] += Qd[q_row[q], q_col[q]]


@njit(cache=True)
def _propagate_short15(P, F, Qd, A):
    """``P <- (I + F) P (I + F)^T + Qd`` for the 15-state short-term strapdown error model
    (:func:`.models.accumulate_short_term_dynamics`: ``F[0:3, 3:6] = I dt``, velocity rows
    ``F[3:6, 6:9] = -[dv^l x]`` and ``F[3:6, 12:15] = -C dt``, attitude rows
    ``F[6:9, 9:12] = -C dt``) through its 3x3 blocks: the same numbers as
    :func:`_first_order_propagation` at a fraction of its cost. ``A``: scratch (15, 15).

    The bias rows of ``I + F`` are rows of the identity, so with ``A = (I + F) P`` only the
    navigation rows 0-8 of ``A`` are formed, and for symmetric ``P`` the bias rows of the
    result are the bias columns of ``A`` (``P'[b, i] = ((I + F) P[:, b])_i = A[i, b]``, the same
    products in the same order) and its bias-bias block is ``P``'s: only the navigation rows
    of ``A (I + F)^T`` are computed (9 of 15), then the navigation block is symmetrised.

    The 30 block entries of ``F`` and each column of ``P`` (row of ``A``) are read into
    tuples first: the compiler cannot tell that the arrays do not overlap, and with the values
    in registers it need not reload them after every store."""
    fp = (F[0, 3], F[1, 4], F[2, 5])
    fa = (F[3, 6], F[3, 7], F[3, 8], F[4, 6], F[4, 7], F[4, 8], F[5, 6], F[5, 7], F[5, 8])
    fb = (F[3, 12], F[3, 13], F[3, 14], F[4, 12], F[4, 13], F[4, 14], F[5, 12], F[5, 13], F[5, 14])
    fg = (F[6, 9], F[6, 10], F[6, 11], F[7, 9], F[7, 10], F[7, 11], F[8, 9], F[8, 10], F[8, 11])
    for j in range(15):  # A[0:9] = rows 0-8 of (I + F) P, row blocks of column j
        p = (
            P[0, j],
            P[1, j],
            P[2, j],
            P[3, j],
            P[4, j],
            P[5, j],
            P[6, j],
            P[7, j],
            P[8, j],
            P[9, j],
            P[10, j],
            P[11, j],
            P[12, j],
            P[13, j],
            P[14, j],
        )
        for i in range(3):
            A[i, j] = p[i] + fp[i] * p[3 + i]
            v = p[3 + i]
            w = p[6 + i]
            for k in range(3):
                v += fa[3 * i + k] * p[6 + k] + fb[3 * i + k] * p[12 + k]
                w += fg[3 * i + k] * p[9 + k]
            A[3 + i, j] = v
            A[6 + i, j] = w
    for j in range(9):  # rows 0-8 of P' = A (I + F)^T, column blocks of row j
        a = (
            A[j, 0],
            A[j, 1],
            A[j, 2],
            A[j, 3],
            A[j, 4],
            A[j, 5],
            A[j, 6],
            A[j, 7],
            A[j, 8],
            A[j, 9],
            A[j, 10],
            A[j, 11],
            A[j, 12],
            A[j, 13],
            A[j, 14],
        )
        for i in range(3):
            P[j, i] = a[i] + fp[i] * a[3 + i]
            v = a[3 + i]
            w = a[6 + i]
            for k in range(3):
                v += a[6 + k] * fa[3 * i + k] + a[12 + k] * fb[3 * i + k]
                w += a[9 + k] * fg[3 * i + k]
            P[j, 3 + i] = v
            P[j, 6 + i] = w
        for i in range(9, 15):
            P[j, i] = a[i]
    for i in range(9):  # symmetrise the navigation block, mirror the navigation-bias block
        for j in range(i + 1, 9):
            v = 0.5 * (P[i, j] + P[j, i]) + Qd[i, j]
            P[i, j] = v
            P[j, i] = v
        for j in range(9, 15):
            v = P[i, j] + Qd[i, j]
            P[i, j] = v
            P[j, i] = v
        P[i, i] += Qd[i, i]
    for i in range(9, 15):
        for j in range(i + 1, 15):
            v = P[i, j] + Qd[i, j]
            P[i, j] = v
            P[j, i] = v
        P[i, i] += Qd[i, i]


@njit(cache=True)
def _kalman_update(P, H, z, m, HP, S, x, Kt, G, s, L, W, V, want_G, n=-1):
    """Stacked Kalman update with the first ``m`` rows of ``H``, ``z`` and their
    ``HP = H P``, ``S = H P H^T + R`` (:func:`_innovation_cov`).

    With ``S = L L^T`` and ``W = L^-1 H P``: the gain (transposed) ``K^T = L^-T W``,
    ``x = K z``, ``G = S^-1 H`` (if ``want_G``), ``s = S^-1 z`` and ``P <- P - K S K^T =
    P - W^T W`` (a
    symmetric rank-m downdate: the optimal-gain form of the Joseph update at a fraction of its
    cost). Returns False (P unchanged) if ``S`` is not positive definite.
    """
    if n < 0:
        n = P.shape[0]
    if not cholesky_into(S, L, m):  # S = L L^T
        return False
    tri_solve(L, HP, m, W, False, n)
    tri_solve(L, W, m, Kt, True, n)
    if want_G:
        tri_solve(L, H, m, V, False, n)
        tri_solve(L, V, m, G, True, n)
    for i in range(m):  # s = S^-1 z
        v = z[i]
        for q in range(i):
            v -= L[i, q] * s[q]
        s[i] = v / L[i, i]
    for i in range(m - 1, -1, -1):
        v = s[i]
        for q in range(i + 1, m):
            v -= L[q, i] * s[q]
        s[i] = v / L[i, i]
    for i in range(n):
        v = 0.0
        for a in range(m):
            v += Kt[a, i] * z[a]
        x[i] = v
    for a in range(m):  # P -= W^T W (upper triangle, row operations)
        for i in range(n):
            wi = W[a, i]
            if wi != 0.0:
                for j in range(i, n):
                    P[i, j] -= wi * W[a, j]
    for i in range(n):
        for j in range(i + 1, n):
            P[j, i] = P[i, j]
    return True


@njit(cache=True)
def row_pattern(H, m, n, nzn, nzc, nzv):
    """The non-zeros of the first ``m`` rows of ``H``: row ``p`` has ``nzn[p]`` of them, at the
    columns ``nzc[p, :nzn[p]]`` (increasing) with the values ``nzv[p, :nzn[p]]`` (a ZUPT row
    selects one velocity state, a ZARU row a gyro bias and the three attitude states). The
    high-rate path forms ``H P``, the blocks of ``S`` and the row-by-row update from it instead
    of reading the dense rows again."""
    for p in range(m):
        nz = 0
        for c in range(n):
            h = H[p, c]
            if h != 0.0:
                nzc[p, nz] = c
                nzv[p, nz] = h
                nz += 1
        nzn[p] = nz


@njit(cache=True)
def _hp_sparse(P, m, nzn, nzc, nzv, HP, n):
    """``HP = H P`` for the first ``m`` rows of ``H`` given by their non-zeros
    (:func:`row_pattern`): the same sums, in the same order, as :func:`.linalg.hp_rows`."""
    for a in range(m):
        for j in range(n):
            HP[a, j] = 0.0
        for q in range(nzn[a]):
            c = nzc[a, q]
            h = nzv[a, q]
            for j in range(n):
                HP[a, j] += h * P[c, j]


@njit(cache=True)
def _innovation_cov_blocks(H, P, R, off, nm, HP, S, n, nzn=None, nzc=None, nzv=None):
    """``HP = H P`` for the rows ``0 .. off[nm]-1`` and the diagonal blocks
    ``S[o0:o1, o0:o1] = H P H^T + R`` of the measurements ``k < nm`` (rows ``off[k] ..
    off[k+1]-1``): what gating and the innovation log read when the measurements are applied
    one row at a time (:func:`_sequential_update`); the zeros of ``H`` are skipped (read from
    the row pattern ``nzn, nzc, nzv`` of :func:`row_pattern` when given)."""
    if nzn is None:
        hp_rows(H, P, off[nm], HP, n)
        for k in range(nm):
            s_block(H, R, HP, off[k], off[k + 1], S, n)
        return
    _hp_sparse(P, off[nm], nzn, nzc, nzv, HP, n)
    for k in range(nm):
        for a in range(off[k], off[k + 1]):
            for b in range(off[k], a + 1):
                v = R[a, b]
                for q in range(nzn[b]):
                    v += HP[a, nzc[b, q]] * nzv[b, q]
                S[a, b] = v
                S[b, a] = v


@njit(cache=True)
def _sequential_update(P, H, z, rd, m, x, Kt, s, u, k, nzc, nzv, n):
    """Kalman update with the first ``m`` rows of ``H``, ``z`` applied one scalar row at a
    time, for mutually uncorrelated rows (``R = diag(rd)``, ``rd > 0``): :func:`_sequential_rows`
    on the row pattern of ``H`` (:func:`row_pattern`; ``nzc``, ``nzv``: scratch of at least
    ``n`` entries, unused)."""
    nzn = np.empty(m, np.int64)
    pc = np.empty((m, n), np.int64)
    pv = np.empty((m, n))
    row_pattern(H, m, n, nzn, pc, pv)
    return _sequential_rows(P, z, rd, m, x, Kt, s, u, k, nzn, pc, pv, n)


@njit(cache=True)
def _sequential_rows(P, z, rd, m, x, Kt, s, u, k, nzn, nzc, nzv, n):
    """Kalman update with ``m`` rows given by their non-zeros (:func:`row_pattern`) and ``z``
    applied one scalar row at a time, for mutually uncorrelated rows (``R = diag(rd)``,
    ``rd > 0``).

    Row ``p`` (``h = H[p]``, prior ``x``, ``P``): ``u = P h^T``, ``s_p = h u + r_p``,
    ``x += u (z_p - h x) / s_p``, ``P -= u u^T / s_p``. For uncorrelated rows this is the
    stacked update (Maybeck 1979, sec. 7.4; Bierman 1977, ch. II) without the Cholesky factor
    of the stacked ``S``: ``u`` is the combination of the rows of ``P`` at the non-zeros of
    ``h`` (a ZUPT row selects one velocity state, a ZARU row a gyro bias and the attitude),
    read from the upper triangle; the rank-one downdates touch the upper triangle only and
    ``P`` is mirrored at the end.

    The smoother's quantities of the stacked update follow from ``P(k|k)`` and ``x`` exactly
    (``K = P(k|k) H^T R^-1``; the Woodbury form of ``S^-1`` gives ``S^-1 z = R^-1 (z - H x)``):
    the transposed gain ``Kt`` and ``s = S^-1 z``, the arrays :func:`_kalman_update` gives, so
    the store and the backward pass are those of the stacked update. (``S^-1 H = R^-1 (H - H K
    H)`` would lose digits to cancellation when ``H P H^T >> R``: a run that stores it, for the
    smoothed covariances, takes the stacked update.) ``u``, ``k``: scratch (n,). Returns False
    (``P`` partly updated) if a row's ``s_p`` is not positive.
    """
    for i in range(n):
        x[i] = 0.0
    for p in range(m):
        nz = nzn[p]
        for j in range(n):
            u[j] = 0.0
        for q in range(nz):  # u = P h^T from the upper triangle
            c = nzc[p, q]
            hc = nzv[p, q]
            for j in range(c):
                u[j] += hc * P[j, c]
            for j in range(c, n):
                u[j] += hc * P[c, j]
        sp = rd[p]
        nu = z[p]
        for q in range(nz):
            sp += nzv[p, q] * u[nzc[p, q]]
            nu -= nzv[p, q] * x[nzc[p, q]]
        if not sp > 0.0:
            return False
        isp = 1.0 / sp
        f = nu * isp
        for i in range(n):
            k[i] = u[i] * isp
            x[i] += u[i] * f
        for i in range(n):
            ki = k[i]
            for j in range(i, n):
                P[i, j] -= ki * u[j]
    for i in range(n):
        for j in range(i + 1, n):
            P[j, i] = P[i, j]
    for p in range(m):  # K^T = R^-1 H P(k|k), S^-1 z = R^-1 (z - H x)
        ri = 1.0 / rd[p]
        for j in range(n):
            Kt[p, j] = 0.0
        hx = 0.0
        for q in range(nzn[p]):
            c = nzc[p, q]
            hc = nzv[p, q]
            hx += hc * x[c]
            for j in range(n):
                Kt[p, j] += hc * P[c, j]
        for j in range(n):
            Kt[p, j] *= ri
        s[p] = (z[p] - hx) * ri
    return True


@njit(cache=True)
def _store_std_row(table, j, P, C, es, n):
    """Forward-table std columns (``STD_COLS``), parameter values are written by the caller,
    and parameter stds of row ``j`` from ``P`` (see :func:`.kernels.assemble_output`)."""
    _euler_std(C, P, 6, es)
    for i in range(6):
        table[j, 9 + i] = np.sqrt(max(P[i, i], 0.0))
    for i in range(3):
        table[j, 15 + i] = es[i]
    npar = n - 9
    for i in range(npar):
        table[j, 18 + npar + i] = np.sqrt(max(P[9 + i, 9 + i], 0.0))


@entry
@njit(cache=True)
def dense_segment(
    model,
    dynamics,
    t,
    dth,
    dv,
    pos,
    vel,
    C,
    pnom,
    i_sg,
    i_sa,
    gmodel,
    aupd,
    q_g,
    q_a,
    dyn,
    decay,
    qdiag,
    Fx,
    Qx,
    table,
    seg,
    post,
    rates,
    f_ptr,
    f_col,
    f_act,
    q_row,
    q_col,
    j,
    frac,
    t_end,
    P,
    hr0,
    hr_t,
    hr_row,
    hr_F,
    hr_Q,
    hr_fb,
    hr_r0,
    hr_r1,
    hr_ppi,
    pp_out,
    H_ptr,
    H_col,
    H_val,
    Ks,
    Gs,
    ss,
    row,
    store_G,
    hr_ptr,
    hr_m,
    hr_r,
    kinds,
    ips,
    fps,
    vptr,
    vals,
    stds,
    tids,
    thrs,
    gyro_psd,
    streak,
    recovery,
    n_nav,
    check,
    rw_on,
    rw_t,
    rw_v,
    rw_state,
    rw_scratch,
    rw_window,
    rw_min,
    rw_bound,
    lg_t,
    lg_tid,
    lg_dof,
    lg_nis,
    lg_thr,
    lg_flags,
    lg_z,
    lg_s,
    status,
):
    """Run the IMU rows ``j ..`` with ``t[j] <= t_end`` of a dense segment (module docstring):
    one high-rate sample per row, written at ``hr0, hr0 + 1, ...`` of the high-rate arrays of
    the store (:class:`insgnss.filter.store.NodeStore`); update rows from ``row`` (``H`` by its
    non-zeros into ``H_ptr, H_col, H_val`` from ``H_ptr[row]``, ``G`` only if ``store_G``); log
    records from 0; the forward table rows complete (nominal, stds,
    parameters).

    ``status`` (int64[4]) receives (code, samples written, update rows written, log records);
    the return value is ``(j, frac, fail_time, fail_value, fail_type)``. After a sample whose
    predicted covariance a gate recovery inflated, the call returns with code ``RECOVERED``
    and that ``P(i|i-1)`` in ``pp_out`` (the smoother needs it); the caller continues the
    segment with another call.
    """
    n = P.shape[0]
    n_t = t.shape[0]
    npar = n - 9
    F = np.zeros((n, n))
    Qd = np.zeros((n, n))
    Qg = np.zeros((3, 3))
    Qa = np.zeros((3, 3))
    A = np.empty((n, n))
    B = np.empty((n, n))
    Lc = np.empty((n, n))
    work = np.empty(STEP_WORK_SHAPE)
    dthc = np.empty(3)
    dvc = np.empty(3)
    w_ib = np.empty(3)
    es = np.empty(3)
    n_meas_max = 1
    for jj in range(j, n_t):
        n_meas_max = max(n_meas_max, hr_ptr[jj + 1] - hr_ptr[jj])
        if t[jj] > t_end:
            break
    mmax = 3 * n_meas_max
    Hk = np.zeros((mmax, n))
    Rk = np.zeros((mmax, mmax))
    zk = np.zeros(mmax)
    off = np.zeros(n_meas_max + 1, np.int64)
    mk = np.zeros(n_meas_max, np.int64)
    acc = np.zeros(n_meas_max, np.bool_)
    x = np.zeros(n)
    Kt = np.empty((mmax, n))
    G = np.empty((mmax, n))
    sv = np.empty(mmax)
    HP = np.empty((mmax, n))
    S = np.empty((mmax, mmax))
    L = np.empty((mmax, mmax))
    W = np.empty((mmax, n))
    V = np.empty((mmax, n))
    rd = np.empty(mmax)
    u_s = np.empty(n)
    k_s = np.empty(n)
    nz_n = np.zeros(mmax, np.int64)  # row pattern of Hk (row_pattern)
    nz_c = np.zeros((mmax, n), np.int64)
    nz_v = np.zeros((mmax, n))
    Ln = np.empty((3, 3))
    wn = np.empty(3)
    fb_work = np.empty((3, 3, 3))
    any_decay = False
    for i in range(9, n):
        if decay[i] > 0.0:
            any_decay = True
    has_fx = Fx.shape[0] == n
    has_qx = Qx.shape[0] == n
    pnom_old = pnom.copy()
    # the 15-state short-term model has a fixed block structure (no scale factors, extra
    # states or Gauss-Markov decay)
    short15 = model == 0 and dynamics == 1 and n == 15 and not any_decay and not has_fx
    na = f_act.shape[0]
    nq = q_row.shape[0]
    h = hr0
    n_log = 0
    r = row
    # int64 at every assignment: as integer literals, numba's ahead-of-time compiler could not
    # unify the codes (insgnss.aot)
    code = np.int64(OK)
    fail_t, fail_v, fail_tid = 0.0, 0.0, -1
    while j < n_t and t[j] <= t_end:
        dt_full = t[j] - t[j - 1]
        a = 1.0 - frac
        dt_s = a * dt_full
        # --- 1. propagate over the interval
        for p in range(na):
            i = f_act[p]
            for q in range(f_ptr[p], f_ptr[p + 1]):
                F[i, f_col[q]] = 0.0
        for i in range(3):
            for c in range(3):
                Qg[i, c] = 0.0
                Qa[i, c] = 0.0
        _model_step(
            model,
            dynamics,
            pos,
            vel,
            C,
            pnom,
            dth[j],
            dv[j],
            a,
            dt_s,
            i_sg,
            i_sa,
            gmodel,
            aupd,
            F,
            Qg,
            Qa,
            q_g,
            q_a,
            dyn,
            dthc,
            dvc,
            work,
        )
        for i in range(3):
            w_ib[i] = dthc[i] / dt_s if dt_s > 0.0 else 0.0
            rates[0, i] = rates[1, i] = w_ib[i]
            rates[2, i] = rates[3, i] = dvc[i] / dt_s if dt_s > 0.0 else 0.0
        if any_decay:  # Gauss-Markov parameters: nominal follows the mean, F gets -1/tau
            for i in range(9, n):
                if decay[i] > 0.0:
                    pnom[i - 9] *= np.exp(-decay[i] * dt_s)
                    F[i, i] -= decay[i] * dt_s
        if has_fx:  # coupled augmenting states: F block and the nominal p += Fx p dt
            for i in range(npar):
                pnom_old[i] = pnom[i]
            for i in range(9, n):
                v = 0.0
                for c in range(9, n):
                    F[i, c] += Fx[i, c] * dt_s
                    v += Fx[i, c] * pnom_old[c - 9]
                pnom[i - 9] += v * dt_s
        for i in range(n):
            Qd[i, i] = qdiag[i] * dt_s
        for i in range(3):
            for c in range(3):
                Qd[3 + i, 3 + c] = Qa[i, c]
                Qd[6 + i, 6 + c] = Qg[i, c]
        if has_qx:
            for i in range(9, n):
                for c in range(9, n):
                    Qd[i, c] = Qx[i, c] * dt_s + (qdiag[i] * dt_s if i == c else 0.0)
        if short15:
            _propagate_short15(P, F, Qd, A)
        else:
            _first_order_propagation(P, F, Qd, f_ptr, f_col, f_act, q_row, q_col, A, B, n)
        frac = 0.0
        if check:  # cheap every sample: finite, positive variances
            fin = pos[0] + pos[1] + pos[2] + vel[0] + vel[1] + vel[2]
            pos_var = True
            for i in range(n):
                fin += P[i, i]
                if not P[i, i] > 0.0:
                    pos_var = False
            if not np.isfinite(fin):
                code = np.int64(NONFINITE)
                fail_t = t[j]
                break
            if not pos_var:
                code = np.int64(NOT_PD)
                fail_t = t[j]
                break
        # --- 2. evaluate, then gate each measurement against the predicted P
        nm = 0
        m_tot = 0
        for e in range(hr_ptr[j], hr_ptr[j + 1]):
            mi = hr_m[e]
            vr = vptr[mi] + hr_r[e]
            window = dt_s if ips[mi, 7] == 1 else 0.0
            d = evaluate_compiled(
                kinds[mi],
                ips[mi],
                fps[mi],
                vals[vr],
                stds[vr],
                vel,
                C,
                pos[0],
                w_ib,
                window,
                gyro_psd,
                pnom,
                zk[m_tot:],
                Hk[m_tot:],
                Rk[m_tot:, m_tot:],
            )
            if d == 0:
                continue
            for p in range(m_tot):  # zero the off-diagonal blocks of R
                for q in range(m_tot, m_tot + d):
                    Rk[p, q] = 0.0
                    Rk[q, p] = 0.0
            off[nm] = m_tot
            mk[nm] = e
            nm += 1
            m_tot += d
            off[nm] = m_tot
        # uncorrelated rows (diagonal R, positive): applied one row at a time; gating and the
        # log need only the diagonal blocks of S (not when the store keeps S^-1 H)
        seq = not store_G
        for p in range(m_tot):
            rd[p] = Rk[p, p]
            if not rd[p] > 0.0:
                seq = False
        for k in range(nm):
            for p in range(off[k], off[k + 1]):
                for q in range(off[k], off[k + 1]):
                    if q != p and Rk[p, q] != 0.0:
                        seq = False
        if nm:
            if seq:
                row_pattern(Hk, m_tot, n, nz_n, nz_c, nz_v)
                if n == 15:
                    _innovation_cov_blocks(Hk, P, Rk, off, nm, HP, S, 15, nz_n, nz_c, nz_v)
                else:
                    _innovation_cov_blocks(Hk, P, Rk, off, nm, HP, S, n, nz_n, nz_c, nz_v)
            elif n == 15:
                _innovation_cov(Hk, P, Rk, m_tot, HP, S, 15)
            else:
                _innovation_cov(Hk, P, Rk, m_tot, HP, S, n)
        m_acc = 0
        recovered = False
        for k in range(nm):
            o0, o1 = off[k], off[k + 1]
            d = o1 - o0
            mi = hr_m[mk[k]]
            zd = zk[o0:o1]
            if d == 3:
                nis = gating.nis3(S, o0, zk)
            else:
                nis = gating.nis_into(S[o0:o1, o0:o1], zd, Ln, wn)
            tid = tids[mi]
            if rw_on:
                med = health.runaway_push(
                    rw_t, rw_v, rw_state, tid, t[j], nis / d, rw_window, rw_min, rw_bound, rw_scratch
                )
                if med >= 0.0:
                    code = np.int64(RUNAWAY)
                    fail_t, fail_v, fail_tid = t[j], med, tid
                    break
            thr = thrs[mi]
            gc = gating.gate_step(streak, tid, t[j], nis, thr, recovery[tid])
            if gc == gating.RECOVER:
                health.runaway_restart(rw_state)
                gating.inflate_for(P, Hk[o0:o1], Rk[o0:o1, o0:o1], zd, thr, n_nav)
                if seq:  # the others see the inflated P
                    _innovation_cov_blocks(Hk, P, Rk, off, nm, HP, S, n, nz_n, nz_c, nz_v)
                else:
                    _innovation_cov(Hk, P, Rk, m_tot, HP, S, n)
                nis = gating.nis_into(S[o0:o1, o0:o1], zd, Ln, wn)
                recovered = True
            acc[k] = gc != gating.REJECT
            if acc[k]:
                m_acc += d
            lg_t[n_log] = t[j]
            lg_tid[n_log] = tid
            lg_dof[n_log] = d
            lg_nis[n_log] = nis
            lg_thr[n_log] = thr
            lg_flags[n_log, 0] = acc[k]
            lg_flags[n_log, 1] = gc == gating.RECOVER
            for p in range(3):
                lg_z[n_log, p] = zd[p] if p < d else np.nan
                lg_s[n_log, p] = np.sqrt(max(S[o0 + p, o0 + p], 0.0)) if p < d else np.nan
            n_log += 1
        if code != OK:
            break
        if m_acc < m_tot:  # drop the rejected rows (and their rows/columns of HP, S)
            dst = 0
            for k in range(nm):
                if not acc[k]:
                    continue
                for p in range(off[k], off[k + 1]):
                    zk[dst] = zk[p]
                    rd[dst] = rd[p]
                    for c in range(n):
                        Hk[dst, c] = Hk[p, c]
                        HP[dst, c] = HP[p, c]
                    if seq:
                        dst += 1
                        continue
                    dc = 0
                    for k2 in range(nm):
                        if acc[k2]:
                            for q in range(off[k2], off[k2 + 1]):
                                S[dst, dc] = S[p, q]
                                dc += 1
                    dst += 1
        hr_ppi[h] = -1
        if recovered:
            for i in range(n):
                for c in range(n):
                    pp_out[i, c] = P[i, c]
        # --- 3. stacked update and feedback
        hr_r0[h] = r
        if m_acc > 0:
            if seq and m_acc < m_tot:
                row_pattern(Hk, m_acc, n, nz_n, nz_c, nz_v)
            if seq and n == 15:  # the constant dimension lets LLVM unroll the loops
                ok = _sequential_rows(P, zk, rd, m_acc, x, Kt, sv, u_s, k_s, nz_n, nz_c, nz_v, 15)
            elif seq:
                ok = _sequential_rows(P, zk, rd, m_acc, x, Kt, sv, u_s, k_s, nz_n, nz_c, nz_v, n)
            elif n == 15:
                ok = _kalman_update(P, Hk, zk, m_acc, HP, S, x, Kt, G, sv, L, W, V, store_G, 15)
            else:
                ok = _kalman_update(P, Hk, zk, m_acc, HP, S, x, Kt, G, sv, L, W, V, store_G, n)
            if not ok:
                code = np.int64(NOT_PD)
                fail_t = t[j]
                break
            if check and (h - hr0) % 64 == 0 and not cholesky_into(P, Lc, n):
                code = np.int64(NOT_PD)
                fail_t = t[j]
                break
            if not seq:
                row_pattern(Hk, m_acc, n, nz_n, nz_c, nz_v)
            nzp = H_ptr[r]
            for p in range(m_acc):  # H by its non-zeros, K^T (and S^-1 H) dense
                for q in range(nz_n[p]):
                    H_col[nzp] = nz_c[p, q]
                    H_val[nzp] = nz_v[p, q]
                    nzp += 1
                H_ptr[r + 1] = nzp
                for c in range(n):
                    Ks[r, c] = Kt[p, c]
                    if store_G:
                        Gs[r, c] = G[p, c]
                ss[r] = sv[p]
                r += 1
            for i in range(n):
                hr_fb[h, i] = x[i]
            _model_feedback(model, pos, vel, C, pnom, x, fb_work)
        else:
            for i in range(n):
                hr_fb[h, i] = 0.0
        hr_r1[h] = r
        # --- 4. store the smoother step and the forward-table row
        hr_t[h] = t[j]
        hr_row[h] = j
        for p in range(na):
            i = f_act[p]
            for q in range(f_ptr[p], f_ptr[p + 1]):
                hr_F[h, q] = F[i, f_col[q]]
        for q in range(nq):
            hr_Q[h, q] = Qd[q_row[q], q_col[q]]
        store_nav(table, j, pos, vel, C)
        for i in range(npar):
            table[j, 18 + i] = pnom[i]
        _store_std_row(table, j, P, C, es, n)
        seg[j] = -1 - h
        post[j] = True
        h += 1
        j += 1
        if recovered:
            code = np.int64(RECOVERED)
            break
    status[0] = code
    status[1] = h - hr0
    status[2] = r - row
    status[3] = n_log
    return j, frac, fail_t, fail_v, fail_tid


class HighRate:
    """The high-rate measurements of one engine run and the calls of :func:`dense_segment`."""

    def __init__(self, measurements: list[Measurement], model, run):
        if not model.high_rate:
            raise ConfigError(
                f"the {type(model).__name__} process model has no compiled "
                "high-rate path; build the measurements with high_rate=False",
                column="measurements",
                found=[repr(m) for m in measurements],
            )
        layout = model.layout
        specs = []
        for m in measurements:
            spec = m.compiled(layout)
            base = next((c for c in type(m).__mro__ if "compiled" in c.__dict__), None)
            if spec is None or (base is not None and type(m).evaluate is not base.evaluate):
                raise ConfigError(
                    f"{type(m).__name__} has no compiled implementation (its "
                    "evaluate() is Python); use high_rate=False",
                    column="measurements",
                    found=repr(m),
                )
            specs.append(spec)
        self.model, self.run = model, run
        k = len(specs)
        self.kinds = np.array([s.kind for s in specs], np.int64)
        self.ips = np.ascontiguousarray(np.array([s.ip for s in specs], np.int64).reshape(k, 8))
        self.fps = np.ascontiguousarray(np.array([s.fp for s in specs], float).reshape(k, 8))
        sizes = [s.values.shape[0] for s in specs]
        self.vptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.vals = np.ascontiguousarray(np.concatenate([s.values for s in specs]), dtype=float)
        self.stds = np.ascontiguousarray(np.concatenate([s.std for s in specs]), dtype=float)
        self.tids = np.array([run.tid[m.name] for m in measurements], np.int64)
        # the thresholds come from the engine's gate table (3 dof for ZUPT/ZARU, the number of
        # constrained axes for body velocity)
        dofs = [3 if s.kind != 2 else int(s.ip[0]) for s in specs]
        self.thrs = np.array(
            [
                run.gates.threshold(run.gates.probability(m), d)
                for m, d in zip(measurements, dofs, strict=True)
            ],
            float,
        )
        self.gyro_psd = np.asarray(model.noise.gyro_psd, float)
        # most non-zeros of H an event of each measurement stores: a ZUPT row selects one
        # velocity state, a ZARU row a gyro bias and the three attitude states; a body-velocity
        # row may touch every state
        n = layout.n
        self.nz_bound = np.array(
            [3 if s.kind == ZUPT else 12 if s.kind == ZARU else 3 * n for s in specs], np.int64
        )
        self.pattern = model.f_pattern()

    def segment(self, t_end: float, P: np.ndarray) -> np.ndarray:
        """Run the dense segment up to ``t_end``; returns ``P`` after it. Raises
        FilterHealthError (after keeping the samples written) when the segment failed."""
        run, model, store = self.run, self.model, self.run.store
        sched = run.sched
        t = model.t
        j0 = model.j
        j1 = int(np.searchsorted(t, t_end, side="right"))
        n_ev = int(sched.hr_ptr[j1] - sched.hr_ptr[j0])
        store.reserve_rows(
            3 * n_ev, int(self.nz_bound[sched.hr_m[sched.hr_ptr[j0] : sched.hr_ptr[j1]]].sum())
        )
        lg = {
            "time": np.empty(n_ev),
            "tid": np.empty(n_ev, np.int64),
            "dof": np.empty(n_ev, np.int64),
            "nis": np.empty(n_ev),
            "threshold": np.empty(n_ev),
            "flags": np.zeros((n_ev, 2), np.bool_),
            "innov": np.empty((n_ev, 3)),
            "innov_std": np.empty((n_ev, 3)),
        }
        status = np.zeros(4, np.int64)
        rw = run.runaway
        P = np.array(P, dtype=float, order="C")
        pp_out = np.empty_like(P)
        n_log = 0
        while True:
            c0 = _time.perf_counter()
            h0 = store.hr_count
            j, frac, fail_t, fail_v, fail_tid = dense_segment(
                *model.high_rate_args(),
                *self.pattern,
                model.j,
                model.frac,
                t_end,
                P,
                h0,
                store.hr_t,
                store.hr_row,
                store.hr_F,
                store.hr_Q,
                store.hr_fb,
                store.hr_r0,
                store.hr_r1,
                store.hr_ppi,
                pp_out,
                store.H_ptr,
                store.H_col,
                store.H_val,
                store.K,
                store.G,
                store.s,
                store.n_rows,
                bool(run.config.smoother_covariance),
                sched.hr_ptr,
                sched.hr_m,
                sched.hr_r,
                self.kinds,
                self.ips,
                self.fps,
                self.vptr,
                self.vals,
                self.stds,
                self.tids,
                self.thrs,
                self.gyro_psd,
                run.streak,
                run.recovery,
                model.n_nav,
                run.check,
                rw.enabled,
                rw.buf_t,
                rw.buf_v,
                rw.state,
                rw.scratch,
                rw.window,
                rw.min_count,
                rw.bound,
                lg["time"][n_log:],
                lg["tid"][n_log:],
                lg["dof"][n_log:],
                lg["nis"][n_log:],
                lg["threshold"][n_log:],
                lg["flags"][n_log:],
                lg["innov"][n_log:],
                lg["innov_std"][n_log:],
                status,
            )
            code, n_s, n_rows, n_new = (int(v) for v in status)
            run.timing["high_rate"] = run.timing.get("high_rate", 0.0) + _time.perf_counter() - c0
            n_log += n_new
            if n_s:
                model.j, model.frac = j, frac
                model.advance_to(float(store.hr_t[h0 + n_s - 1]))
            store.n_rows += n_rows
            store.hr_count = h0 + n_s
            if code != RECOVERED:
                break
            store.add_hr_predicted(h0 + n_s - 1, pp_out)
        run.log.add_block(
            {
                "time": lg["time"][:n_log],
                "tid": lg["tid"][:n_log],
                "dof": lg["dof"][:n_log],
                "nis": lg["nis"][:n_log],
                "threshold": lg["threshold"][:n_log],
                "accepted": lg["flags"][:n_log, 0].copy(),
                "recovered": lg["flags"][:n_log, 1].copy(),
                "innov": lg["innov"][:n_log],
                "innov_std": lg["innov_std"][:n_log],
            }
        )
        if code == NONFINITE:
            raise FilterHealthError(
                f"filter state became non-finite at t = {fail_t:.6f} s (high-rate propagation)",
                found="NaN/inf in P or nominal",
            )
        if code == NOT_PD:
            raise FilterHealthError(
                f"covariance is not positive definite at t = {fail_t:.6f} s (high-rate path)",
                found="Cholesky factorisation failed",
            )
        if code == RUNAWAY:
            raise rw.error(int(fail_tid), run.log.names[int(fail_tid)], fail_t, fail_v)
        return P
