"""Small dense linear algebra of the compiled filter code (numba): explicit loops, fast for
n <= 30 and quick to compile (slice assignments such as ``A[:, :] = B`` are avoided on purpose:
each costs seconds of compilation). One implementation each, shared by the strapdown kernels,
the high-rate path, gating, health checks and the smoother.

Functions with an optional dimension argument take it from a caller that compiled it as a
constant (``numba.literally``, the high-rate path and the smoother): loops with constant bounds
are unrolled and vectorised by LLVM, 2-3 times faster than with bounds read from the arrays.

The kernels a run calls use these (and no ``@``, ``np.dot`` or ``np.linalg`` on arrays): numba
compiles those to BLAS / LAPACK calls through scipy, and the first such call of a run imports
``scipy.linalg`` (0.12-0.15 s) for products of 3 to 30 rows that loops do as fast."""

from __future__ import annotations

import numpy as np

from ..jit import njit


@njit(cache=True)
def cholesky_into(A, L, m):
    """Cholesky factor ``L`` (lower) of the leading ``m x m`` block of the symmetric ``A``;
    False (L partly written) if it is not positive definite."""
    for i in range(m):
        for k in range(i + 1):
            v = A[i, k]
            for q in range(k):
                v -= L[i, q] * L[k, q]
            if i == k:
                if not v > 0.0:
                    return False
                L[i, i] = np.sqrt(v)
            else:
                L[i, k] = v / L[k, k]
    return True


@njit(cache=True)
def _copy(src, dst):
    """``dst[...] = src`` for 2-D arrays of equal shape."""
    for i in range(src.shape[0]):
        for k in range(src.shape[1]):
            dst[i, k] = src[i, k]


@njit(cache=True)
def _fill(a, v):
    """``a[...] = v`` for a 2-D array."""
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            a[i, k] = v


@njit(cache=True)
def _mm(A, B, out, skip_zeros=True):
    """``out = A @ B`` (out must not alias A or B), skipping the zeros of A unless
    ``skip_zeros`` is False (then every term counts, as in BLAS: a NaN or an infinity of B
    propagates). The inner loop runs along a row of ``B`` and of ``out`` (1-D views: it
    vectorises); each element is summed in the order of ``j`` either way."""
    n, m = A.shape
    p = B.shape[1]
    for i in range(n):
        o = out[i]
        for k in range(p):
            o[k] = 0.0
        for j in range(m):
            a = A[i, j]
            if skip_zeros and a == 0.0:
                continue
            b = B[j]
            for k in range(p):
                o[k] += a * b[k]


@njit(cache=True)
def matmul(A, B):
    """``A @ B`` (a new array; every term, as BLAS: :func:`_mm` without skipping zeros)."""
    out = np.empty((A.shape[0], B.shape[1]))
    _mm(A, B, out, False)
    return out


@njit(cache=True)
def matmul_bt(A, B):
    """``A @ B.T`` (a new array): ``B`` transposed into a copy first, so that the inner loop
    runs along rows and vectorises (a dot product per element would be a floating-point
    reduction, which LLVM keeps in order)."""
    return matmul(A, transpose(B))


@njit(cache=True)
def transpose(A):
    """``A.T`` as a new C-ordered array."""
    p, m = A.shape
    out = np.empty((m, p))
    for j in range(p):
        for k in range(m):
            out[k, j] = A[j, k]
    return out


@njit(cache=True)
def congruence_transposed(A, P):
    """``(A P A^T)^T`` for a sparse ``A`` (a transition matrix, ``I - K H``: mostly zeros),
    computed as ``A (A P)^T`` with both products skipping the zeros of ``A``: a fraction of
    the dense cost. Element ``[i, j]`` is the sum ``matmul_bt(matmul(A, P), A)`` forms at
    ``[j, i]``, term by term in the same order (a zero term changes no finite sum): the
    result is exactly the transpose of that product, which a caller symmetrizing it
    (``0.5 (X + X^T)``) cannot tell from the product itself."""
    n = A.shape[0]
    AP = np.empty((n, P.shape[1]))
    _mm(A, P, AP)
    out = np.empty((n, n))
    _mm(A, transpose(AP), out)
    return out


@njit(cache=True)
def innovation_covariance(H, P, R):
    """``S = H P H^T + R`` (a new array) as ``matmul_bt(matmul(H, P), H) + R`` forms it, ``H P``
    skipping the zeros of ``H`` (the same sums): the Kalman update's and the smoother record's
    ``S``. The gate and the high-rate path form the exactly symmetric one
    (:func:`_innovation_cov`)."""
    m, n = H.shape
    HP = np.empty((m, n))
    _mm(H, P, HP)
    return matmul_bt(HP, H) + R


@njit(cache=True)
def symmetrized_transposed_sum(Y, W):
    """``(X + X^T) / 2`` of ``X = (Y + W)^T`` (a new array), each element as numpy's
    ``0.5 * (X + X.T)`` forms it from ``X``: exactly symmetric. For the congruences of
    :func:`congruence_transposed` (``Y``) plus a transposed term."""
    n = Y.shape[0]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            v = 0.5 * ((Y[j, i] + W[j, i]) + (Y[i, j] + W[i, j]))
            out[i, j] = v
            out[j, i] = v
    return out


@njit(cache=True)
def matvec(A, x):
    """``A @ x`` (a new vector)."""
    n, m = A.shape
    out = np.empty(n)
    for i in range(n):
        v = 0.0
        for j in range(m):
            v += A[i, j] * x[j]
        out[i] = v
    return out


@njit(cache=True)
def inverse(A):
    """``A^-1`` by Gauss-Jordan elimination with partial pivoting (LAPACK's ``getrf/getri``
    pivoting, to rounding); raises ``LinAlgError`` for an exactly singular ``A``, as
    ``np.linalg.inv``."""
    n = A.shape[0]
    W = np.empty((n, n))
    X = np.zeros((n, n))
    for i in range(n):
        X[i, i] = 1.0
        for k in range(n):
            W[i, k] = A[i, k]
    for c in range(n):
        piv, big = c, abs(W[c, c])
        for r in range(c + 1, n):
            if abs(W[r, c]) > big:
                piv, big = r, abs(W[r, c])
        if not big > 0.0:
            raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
        if piv != c:
            for k in range(n):
                W[c, k], W[piv, k] = W[piv, k], W[c, k]
                X[c, k], X[piv, k] = X[piv, k], X[c, k]
        d = 1.0 / W[c, c]
        for k in range(n):
            W[c, k] *= d
            X[c, k] *= d
        for r in range(n):
            if r != c:
                f = W[r, c]
                if f != 0.0:
                    for k in range(n):
                        W[r, k] -= f * W[c, k]
                        X[r, k] -= f * X[c, k]
    return X


@njit(cache=True)
def _sparse(A, ri, ci, vals):
    """Non-zero entries of A into (ri, ci, vals); returns their number."""
    k = 0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            v = A[i, j]
            if v != 0.0:
                ri[k] = i
                ci[k] = j
                vals[k] = v
                k += 1
    return k


@njit(cache=True)
def _spmm(ri, ci, vals, nnz, X, out):
    """``out = A @ X`` for sparse A given by its entries (the inner loop along 1-D row views,
    which vectorises: a sixth off the discretisation of a 25-state segment)."""
    _fill(out, 0.0)
    p = X.shape[1]
    for q in range(nnz):
        o = out[ri[q]]
        x = X[ci[q]]
        a = vals[q]
        for k in range(p):
            o[k] += a * x[k]


@njit(cache=True)
def _mmspt(X, ri, ci, vals, nnz, out):
    """``out = X @ A^T`` for sparse A given by its entries."""
    _fill(out, 0.0)
    m = X.shape[0]
    for q in range(nnz):
        r, c, a = ri[q], ci[q], vals[q]
        for i in range(m):
            out[i, r] += X[i, c] * a


@njit(cache=True)
def tri_solve(L, B, m, out, transpose, p=-1):
    """``out[:m] = L^-1 B[:m]`` (``transpose``: ``L^-T B[:m]``) for lower-triangular ``L``
    (m x m), by row operations (``out`` may be ``B``); ``p``: the columns (default all; a
    compile-time constant from the caller lets LLVM unroll the rows)."""
    if p < 0:
        p = B.shape[1]
    for ii in range(m):
        i = m - 1 - ii if transpose else ii
        for c in range(p):
            out[i, c] = B[i, c]
        q0, q1 = (i + 1, m) if transpose else (0, i)
        for q in range(q0, q1):
            lq = L[q, i] if transpose else L[i, q]
            for c in range(p):
                out[i, c] -= lq * out[q, c]
        li = 1.0 / L[i, i]
        for c in range(p):
            out[i, c] *= li


@njit(cache=True)
def matvec_t(A, x, out):
    """``out = A^T x``."""
    n, p = A.shape
    for i in range(p):
        v = 0.0
        for j in range(n):
            v += A[j, i] * x[j]
        out[i] = v


@njit(cache=True)
def hp_rows(H, P, m, HP, n):
    """``HP = H P`` for the first ``m`` rows of ``H``, skipping its zeros (a ZUPT or GNSS row
    selects a few states)."""
    for a in range(m):
        for j in range(n):
            HP[a, j] = 0.0
        for q in range(n):
            h = H[a, q]
            if h != 0.0:
                for j in range(n):
                    HP[a, j] += h * P[q, j]


@njit(cache=True)
def _innovation_cov(H, P, R, m, HP, S, n=-1):
    """``HP = H P`` and ``S = H P H^T + R`` for the first ``m`` rows (``n``: the state
    dimension, default from ``P``)."""
    if n < 0:
        n = P.shape[0]
    hp_rows(H, P, m, HP, n)
    s_block(H, R, HP, 0, m, S, n)


@njit(cache=True)
def s_block(H, R, HP, o0, o1, S, n):
    """The symmetric block ``S[o0:o1, o0:o1] = H P H^T + R`` of the rows ``o0 .. o1-1`` from
    ``HP = H P``, skipping the zeros of ``H``."""
    for a in range(o0, o1):
        for b in range(o0, a + 1):
            v = R[a, b]
            for q in range(n):
                h = H[b, q]
                if h != 0.0:
                    v += HP[a, q] * h
            S[a, b] = v
            S[b, a] = v


@njit(cache=True)
def congruence_t(A, X, T1, out):
    """``out = A^T X A`` for symmetric ``X`` (``T1``: scratch for ``X A``); symmetric result."""
    n = A.shape[0]
    _mm(X, A, T1)
    for i in range(n):
        for j in range(i, n):
            v = 0.0
            for q in range(n):
                v += A[q, i] * T1[q, j]
            out[i, j] = v
            out[j, i] = v
