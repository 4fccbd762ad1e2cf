"""Smoother of the closed-loop (feedback) error-state filter: the engine's backward pass.

Why not ``filterpy.kalman.rts_smoother`` as it is
--------------------------------------------------
filterpy's smoother assumes one fixed linear state space: it forms the prediction
``F x(k|k)`` and corrects ``x(k|k) += K (x_s(k+1) - F x(k|k))``. In the closed-loop filter
the state is an *error of a nominal trajectory that changes at every update*: after the
update at node k the estimate ``x(k|k)`` (the feedback ``fb_k``) is folded into the
nominal and the state reset to zero, and the prediction to k+1 refers to the nominal
propagated from that *corrected* nominal. Every filtered state handed to filterpy would be
zero and the feedback jumps would be lost. The backward pass is therefore written in
error-state form (Shin 2005, sec. 3.6; DESIGN.md section 4): with ``x(k|k-1) = 0`` before and
``0`` again after the reset, the smoothed error relative to the pre-feedback nominal is the
one relative to the post-feedback nominal plus the feedback applied,
``xs_minus(k) = xs_plus(k) + fb(k)``.

The engine's backward pass: modified Bryson-Frazier form
--------------------------------------------------------
The engine runs the modified Bryson-Frazier (MBF) form of the fixed-interval smoother (Bierman
1973; Bierman, *Factorization Methods for Discrete Sequential Estimation*, 1977, ch. X), which
gives the same smoothed states and covariances as the Rauch-Tung-Striebel form but needs no
inverse of ``P(k+1|k)`` and costs O(n m) per update and O(n^2) per node for the states (the
covariance recursion, optional, is O(n^3)). That is what makes smoothing affordable at every
IMU sample of the compiled high-rate path. With the adjoint ``lambda`` (``^`` after, ``~``
before the update at node k; ``lambda^_N = 0``, ``Lambda^_N = 0``)::

    xs_plus(k)    = -P(k|k) lambda^_k          Ps(k) = P(k|k) - P(k|k) Lambda^_k P(k|k)
    lambda~_k     = lambda^_k - H^T (S^-1 z + K^T lambda^_k)
    Lambda~_k     = H^T S^-1 H + (I - K H)^T Lambda^_k (I - K H)
    lambda^_{k-1} = Phi_k^T lambda~_k          Lambda^_{k-1} = Phi_k^T Lambda~_k Phi_k

(``z`` the stacked innovation, ``S`` its covariance, ``K`` the gain of the update at k; no
update: ``lambda~ = lambda^``). The smoothed state at node k is the post-feedback nominal
minus ``xs_plus(k)`` (errors are "nominal minus true"). A gate recovery that inflated
``P(k|k-1)`` acts as extra process noise: the recursion uses the gain computed with it.

:func:`rts_error_state` is the RTS form of the same smoother on the stored ``P(k|k)``,
``P(k|k-1)``, ``Phi`` and feedback (``A(k) = P(k|k) Phi(k+1)^T P(k+1|k)^-1``,
``xs_plus(k) = A(k) xs_minus(k+1)``, ``Ps(k) = P(k|k) + A(k) (Ps(k+1) - P(k+1|k)) A(k)^T``), for
users of the stored quantities (e.g. an EM estimate of the noise needs the RTS gains ``A``)
and as the cross-check of the engine's pass.

IMU-rate output
---------------
Between nodes ``k`` and ``k+1`` the stored forward nominal runs from the post-feedback
state at ``k`` to the pre-feedback state at ``k+1``, so its smoothed error goes from
``xs_plus(k)`` to ``xs_minus(k+1)``; both ends and the smoothed variances are interpolated
linearly in time and applied to every stored sample. A sample that sits exactly on a node
holds the post-feedback nominal and takes ``xs_plus`` of that node. Epochs are at most
``epoch_interval`` (1 s default) apart, over which the error of an aided or briefly coasting
INS is close to linear; in high-rate segments every IMU sample is a node.
"""

from __future__ import annotations

import numpy as np

from ..aot import entry
from ..columns import STD_COLS  # noqa: F401  (the filter tables' std columns, here as before)
from ..jit import njit
from .linalg import _mm, cholesky_into, congruence_t, matvec_t, tri_solve

__all__ = ["mbf_backward", "rts_error_state", "smooth"]


@njit(cache=True, inline="always")
def _adjoint_through_update(lam, lt, H_ptr, H_col, H_val, K, s, r0, r1, n):
    """``lambda~ = lambda^ - H^T (S^-1 z + K^T lambda^)`` for the update rows r0 .. r1-1 (``H``
    by its non-zeros): the adjoint part of :func:`_through_update`, inlined into the
    per-sample loop of :func:`_hr_backward`."""
    for i in range(n):
        lt[i] = lam[i]
    for r in range(r0, r1):
        c = s[r]
        for i in range(n):
            c += K[r, i] * lam[i]
        for q in range(H_ptr[r], H_ptr[r + 1]):
            lt[H_col[q]] -= H_val[q] * c


@njit(cache=True, inline="always")
def _adjoint_back_sparse(lam, lt, hr_F, h, f_ptr, f_col, f_act, n):
    """``lambda^ = Phi^T lambda~`` for ``Phi = I + F`` with F given at its pattern (values
    ``hr_F[h]``): the adjoint part of :func:`_back_through_sparse`, inlined likewise."""
    for i in range(n):
        lam[i] = lt[i]
    for a in range(f_act.shape[0]):
        i = f_act[a]
        for q in range(f_ptr[a], f_ptr[a + 1]):
            lam[f_col[q]] += hr_F[h, q] * lt[i]


@njit(cache=True)
def _through_update(lam, lt, Lam, Lt, H_ptr, H_col, H_val, K, G, s, r0, r1, covariance, KL, W, Hd, n=-1):
    """``lambda~ = lambda^ - H^T (S^-1 z + K^T lambda^)`` and (``covariance``)
    ``Lambda~ = H^T S^-1 H + (I - K H)^T Lambda^ (I - K H)`` for the update rows r0 .. r1-1
    (``H`` by its non-zeros, :mod:`.store`: ``H^T c`` touches only them; the covariance
    recursion expands the rows into the scratch ``Hd`` (m, n))."""
    if n < 0:
        n = lam.shape[0]
    m = r1 - r0
    _adjoint_through_update(lam, lt, H_ptr, H_col, H_val, K, s, r0, r1, n)
    if not covariance:
        return
    for i in range(n):
        for j in range(n):
            Lt[i, j] = Lam[i, j]
    if m == 0:
        return
    for a in range(m):
        for j in range(n):
            Hd[a, j] = 0.0
        for q in range(H_ptr[r0 + a], H_ptr[r0 + a + 1]):
            Hd[a, H_col[q]] = H_val[q]
    # M^T Lam M = Lam - H^T (K^T Lam) - (K^T Lam)^T H + H^T (K^T Lam K) H
    for a in range(m):
        for j in range(n):
            v = 0.0
            for i in range(n):
                v += K[r0 + a, i] * Lam[i, j]
            KL[a, j] = v
    for a in range(m):
        for b in range(m):
            v = 0.0
            for j in range(n):
                v += KL[a, j] * K[r0 + b, j]
            W[a, b] = v
    for a in range(m):
        ha = Hd[a]
        ga = G[r0 + a]
        ka = KL[a]
        for i in range(n):
            hi = ha[i]
            for j in range(n):
                v = hi * (ga[j] - ka[j]) - ka[i] * ha[j]
                for b in range(m):
                    v += hi * W[a, b] * Hd[b, j]
                Lt[i, j] += v


@njit(cache=True)
def _back_through_sparse(lam, lt, Lam, Lt, hr_F, h, f_ptr, f_col, f_act, covariance, C1, n=-1):
    """``lambda^ = Phi^T lambda~``, ``Lambda^ = Phi^T Lambda~ Phi`` for ``Phi = I + F`` with F
    given at its pattern (values ``hr_F[h]``)."""
    if n < 0:
        n = lam.shape[0]
    _adjoint_back_sparse(lam, lt, hr_F, h, f_ptr, f_col, f_act, n)
    if not covariance:
        return
    Fv = hr_F[h]
    for i in range(n):  # C1 = Lt F
        for j in range(n):
            C1[i, j] = 0.0
    for a in range(f_act.shape[0]):
        i = f_act[a]
        for q in range(f_ptr[a], f_ptr[a + 1]):
            c, v = f_col[q], Fv[q]
            for r in range(n):
                C1[r, c] += v * Lt[r, i]
    for i in range(n):
        for j in range(n):
            Lam[i, j] = Lt[i, j] + C1[i, j] + C1[j, i]
    for a in range(f_act.shape[0]):  # + F^T C1
        i = f_act[a]
        for q in range(f_ptr[a], f_ptr[a + 1]):
            c, v = f_col[q], Fv[q]
            for r in range(n):
                Lam[c, r] += v * C1[i, r]


@njit(cache=True)
def _back_through_dense(lam, lt, Lam, Lt, F, covariance, T1):
    """``lambda^ = Phi^T lambda~``, ``Lambda^ = Phi^T Lambda~ Phi`` for a dense ``Phi``."""
    matvec_t(F, lt, lam)
    if not covariance:
        return
    congruence_t(F, Lt, T1, Lam)  # Phi^T Lt Phi


@njit(cache=True)
def _hr_backward(
    h0,
    h1,
    lam,
    lt,
    Lam,
    Lt,
    H_ptr,
    H_col,
    H_val,
    K,
    G,
    s,
    hr_r0,
    hr_r1,
    hr_F,
    f_ptr,
    f_col,
    f_act,
    covariance,
    KL,
    W,
    Hd,
    T1,
    LT,
    n,
):
    """The adjoint back through the high-rate samples ``h1-1 .. h0``; ``LT[h - h0]`` keeps
    each ``lambda~``."""
    for h in range(h1 - 1, h0 - 1, -1):
        if covariance:
            _through_update(
                lam, lt, Lam, Lt, H_ptr, H_col, H_val, K, G, s, hr_r0[h], hr_r1[h], covariance, KL, W, Hd, n
            )
        else:  # the adjoint only (no call per sample: the foot INS's every IMU sample)
            _adjoint_through_update(lam, lt, H_ptr, H_col, H_val, K, s, hr_r0[h], hr_r1[h], n)
        for i in range(n):
            LT[h - h0, i] = lt[i]
        if covariance:
            _back_through_sparse(lam, lt, Lam, Lt, hr_F, h, f_ptr, f_col, f_act, covariance, T1, n)
        else:
            _adjoint_back_sparse(lam, lt, hr_F, h, f_ptr, f_col, f_act, n)


@njit(cache=True)
def _hr_forward(
    x, h0, h1, hr_F, hr_Q, hr_fb, hr_ppi, hr_Pp, LT, f_ptr, f_col, f_act, q_row, q_col, xs_hr, xm, n
):
    """The smoothed errors of the high-rate samples ``h0 .. h1-1`` rebuilt forwards from
    ``x`` (the smoothed error after the node before them; overwritten)."""
    for h in range(h0, h1):
        Fv = hr_F[h]
        for i in range(n):
            xm[i] = x[i]
        for a in range(f_act.shape[0]):
            i = f_act[a]
            for q in range(f_ptr[a], f_ptr[a + 1]):
                xm[i] += Fv[q] * x[f_col[q]]
        if hr_ppi[h] >= 0:
            Pp = hr_Pp[hr_ppi[h]]
            for i in range(n):
                v = 0.0
                for j in range(n):
                    v += Pp[i, j] * LT[h - h0, j]
                xm[i] = -v
        else:
            for q in range(q_row.shape[0]):
                xm[q_row[q]] -= hr_Q[h, q] * LT[h - h0, q_col[q]]
        for i in range(n):
            x[i] = xm[i] - hr_fb[h, i]
            xs_hr[h, i] = x[i]


@entry
@njit(cache=True)
def _mbf_backward15(
    Pf,
    Phi,
    fb,
    r0,
    r1,
    H_ptr,
    H_col,
    H_val,
    K,
    G,
    s,
    n_nodes,
    seg0,
    seg1,
    n_hr,
    hr_F,
    hr_Q,
    hr_fb,
    hr_r0,
    hr_r1,
    hr_ppi,
    hr_Pp,
    f_ptr,
    f_col,
    f_act,
    q_row,
    q_col,
    covariance,
    xs_plus,
    xs_minus,
    Ps,
    xs_hr,
):
    """:func:`mbf_backward` of the 15-state model with the dimension a compile-time constant,
    so that LLVM unrolls the per-sample loops (a separate entry point: a job compiles only the
    specialisation it runs, :func:`smooth` picks it)."""
    mbf_backward(
        Pf,
        Phi,
        fb,
        r0,
        r1,
        H_ptr,
        H_col,
        H_val,
        K,
        G,
        s,
        n_nodes,
        seg0,
        seg1,
        n_hr,
        hr_F,
        hr_Q,
        hr_fb,
        hr_r0,
        hr_r1,
        hr_ppi,
        hr_Pp,
        f_ptr,
        f_col,
        f_act,
        q_row,
        q_col,
        covariance,
        xs_plus,
        xs_minus,
        Ps,
        xs_hr,
        15,
    )


@entry
@njit(cache=True)
def mbf_backward(
    Pf,
    Phi,
    fb,
    r0,
    r1,
    H_ptr,
    H_col,
    H_val,
    K,
    G,
    s,
    n_nodes,
    seg0,
    seg1,
    n_hr,
    hr_F,
    hr_Q,
    hr_fb,
    hr_r0,
    hr_r1,
    hr_ppi,
    hr_Pp,
    f_ptr,
    f_col,
    f_act,
    q_row,
    q_col,
    covariance,
    xs_plus,
    xs_minus,
    Ps,
    xs_hr,
    n,
):
    """Modified Bryson-Frazier backward pass (module docstring) over the nodes
    ``0 .. n_nodes-1`` and the high-rate samples ``0 .. n_hr-1`` of a
    :class:`~insgnss.filter.store.NodeStore`.

    At the nodes: ``xs_plus``, ``xs_minus`` (n_nodes, n) and, if ``covariance``, ``Ps``.
    At the high-rate samples (no stored covariance): ``lambda~`` is kept through each segment
    and the smoothed errors are rebuilt forwards from the node before it,
    ``xs_minus(i) = Phi_i xs_plus(i-1) - Qd_i lambda~_i`` (from ``P(i|i-1) = Phi_i P(i-1|i-1)
    Phi_i^T + Qd_i``; at a sample whose ``P(i|i-1)`` a gate recovery inflated, stored in
    ``hr_Pp``: ``xs_minus(i) = -P(i|i-1) lambda~_i``), ``xs_plus(i) = xs_minus(i) - fb(i)``,
    into ``xs_hr`` (n_hr, n). ``n`` is the state dimension ``Pf.shape[1]`` (a compile-time
    constant when called from :func:`_mbf_backward15`).
    """
    lam = np.zeros(n)
    lt = np.empty(n)
    Lam = np.zeros((n, n))
    Lt = np.empty((n, n))
    T1 = np.empty((n, n))
    T2 = np.empty((n, n))
    m_max = 1
    for k in range(n_nodes):
        m_max = max(m_max, r1[k] - r0[k])
    for h in range(n_hr):
        m_max = max(m_max, hr_r1[h] - hr_r0[h])
    KL = np.empty((m_max, n))
    W = np.empty((m_max, m_max))
    Hd = np.empty((m_max, n))
    seg_max = 1
    for k in range(n_nodes):
        seg_max = max(seg_max, seg1[k] - seg0[k])
    tail0 = seg1[n_nodes - 1]
    seg_max = max(seg_max, n_hr - tail0)
    LT = np.empty((seg_max, n))  # lambda~ of the samples of the pending segment
    pend0, pend1 = 0, 0
    x = np.empty(n)
    xm = np.empty(n)

    # trailing high-rate samples after the last node (a stopped run): lambda^ = 0 at the end
    if n_hr > tail0:
        _hr_backward(
            tail0,
            n_hr,
            lam,
            lt,
            Lam,
            Lt,
            H_ptr,
            H_col,
            H_val,
            K,
            G,
            s,
            hr_r0,
            hr_r1,
            hr_F,
            f_ptr,
            f_col,
            f_act,
            covariance,
            KL,
            W,
            Hd,
            T1,
            LT,
            n,
        )
        pend0, pend1 = tail0, n_hr
    for k in range(n_nodes - 1, -1, -1):
        P = Pf[k]
        for i in range(n):
            v = 0.0
            for j in range(n):
                v += P[i, j] * lam[j]
            xs_plus[k, i] = -v
            xs_minus[k, i] = fb[k, i] - v
        if covariance:
            congruence_t(P, Lam, T1, T2)  # P Lam P (P symmetric)
            for i in range(n):
                for j in range(n):
                    Ps[k, i, j] = P[i, j] - T2[i, j]
        if pend1 > pend0:  # rebuild the smoothed errors of the segment after node k
            for i in range(n):
                x[i] = xs_plus[k, i]
            _hr_forward(
                x,
                pend0,
                pend1,
                hr_F,
                hr_Q,
                hr_fb,
                hr_ppi,
                hr_Pp,
                LT,
                f_ptr,
                f_col,
                f_act,
                q_row,
                q_col,
                xs_hr,
                xm,
                n,
            )
            pend0, pend1 = 0, 0
        _through_update(
            lam, lt, Lam, Lt, H_ptr, H_col, H_val, K, G, s, r0[k], r1[k], covariance, KL, W, Hd, n
        )
        if k > 0:
            _back_through_dense(lam, lt, Lam, Lt, Phi[k], covariance, T1)
            if seg1[k] > seg0[k]:  # the high-rate samples between node k-1 and k
                _hr_backward(
                    seg0[k],
                    seg1[k],
                    lam,
                    lt,
                    Lam,
                    Lt,
                    H_ptr,
                    H_col,
                    H_val,
                    K,
                    G,
                    s,
                    hr_r0,
                    hr_r1,
                    hr_F,
                    f_ptr,
                    f_col,
                    f_act,
                    covariance,
                    KL,
                    W,
                    Hd,
                    T1,
                    LT,
                    n,
                )
                pend0, pend1 = seg0[k], seg1[k]


def smooth(store, n_nodes: int, covariance: bool = True, pattern=None):
    """Run :func:`mbf_backward` on the first ``n_nodes`` nodes and all high-rate samples of a
    :class:`~insgnss.filter.store.NodeStore` (``pattern``: the process model's F / Qd pattern,
    :meth:`~insgnss.filter.strapdown_model.StrapdownModel.f_pattern`, when there are high-rate
    samples); returns ``(xs_plus, xs_minus, Ps or None, xs_hr)``."""
    n = store.n
    xs_plus = np.zeros((n_nodes, n))
    xs_minus = np.zeros((n_nodes, n))
    Ps = np.empty((n_nodes, n, n)) if covariance else np.empty((1, n, n))
    n_hr = store.hr_count
    xs_hr = np.zeros((n_hr, n))
    if pattern is None:
        e = np.zeros(0, np.int64)
        pattern = (np.zeros(1, np.int64), e, e, e, e)
    args = (
        store.Pf,
        store.Phi,
        store.fb,
        store.r0,
        store.r1,
        store.H_ptr,
        store.H_col,
        store.H_val,
        store.K,
        store.G,
        store.s,
        n_nodes,
        store.seg0,
        store.seg1,
        n_hr,
        store.hr_F,
        store.hr_Q,
        store.hr_fb,
        store.hr_r0,
        store.hr_r1,
        store.hr_ppi,
        store.hr_Pp,
        *pattern,
        bool(covariance),
        xs_plus,
        xs_minus,
        Ps,
        xs_hr,
    )
    if n == 15:
        _mbf_backward15(*args)
    else:
        mbf_backward(*args, n)
    return xs_plus, xs_minus, (Ps if covariance else None), xs_hr


@njit(cache=True)
def _chol_solve(P, B, L, out):
    """``out = P^-1 B`` for symmetric positive definite P (Cholesky); False if not PD."""
    n = P.shape[0]
    if not cholesky_into(P, L, n):
        return False
    tri_solve(L, B, n, out, False)
    tri_solve(L, out, n, out, True)
    return True


@njit(cache=True)
def rts_backward(Pf, Pp, Phi, fb, n_ep, xs_plus, xs_minus, Ps):
    """Backward pass of the RTS smoother in closed-loop error-state form.

    For epochs ``e = 0 .. n_ep-1`` with filtered covariance ``Pf[e] = P(e|e)``, predicted
    ``Pp[e] = P(e|e-1)``, transition ``Phi[e]`` from ``e-1`` to ``e`` and the feedback
    ``fb[e]`` (the filtered error estimate removed from the nominal at ``e``):

    - ``xs_plus[e]`` is the smoothed error relative to the corrected (post-feedback) nominal
      at ``e``; ``xs_minus[e] = xs_plus[e] + fb[e]`` the same relative to the pre-feedback
      nominal, which is what the forward prediction from ``e-1`` refers to;
    - ``A = P(e|e) Phi[e+1]^T P(e+1|e)^-1``, ``xs_plus[e] = A xs_minus[e+1]`` (the filtered
      error at ``e`` after the reset is zero and so is its prediction),
      ``Ps[e] = P(e|e) + A (Ps[e+1] - P(e+1|e)) A^T``.

    Returns the number of epochs where ``P(e+1|e)`` was not positive definite (skipped:
    the smoothed values there are the filtered ones).
    """
    n = Pf.shape[1]
    At = np.empty((n, n))
    B = np.empty((n, n))
    L = np.empty((n, n))
    D = np.empty((n, n))
    T1 = np.empty((n, n))
    bad = 0
    for i in range(n):
        xs_plus[n_ep - 1, i] = 0.0
        xs_minus[n_ep - 1, i] = fb[n_ep - 1, i]
        for k in range(n):
            Ps[n_ep - 1, i, k] = Pf[n_ep - 1, i, k]
    for e in range(n_ep - 2, -1, -1):
        # A^T = Pp^-1 (Phi Pf)   (Pf, Pp symmetric)
        _mm(Phi[e + 1], Pf[e], B)
        if not _chol_solve(Pp[e + 1], B, L, At):
            bad += 1
            for i in range(n):
                xs_plus[e, i] = 0.0
                for k in range(n):
                    Ps[e, i, k] = Pf[e, i, k]
        else:
            matvec_t(At, xs_minus[e + 1], xs_plus[e])
            for i in range(n):
                for k in range(n):
                    D[i, k] = Ps[e + 1, i, k] - Pp[e + 1, i, k]
            # Ps = Pf + A D A^T = Pf + At^T D At
            congruence_t(At, D, T1, B)
            for i in range(n):
                for k in range(n):
                    Ps[e, i, k] = Pf[e, i, k] + B[i, k]
        for i in range(n):
            xs_minus[e, i] = xs_plus[e, i] + fb[e, i]
    return bad


def rts_error_state(P_filtered, P_predicted, Phi, feedback):
    """Backward pass of the closed-loop error-state RTS smoother (module docstring).

    Parameters
    ----------
    P_filtered, P_predicted : (E, n, n) arrays
        ``P(k|k)`` and ``P(k|k-1)`` (``P_predicted[0]`` unused).
    Phi : (E, n, n) array
        ``Phi[k]`` propagates the error from node k-1 to k (``Phi[0]`` unused).
    feedback : (E, n) array
        Error estimate fed back (removed from the nominal) at each node.

    Returns
    -------
    xs_plus, xs_minus : (E, n) arrays
        Smoothed errors relative to the post- and pre-feedback nominal at each node.
    Ps : (E, n, n) array
        Smoothed covariances.
    """
    Pf = np.ascontiguousarray(P_filtered, dtype=float)
    E, n = Pf.shape[0], Pf.shape[1]
    xs_plus = np.zeros((E, n))
    xs_minus = np.zeros((E, n))
    Ps = np.empty_like(Pf)
    rts_backward(
        Pf,
        np.ascontiguousarray(P_predicted, dtype=float),
        np.ascontiguousarray(Phi, dtype=float),
        np.ascontiguousarray(feedback, dtype=float),
        E,
        xs_plus,
        xs_minus,
        Ps,
    )
    return xs_plus, xs_minus, Ps
