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
from numba import njit

from .kernels import _mm

__all__ = ["mbf_backward", "rts_error_state", "smooth"]


@njit(cache=True)
def mbf_backward(Pf, Phi, fb, ptr, H, K, G, s, n_nodes, covariance, xs_plus, xs_minus, Ps):
    """Modified Bryson-Frazier backward pass over nodes ``0 .. n_nodes-1`` (module docstring).

    ``ptr``, ``H``, ``K`` (gain, transposed rows), ``G = S^-1 H`` and ``s = S^-1 z`` are the
    update rows of :class:`insgnss.filter.store.NodeStore`. Writes ``xs_plus``, ``xs_minus``
    (n_nodes, n) and, if ``covariance``, ``Ps`` (n_nodes, n, n).
    """
    n = Pf.shape[1]
    lam = np.zeros(n)
    lt = np.empty(n)
    Lam = np.zeros((n, n))
    Lt = np.empty((n, n))
    T1 = np.empty((n, n))
    T2 = np.empty((n, n))
    m_max = 1
    for k in range(n_nodes):
        m_max = max(m_max, ptr[k + 1] - ptr[k])
    KL = np.empty((m_max, n))
    W = np.empty((m_max, m_max))
    for k in range(n_nodes - 1, -1, -1):
        P = Pf[k]
        for i in range(n):
            v = 0.0
            for j in range(n):
                v += P[i, j] * lam[j]
            xs_plus[k, i] = -v
            xs_minus[k, i] = fb[k, i] - v
        if covariance:
            _mm(P, Lam, T1)
            for i in range(n):
                for j in range(i, n):
                    v = 0.0
                    for q in range(n):
                        v += T1[i, q] * P[q, j]
                    Ps[k, i, j] = P[i, j] - v
                    Ps[k, j, i] = Ps[k, i, j]
        # through the update at k
        r0, r1 = ptr[k], ptr[k + 1]
        m = r1 - r0
        for i in range(n):
            lt[i] = lam[i]
        for r in range(r0, r1):
            c = s[r]
            for i in range(n):
                c += K[r, i] * lam[i]
            for i in range(n):
                lt[i] -= H[r, i] * c
        if covariance:
            for i in range(n):
                for j in range(n):
                    Lt[i, j] = Lam[i, j]
            if m > 0:
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
                    ha = H[r0 + a]
                    ga = G[r0 + a]
                    ka = KL[a]
                    for i in range(n):
                        hi = ha[i]
                        for j in range(n):
                            v = hi * (ga[j] - ka[j]) - ka[i] * ha[j]
                            for b in range(m):
                                v += hi * W[a, b] * H[r0 + b, j]
                            Lt[i, j] += v
        if k > 0:
            F = Phi[k]
            for i in range(n):
                v = 0.0
                for j in range(n):
                    v += F[j, i] * lt[j]
                lam[i] = v
            if covariance:
                _mm(Lt, F, T1)  # Lt Phi
                for i in range(n):
                    for j in range(i, n):
                        v = 0.0
                        for q in range(n):
                            v += F[q, i] * T1[q, j]
                        T2[i, j] = v
                for i in range(n):
                    for j in range(i, n):
                        Lam[i, j] = T2[i, j]
                        Lam[j, i] = T2[i, j]


def smooth(store, n_nodes: int, covariance: bool = True):
    """Run :func:`mbf_backward` on the first ``n_nodes`` nodes of a
    :class:`~insgnss.filter.store.NodeStore`; returns ``(xs_plus, xs_minus, Ps or None)``."""
    n = store.n
    xs_plus = np.zeros((n_nodes, n))
    xs_minus = np.zeros((n_nodes, n))
    Ps = np.empty((n_nodes, n, n)) if covariance else np.empty((1, n, n))
    mbf_backward(store.Pf, store.Phi, store.fb, store.ptr, store.H, store.K, store.G, store.s,
                 n_nodes, bool(covariance), xs_plus, xs_minus, Ps)
    return xs_plus, xs_minus, (Ps if covariance else None)


@njit(cache=True)
def _chol_solve(P, B, L, out):
    """``out = P^-1 B`` for symmetric positive definite P (Cholesky); False if not PD."""
    n = P.shape[0]
    for i in range(n):
        for k in range(i + 1):
            v = P[i, k]
            for q in range(k):
                v -= L[i, q] * L[k, q]
            if i == k:
                if not v > 0.0:
                    return False
                L[i, i] = np.sqrt(v)
            else:
                L[i, k] = v / L[k, k]
    m = B.shape[1]
    for c in range(m):
        for i in range(n):  # forward
            v = B[i, c]
            for q in range(i):
                v -= L[i, q] * out[q, c]
            out[i, c] = v / L[i, i]
        for i in range(n - 1, -1, -1):  # backward
            v = out[i, c]
            for q in range(i + 1, n):
                v -= L[q, i] * out[q, c]
            out[i, c] = v / L[i, i]
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
            for i in range(n):
                v = 0.0
                for k in range(n):
                    v += At[k, i] * xs_minus[e + 1, k]
                xs_plus[e, i] = v
            for i in range(n):
                for k in range(n):
                    D[i, k] = Ps[e + 1, i, k] - Pp[e + 1, i, k]
            # Ps = Pf + A D A^T = Pf + At^T D At
            _mm(D, At, T1)  # D At
            for i in range(n):
                for k in range(i, n):
                    v = 0.0
                    for q in range(n):
                        v += At[q, i] * T1[q, k]
                    Ps[e, i, k] = Pf[e, i, k] + v
            for i in range(n):
                for k in range(i + 1, n):
                    Ps[e, k, i] = Ps[e, i, k]
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
    rts_backward(Pf, np.ascontiguousarray(P_predicted, dtype=float),
                 np.ascontiguousarray(Phi, dtype=float),
                 np.ascontiguousarray(feedback, dtype=float), E, xs_plus, xs_minus, Ps)
    return xs_plus, xs_minus, Ps
