"""Linearised error dynamics and their discretisation (as in the ``inu`` package's
``jacobian`` and ``vanloan``).

- :func:`jacobian`: the continuous-time matrix ``F`` of insgnss' error-state model
  (:mod:`insgnss.filter.models`, the one the Kalman filter uses) at a nominal state, for one
  specific force and angular rate.
- :func:`vanloan`: van Loan's method (van Loan 1978; Brown & Hwang 2012 section 3.9) for
  ``Phi = exp(F T)``, ``Bd = int_0^T exp(F s) ds B`` and
  ``Qd = int_0^T exp(F s) Q exp(F s)^T ds``.

How this differs from inu
-------------------------
inu's ``jacobian(fbbi, llh, vne, Cnb)`` returns the 9 x 9 Jacobian of the *total* NED state
(latitude, longitude, height in rad/m; north-east-down velocity; tilt). Ours is the Jacobian of
the *error* state of the filter, in the order of :class:`insgnss.filter.models.StateLayout`:
position error in ENU metres (``nominal - true``), ENU velocity error, attitude misalignment
``phi`` in the l-frame (``C_nom = exp([phi x]) C_true``), then gyro and accelerometer bias errors
(15 states; 21 with scale factors). The attitude matrix is ``C_b^l`` (body RFU to ENU), the
velocity ENU. inu's ``Q`` in ``vanloan(F, B, Q, T)`` is, as here, the continuous noise PSD
already mapped onto the states (``G Q G^T``).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from .earth import check_latitude
from .errors import InvalidValueError
from .filter.models import StateLayout, error_dynamics


def jacobian(f_b, llh, vel, C, *, w_ib=None, layout: StateLayout | None = None,
             decay=None) -> np.ndarray:
    """Continuous error-dynamics matrix ``F`` (``d(dx)/dt = F dx``) at a nominal state.

    Parameters
    ----------
    f_b : 3-vector
        Specific force in the body frame (RFU) [m/s^2].
    llh : 3-vector
        Nominal latitude, longitude [rad] and height [m] (longitude does not enter).
    vel : 3-vector
        Nominal ENU velocity [m/s].
    C : (3, 3)
        Nominal attitude ``C_b^l``.
    w_ib : 3-vector, optional
        Angular rate [rad/s] (enters only with gyro scale-factor states); default zero.
    layout : StateLayout, optional
        Error-state layout; default the 15 core states.
    decay : (n,) array, optional
        ``1 / tau`` of Gauss-Markov states, subtracted on the diagonal.

    Returns
    -------
    (n, n) array. A wrapper of :func:`insgnss.filter.models.error_dynamics` (the same compiled
    code the filter integrates): its equations and their known approximations are documented
    there and in docs/filter.md.
    """
    llh = np.asarray(llh, float).reshape(3)
    check_latitude(llh[0], "llh[0]")
    layout = StateLayout() if layout is None else layout
    w = np.zeros(3) if w_ib is None else np.asarray(w_ib, float).reshape(3)
    return error_dynamics(llh[0], llh[2], np.asarray(vel, float).reshape(3),
                          np.asarray(C, float).reshape(3, 3), np.asarray(f_b, float).reshape(3),
                          w, layout, decay)


def vanloan(F, B=None, Q=None, T=None):
    """Discretise ``dx/dt = F x + B u + w`` (``E[w w^T] = Q delta``) over ``T`` by van Loan's
    matrix exponentials.

    Returns ``(Phi, Bd, Qd)`` with ``Phi = exp(F T)``, ``Bd = int_0^T exp(F s) ds B`` (``None``
    without ``B``) and ``Qd = int_0^T exp(F s) Q exp(F s)^T ds`` (``None`` without ``Q``)::

        exp([[F, B], [0, 0]] T) = [[Phi, Bd], [0, I]]
        exp([[-F, Q], [0, F^T]] T) = [[., Phi^-1 Qd], [0, Phi^T]]
    """
    if T is None:
        raise InvalidValueError("the sampling period T is required", column="T")
    F = np.asarray(F, float)
    n = F.shape[0]
    if F.shape != (n, n):
        raise InvalidValueError("F must be square", column="F", found=F.shape)
    T = float(T)
    Bd = None
    if B is None:
        Phi = expm(F * T)
    else:
        B = np.asarray(B, float).reshape(n, -1)
        m = B.shape[1]
        M = np.zeros((n + m, n + m))
        M[:n, :n] = F
        M[:n, n:] = B
        E = expm(M * T)
        Phi, Bd = E[:n, :n], E[:n, n:]
    Qd = None
    if Q is not None:
        Q = np.asarray(Q, float)
        if Q.shape != (n, n):
            raise InvalidValueError("Q must match F", column="Q", found=Q.shape)
        M = np.zeros((2 * n, 2 * n))
        M[:n, :n] = -F
        M[:n, n:] = Q
        M[n:, n:] = F.T
        E = expm(M * T)
        Phi = E[n:, n:].T
        Qd = Phi @ E[:n, n:]
        Qd = 0.5 * (Qd + Qd.T)
    return Phi, Bd, Qd
