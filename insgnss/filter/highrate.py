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
   the sparsity of ``F``: ``P <- Phi P Phi^T + Qd`` in O(n nnz(F));
2. *update/gate*: each high-rate measurement at the sample gives ``(z, H, R)``
   (:func:`.measurements.evaluate_compiled`, the same implementation the Python path uses); it
   is gated against the predicted ``P`` (:func:`.gating.gate_step`, the chi-square thresholds
   of the engine's gate table, gate recovery with :func:`.gating.inflate_for`), checked by the
   runaway-NIS monitor (:func:`.health.runaway_push`) and logged; the accepted ones are
   stacked into one update, ``P <- P - K S K^T`` as a symmetric rank-m downdate through the
   Cholesky factor of ``S`` (the optimal-gain form of the Joseph update at a third of its
   cost; :func:`_kalman_update`);
3. *feedback*: the error estimate is fed back into the nominal (:func:`.kernels.apply_feedback`)
   and reset;
4. *store*: the node (``Phi``, ``P(k|k-1)``, ``P(k|k)``, feedback, the update's ``H, K,
   S^-1 H, S^-1 z``, the nominal parameters) and the IMU-rate nominal row.

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
from numba import njit

from ..errors import ConfigError, FilterHealthError
from ..mechanization.strapdown import STEP_WORK_SHAPE
from . import gating, health
from .kernels import apply_feedback, interval_step, store_nav
from .measurements import Measurement, evaluate_compiled

__all__ = ["HighRate", "dense_segment"]

OK, NONFINITE, NOT_PD, RUNAWAY = 0, 1, 2, 3


@njit(cache=True)
def _model_step(model, pos, vel, C, pnom, dth_j, dv_j, a, dt_s, i_sg, i_sa, gmodel, aupd, F,
                Qg, Qa, q_g, q_a, dyn, dthc, dvc, work):
    """Advance the nominal of process model ``model`` over one IMU interval, adding ``F dt``
    and the noise integrals (model 0: LLF strapdown)."""
    if model == 0:
        interval_step(pos, vel, C, pnom, dth_j, dv_j, a, dt_s, i_sg, i_sa, gmodel, aupd, F, Qg,
                      Qa, q_g, q_a, dyn, dthc, dvc, work)


@njit(cache=True)
def _model_feedback(model, pos, vel, C, pnom, x):
    """Closed-loop feedback of the error estimate ``x`` into the nominal (model 0: LLF)."""
    if model == 0:
        apply_feedback(pos, vel, C, pnom, x)


@njit(cache=True)
def _first_order_propagation(P, F, Qd, A, B, ri, ci, vals):
    """``P <- (I + F) P (I + F)^T + Qd`` using the non-zero entries of ``F`` (``F`` = F dt)."""
    n = P.shape[0]
    nnz = 0
    for i in range(n):
        for j in range(n):
            v = F[i, j]
            if v != 0.0:
                ri[nnz] = i
                ci[nnz] = j
                vals[nnz] = v
                nnz += 1
    for i in range(n):
        for j in range(n):
            A[i, j] = P[i, j]
    for q in range(nnz):  # A = P + F P
        r, c, v = ri[q], ci[q], vals[q]
        for j in range(n):
            A[r, j] += v * P[c, j]
    for i in range(n):  # B = A^T = P (I + F)^T
        for j in range(n):
            B[i, j] = A[j, i]
    for i in range(n):
        for j in range(n):
            P[i, j] = B[i, j]
    for q in range(nnz):  # P = (I + F) B
        r, c, v = ri[q], ci[q], vals[q]
        for j in range(n):
            P[r, j] += v * B[c, j]
    for i in range(n):
        for j in range(i, n):
            v = 0.5 * (P[i, j] + P[j, i]) + Qd[i, j]
            P[i, j] = v
            P[j, i] = v


@njit(cache=True)
def _forward_sub(L, B, m, out):
    """``out[:m] = L^-1 B[:m]`` for lower-triangular ``L`` (m x m)."""
    p = B.shape[1]
    for i in range(m):
        li = L[i, i]
        for c in range(p):
            v = B[i, c]
            for q in range(i):
                v -= L[i, q] * out[q, c]
            out[i, c] = v / li


@njit(cache=True)
def _back_sub(L, B, m, out):
    """``out[:m] = L^-T B[:m]`` for lower-triangular ``L`` (m x m)."""
    p = B.shape[1]
    for i in range(m - 1, -1, -1):
        li = L[i, i]
        for c in range(p):
            v = B[i, c]
            for q in range(i + 1, m):
                v -= L[q, i] * out[q, c]
            out[i, c] = v / li


@njit(cache=True)
def _hp(H, P, m, out):
    """``out[:m] = H[:m] P`` skipping the zeros of H."""
    n = P.shape[0]
    for a in range(m):
        for j in range(n):
            out[a, j] = 0.0
        for q in range(n):
            h = H[a, q]
            if h != 0.0:
                for j in range(n):
                    out[a, j] += h * P[q, j]


@njit(cache=True)
def _kalman_update(P, H, R, z, m, x, Kt, G, s, HP, S, L, W, V):
    """Stacked Kalman update with the first ``m`` rows of ``H``, ``R``, ``z``.

    With ``S = H P H^T + R = L L^T`` and ``W = L^-1 H P``: the gain (transposed)
    ``K^T = L^-T W``, ``x = K z``, ``G = S^-1 H``, ``s = S^-1 z`` and
    ``P <- P - K S K^T = P - W^T W`` (a symmetric rank-m downdate: the optimal-gain form of
    the Joseph update, a third of its cost at the IMU rate). Returns False (P unchanged) if
    ``S`` is not positive definite.
    """
    n = P.shape[0]
    _hp(H, P, m, HP)
    for a in range(m):
        for b in range(a + 1):
            v = R[a, b]
            for q in range(n):
                v += HP[a, q] * H[b, q]
            S[a, b] = v
            S[b, a] = v
    for i in range(m):  # Cholesky S = L L^T
        for k in range(i + 1):
            v = S[i, k]
            for q in range(k):
                v -= L[i, q] * L[k, q]
            if i == k:
                if not v > 0.0:
                    return False
                L[i, i] = np.sqrt(v)
            else:
                L[i, k] = v / L[k, k]
    _forward_sub(L, HP, m, W)
    _back_sub(L, W, m, Kt)
    _forward_sub(L, H, m, V)
    _back_sub(L, V, m, G)
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
    for i in range(n):
        for j in range(i, n):
            v = P[i, j]
            for a in range(m):
                v -= W[a, i] * W[a, j]
            P[i, j] = v
            P[j, i] = v
    return True


@njit(cache=True)
def dense_segment(model, t, dth, dv, pos, vel, C, pnom, i_sg, i_sa, gmodel, aupd, q_g, q_a, dyn,
                  decay, qdiag, Fx, Qx, table, seg, post, rates, j, frac, t_end, P, node,
                  node_t, Pf, Pp, Phi, fb, par, ptr, Hs, Ks, Gs, ss, row,
                  hr_ptr, hr_m, hr_r, kinds, ips, fps, vptr, vals, stds, tids, thrs, gyro_psd,
                  streak, recovery, n_nav, check, rw_on, rw_t, rw_v, rw_state, rw_scratch,
                  rw_window, rw_min, rw_bound, lg_t, lg_tid, lg_dof, lg_nis, lg_thr, lg_flags,
                  lg_z, lg_s, status):
    """Run the IMU rows ``j ..`` with ``t[j] <= t_end`` of a dense segment (module docstring):
    one node per row, written at ``node, node + 1, ...`` of the store arrays; update rows from
    ``row``; log records from 0.

    ``status`` (int64[4]) receives (code, nodes written, update rows written, log records);
    the return value is ``(j, frac, fail_time, fail_value, fail_type)``.
    """
    n = P.shape[0]
    n_t = t.shape[0]
    F = np.zeros((n, n))
    Qd = np.zeros((n, n))
    Qg = np.zeros((3, 3))
    Qa = np.zeros((3, 3))
    A = np.empty((n, n))
    B = np.empty((n, n))
    ri = np.empty(n * n, np.int64)
    ci = np.empty(n * n, np.int64)
    fv = np.empty(n * n)
    work = np.empty(STEP_WORK_SHAPE)
    dthc = np.empty(3)
    dvc = np.empty(3)
    w_ib = np.empty(3)
    n_meas_max = 1
    for jj in range(j, n_t):
        n_meas_max = max(n_meas_max, hr_ptr[jj + 1] - hr_ptr[jj])
        if t[jj] > t_end:
            break
    mmax = 3 * n_meas_max
    Hk = np.zeros((mmax, n))
    Rk = np.zeros((mmax, mmax))
    zk = np.zeros(mmax)
    Hm = np.empty((3, n))
    Rm = np.empty((3, 3))
    zm = np.empty(3)
    Sm = np.empty((3, 3))
    HPm = np.empty((3, n))
    x = np.zeros(n)
    Kt = np.empty((mmax, n))
    G = np.empty((mmax, n))
    sv = np.empty(mmax)
    HP = np.empty((mmax, n))
    S = np.empty((mmax, mmax))
    L = np.empty((mmax, mmax))
    W = np.empty((mmax, n))
    V = np.empty((mmax, n))
    any_decay = False
    for i in range(9, n):
        if decay[i] > 0.0:
            any_decay = True
    has_fx = Fx.shape[0] == n
    has_qx = Qx.shape[0] == n
    k_node = node
    n_log = 0
    r = row
    code = OK
    fail_t, fail_v, fail_tid = 0.0, 0.0, -1
    while j < n_t and t[j] <= t_end:
        dt_full = t[j] - t[j - 1]
        a = 1.0 - frac
        dt_s = a * dt_full
        # --- 1. propagate over the interval
        for i in range(n):
            for c in range(n):
                F[i, c] = 0.0
                Qd[i, c] = 0.0
        for i in range(3):
            for c in range(3):
                Qg[i, c] = 0.0
                Qa[i, c] = 0.0
        _model_step(model, pos, vel, C, pnom, dth[j], dv[j], a, dt_s, i_sg, i_sa, gmodel, aupd, F,
                    Qg, Qa, q_g, q_a, dyn, dthc, dvc, work)
        for i in range(3):
            w_ib[i] = dthc[i] / dt_s if dt_s > 0.0 else 0.0
            rates[0, i] = rates[1, i] = w_ib[i]
            rates[2, i] = rates[3, i] = dvc[i] / dt_s if dt_s > 0.0 else 0.0
        if any_decay:  # Gauss-Markov parameters: nominal follows the mean, F gets -1/tau
            for i in range(9, n):
                if decay[i] > 0.0:
                    pnom[i - 9] *= np.exp(-decay[i] * dt_s)
        for i in range(n):
            F[i, i] -= decay[i] * dt_s
            Qd[i, i] = qdiag[i] * dt_s
        for i in range(3):
            for c in range(3):
                Qd[3 + i, 3 + c] += Qa[i, c]
                Qd[6 + i, 6 + c] += Qg[i, c]
        if has_fx:
            for i in range(n):
                for c in range(n):
                    F[i, c] += Fx[i, c] * dt_s
        if has_qx:
            for i in range(n):
                for c in range(n):
                    Qd[i, c] += Qx[i, c] * dt_s
        _first_order_propagation(P, F, Qd, A, B, ri, ci, fv)
        frac = 0.0
        if check:
            fin = pos[0] + pos[1] + pos[2] + vel[0] + vel[1] + vel[2]
            for i in range(n):
                fin += P[i, i]
            if not np.isfinite(fin):
                code = NONFINITE
                fail_t = t[j]
                break
        # --- 2. evaluate and gate the high-rate measurements at this sample
        m_acc = 0
        for e in range(hr_ptr[j], hr_ptr[j + 1]):
            mi = hr_m[e]
            vr = vptr[mi] + hr_r[e]
            window = dt_s if ips[mi, 7] == 1 else 0.0
            d = evaluate_compiled(kinds[mi], ips[mi], fps[mi], vals[vr], stds[vr], vel, C,
                                  pos[0], w_ib, window, gyro_psd, pnom, zm, Hm, Rm)
            if d == 0:
                continue
            zd = zm[:d]
            Hd = Hm[:d]
            Rd = Rm[:d, :d]
            _hp(Hd, P, d, HPm)
            for p in range(d):
                for q in range(d):
                    v = Rd[p, q]
                    for c in range(n):
                        v += HPm[p, c] * Hd[q, c]
                    Sm[p, q] = v
            Sd = Sm[:d, :d]
            nis = gating.nis(Sd, zd)
            tid = tids[mi]
            if rw_on:
                med = health.runaway_push(rw_t, rw_v, rw_state, tid, t[j], nis / d, rw_window,
                                          rw_min, rw_bound, rw_scratch)
                if med >= 0.0:
                    code = RUNAWAY
                    fail_t, fail_v, fail_tid = t[j], med, tid
                    break
            thr = thrs[mi]
            gc = gating.gate_step(streak, tid, t[j], nis, thr, recovery)
            if gc == gating.RECOVER:
                Si = gating.inflate_for(P, Hd, Rd, zd, thr, n_nav)
                for p in range(d):
                    for q in range(d):
                        Sm[p, q] = Si[p, q]
                nis = gating.nis(Sm[:d, :d], zd)
            lg_t[n_log] = t[j]
            lg_tid[n_log] = tid
            lg_dof[n_log] = d
            lg_nis[n_log] = nis
            lg_thr[n_log] = thr
            lg_flags[n_log, 0] = gc != gating.REJECT
            lg_flags[n_log, 1] = gc == gating.RECOVER
            for p in range(3):
                lg_z[n_log, p] = zd[p] if p < d else np.nan
                lg_s[n_log, p] = np.sqrt(max(Sm[p, p], 0.0)) if p < d else np.nan
            n_log += 1
            if gc != gating.REJECT:
                for p in range(d):
                    zk[m_acc + p] = zd[p]
                    for c in range(n):
                        Hk[m_acc + p, c] = Hd[p, c]
                    for q in range(mmax):
                        Rk[m_acc + p, q] = 0.0
                        Rk[q, m_acc + p] = 0.0
                for p in range(d):
                    for q in range(d):
                        Rk[m_acc + p, m_acc + q] = Rd[p, q]
                m_acc += d
        if code != OK:
            break
        for i in range(n):
            for c in range(n):
                Pp[k_node, i, c] = P[i, c]
        # --- 3. stacked update and feedback
        for i in range(n):
            fb[k_node, i] = 0.0
        if m_acc > 0:
            if not _kalman_update(P, Hk, Rk, zk, m_acc, x, Kt, G, sv, HP, S, L, W, V):
                code = NOT_PD
                fail_t = t[j]
                break
            if check and not health.is_positive_definite(P):
                code = NOT_PD
                fail_t = t[j]
                break
            for p in range(m_acc):
                for c in range(n):
                    Hs[r, c] = Hk[p, c]
                    Ks[r, c] = Kt[p, c]
                    Gs[r, c] = G[p, c]
                ss[r] = sv[p]
                r += 1
            for i in range(n):
                fb[k_node, i] = x[i]
            _model_feedback(model, pos, vel, C, pnom, x)
        # --- 4. store the node and the IMU-rate nominal row
        node_t[k_node] = t[j]
        for i in range(n):
            for c in range(n):
                Phi[k_node, i, c] = F[i, c] + (1.0 if i == c else 0.0)
                Pf[k_node, i, c] = P[i, c]
        for i in range(pnom.shape[0]):
            par[k_node, i] = pnom[i]
        ptr[k_node + 1] = r
        store_nav(table, j, pos, vel, C)
        seg[j] = k_node
        post[j] = True
        k_node += 1
        j += 1
    status[0] = code
    status[1] = k_node - node
    status[2] = r - row
    status[3] = n_log
    return j, frac, fail_t, fail_v, fail_tid


class HighRate:
    """The high-rate measurements of one engine run and the calls of :func:`dense_segment`."""

    def __init__(self, measurements: list[Measurement], model, run):
        if not model.high_rate:
            raise ConfigError(f"the {type(model).__name__} process model has no compiled "
                              "high-rate path; build the measurements with high_rate=False",
                              column="measurements", found=[repr(m) for m in measurements])
        layout = model.layout
        specs = []
        for m in measurements:
            spec = m.compiled(layout)
            base = next((c for c in type(m).__mro__ if "compiled" in c.__dict__), None)
            if spec is None or (base is not None and type(m).evaluate is not base.evaluate):
                raise ConfigError(f"{type(m).__name__} has no compiled implementation (its "
                                  "evaluate() is Python); use high_rate=False",
                                  column="measurements", found=repr(m))
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
        self.thrs = np.array([run.gates.threshold(run.gates.probability(m), d)
                              for m, d in zip(measurements, dofs, strict=True)], float)
        self.gyro_psd = np.asarray(model.noise.gyro_psd, float)

    def segment(self, t_end: float, node: int, P: np.ndarray):
        """Run the dense segment up to ``t_end`` from ``node``; returns ``(node, P)`` after it.
        Raises FilterHealthError (after keeping the nodes written) when the segment failed."""
        run, model, store = self.run, self.model, self.run.store
        sched = run.sched
        t = model.t
        j0 = model.j
        j1 = int(np.searchsorted(t, t_end, side="right"))
        n_ev = int(sched.hr_ptr[j1] - sched.hr_ptr[j0])
        store.reserve_rows(3 * n_ev)
        lg = {"time": np.empty(n_ev), "tid": np.empty(n_ev, np.int64),
              "dof": np.empty(n_ev, np.int64), "nis": np.empty(n_ev),
              "threshold": np.empty(n_ev), "flags": np.zeros((n_ev, 2), np.bool_),
              "innov": np.empty((n_ev, 3)), "innov_std": np.empty((n_ev, 3))}
        status = np.zeros(4, np.int64)
        rw = run.runaway
        P = np.array(P, dtype=float, order="C")
        c0 = _time.perf_counter()
        j, frac, fail_t, fail_v, fail_tid = dense_segment(
            *model.high_rate_args(), model.j, model.frac, t_end, P, node,
            store.t, store.Pf, store.Pp, store.Phi, store.fb, store.par, store.ptr, store.H,
            store.K, store.G, store.s, store.n_rows,
            sched.hr_ptr, sched.hr_m, sched.hr_r, self.kinds, self.ips, self.fps, self.vptr,
            self.vals, self.stds, self.tids, self.thrs, self.gyro_psd,
            run.streak, run.recovery, model.n_nav, run.check, rw.enabled, rw.buf_t, rw.buf_v,
            rw.state, rw.scratch, rw.window, rw.min_count, rw.bound,
            lg["time"], lg["tid"], lg["dof"], lg["nis"], lg["threshold"], lg["flags"],
            lg["innov"], lg["innov_std"], status)
        code, n_nodes, n_rows, n_log = (int(v) for v in status)
        run.timing["high_rate"] = run.timing.get("high_rate", 0.0) + _time.perf_counter() - c0
        if n_nodes:
            model.j, model.frac = j, frac
            model.advance_to(float(store.t[node + n_nodes - 1]))
        store.n_rows += n_rows
        store.count = node + n_nodes
        run.log.add_block({"time": lg["time"][:n_log], "tid": lg["tid"][:n_log],
                           "dof": lg["dof"][:n_log], "nis": lg["nis"][:n_log],
                           "threshold": lg["threshold"][:n_log],
                           "accepted": lg["flags"][:n_log, 0].copy(),
                           "recovered": lg["flags"][:n_log, 1].copy(),
                           "innov": lg["innov"][:n_log], "innov_std": lg["innov_std"][:n_log]})
        if code == NONFINITE:
            raise FilterHealthError(f"filter state became non-finite at t = {fail_t:.6f} s "
                                    "(high-rate propagation)", found="NaN/inf in P or nominal")
        if code == NOT_PD:
            raise FilterHealthError(f"covariance is not positive definite at t = {fail_t:.6f} s "
                                    "(high-rate update)", found="Cholesky factorisation failed")
        if code == RUNAWAY:
            raise rw.error(int(fail_tid), run.log.names[int(fail_tid)], fail_t, fail_v)
        return node + n_nodes, P
