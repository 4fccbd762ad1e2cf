"""Compiled Kalman predict and update of the engine's general (non high-rate) epochs.

The engine propagates ``x, P`` and applies the stacked update of the measurements accepted at
an epoch. Those steps were filterpy's ``predict`` and ``update`` called from Python at every
epoch; on a car drive (about 5,000 GNSS epochs) their per-call overhead (argument checks,
reshapes, temporaries), not the arithmetic of a 15-21 state filter, dominated the filter's
time. The two functions below are the same arithmetic, compiled, with the products as loops
(:mod:`.linalg`; no BLAS or LAPACK call, whose first use imports ``scipy.linalg``):

- :func:`predict`: ``x = F x``, ``P = F P F^T + Q``;
- :func:`update`: ``y = z - H x``, ``S = H P H^T + R``, ``K = P H^T S^-1`` (explicit
  inverse, like filterpy: Gauss-Jordan with partial pivoting), ``x = x + K y`` and the Joseph form
  ``P = (I - K H) P (I - K H)^T + K R K^T``.

Both return ``P`` symmetrized, ``(P + P^T) / 2``, bit for bit as the engine formed it after
the plain products (so it does not again). The products skip the zeros of the sparse factor:
the transition matrix of predict, ``H`` and ``I - K H`` of the update (a GNSS or NHC row
touches a few of 15-25 states): at 25 states about 30 % off the predict and 20 % off the
update; a zero term changes no finite sum, and the congruences are formed transposed
(:func:`.linalg.congruence_transposed`) so that every element is the same sum in the same
order as before.

They agree with ``filterpy.kalman.predict`` / ``update`` (and ``KalmanFilter``) to rounding
(tests/test_filter_kalman.py checks 1e-12 on random cases). filterpy stays the reference:
``FilterConfig.kalman = "filterpy"`` (``[filter] kalman = "filterpy"``) runs the engine
through it instead (:func:`backend`).
"""

from __future__ import annotations

import numpy as np

from ..aot import entry
from ..errors import FilterHealthError
from ..jit import njit
from .linalg import (
    cholesky_into,
    congruence_transposed,
    innovation_covariance,
    inverse,
    matmul,
    matmul_bt,
    matvec,
    symmetrized_transposed_sum,
    transpose,
    tri_solve,
)

__all__ = ["KALMAN_BACKENDS", "as_f64", "backend", "predict", "smoother_record", "update"]

#: values of ``FilterConfig.kalman``
KALMAN_BACKENDS = ("compiled", "filterpy")


@entry
@njit(cache=True)
def _predict(x, P, F, Q):
    x1 = matvec(F, x)
    Y = congruence_transposed(F, P)  # (F P F^T)^T, skipping the zeros of F
    # F P F^T + Q = (Y + Q^T)^T, symmetrized as numpy forms it
    return x1, symmetrized_transposed_sum(Y, transpose(Q))


@entry
@njit(cache=True)
def _update(x, P, z, R, H):
    n = x.shape[0]
    y = z - matvec(H, x)
    S = innovation_covariance(H, P, R)
    K = matmul(matmul_bt(P, H), inverse(S))
    x1 = x + matvec(K, y)
    I_KH = np.eye(n) - matmul(K, H)
    Y = congruence_transposed(I_KH, P)  # ((I - K H) P (I - K H)^T)^T: I - K H is sparse
    W = matmul_bt(K, matmul(K, R))  # (K R K^T)^T
    return x1, symmetrized_transposed_sum(Y, W)


_F64 = np.dtype(np.float64)


def as_f64(a):
    """``np.ascontiguousarray(a, dtype=float64)``; an array that already is one is returned as
    it is without the call (a microsecond each, four or five per epoch)."""
    if type(a) is np.ndarray and a.dtype is _F64 and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=np.float64)


def predict(x, P, F, Q):
    """``x = F x``, ``P = F P F^T + Q`` (filterpy's ``predict`` without control input).

    Parameters
    ----------
    x : (n,) array
    P, F, Q : (n, n) arrays

    Returns
    -------
    x, P : the predicted state and covariance (new arrays; ``P`` exactly symmetric).
    """
    return _predict(as_f64(x), as_f64(P), as_f64(F), as_f64(Q))


def update(x, P, z, R, H):
    """Joseph-form Kalman update with the gain from the explicit inverse of
    ``S = H P H^T + R`` (filterpy's ``update(x, P, z, R, H)``).

    Parameters
    ----------
    x : (n,) array
    P : (n, n) array
    z : (m,) array
    R : (m, m) array
    H : (m, n) array

    Returns
    -------
    x, P : the updated state and covariance (new arrays; ``P`` exactly symmetric).
    """
    return _update(as_f64(x), as_f64(P), as_f64(z), as_f64(R), as_f64(H))


@entry
@njit(cache=True)
def _smoother_record(Pp, H, R, z):
    m, n = H.shape
    S = innovation_covariance(H, Pp, R)
    L = np.empty((m, m))
    G = np.empty((m, n))
    s = np.empty((m, 1))
    if not cholesky_into(S, L, m):  # S = L L^T
        return False, G, G, s[:, 0]
    tri_solve(L, H, m, G, False)  # G = L^-T (L^-1 H)
    tri_solve(L, G, m, G, True)
    tri_solve(L, z.reshape((m, 1)), m, s, False)  # s = L^-T (L^-1 z)
    tri_solve(L, s, m, s, True)
    return True, matmul_bt(Pp, G), G, s[:, 0]


def smoother_record(Pp, H, R, z, time: float = float("nan")):
    """The smoother's record of one update from the predicted covariance ``Pp``:
    ``K = Pp H^T S^-1``, ``G = S^-1 H`` and ``s = S^-1 z`` with ``S = H Pp H^T + R``, from
    the Cholesky factor ``S = L L^T`` (as the high-rate path's update,
    :func:`insgnss.filter.highrate._kalman_update`), compiled: the numpy form cost a stack, a
    solve and three products of Python overhead per epoch. (LAPACK's ``gesv`` through
    ``np.linalg.solve`` gave the same numbers to rounding, but its compiled copy-in brought
    numba's shape-error formatting, 3-4 s, into the first run's compile.)

    ``time``: the epoch, for the message of the error below.

    Returns
    -------
    K : (n, m) array
    G : (m, n) array
    s : (m,) array

    Raises
    ------
    FilterHealthError
        ``S`` is not positive definite (a broken ``Pp``).
    """
    ok, K, G, s = _smoother_record(as_f64(Pp), as_f64(H), as_f64(R), as_f64(z))
    if not ok:
        raise FilterHealthError(f"innovation covariance is not positive definite at "
                                f"t = {time:.6f} s (smoother record)",
                                found="Cholesky factorisation failed")
    return K, G, s


def backend(name: str):
    """``(predict, update)`` of the engine's general epochs: the compiled ones above
    (``"compiled"``) or filterpy's (``"filterpy"``, imported on first use)."""
    if name == "compiled":
        return predict, update
    if name == "filterpy":
        from filterpy.kalman import predict as kf_predict
        from filterpy.kalman import update as kf_update

        return kf_predict, kf_update
    raise ValueError(f"unknown Kalman backend {name!r}")
