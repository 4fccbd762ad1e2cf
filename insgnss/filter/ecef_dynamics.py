"""Pole-safe error-state dynamics of the wander-azimuth strapdown process model: errors resolved
in the Earth-fixed (ECEF) frame.

The LLF error state of :mod:`.models` is tied to the ENU axes at the nominal point; its
dynamics carry ``tan(lat)`` and ``1 / cos^2(lat)`` (the ENU frame spins about its vertical
without bound near a pole), so it cannot describe a route over a pole. The wander model
(:mod:`.wander_model`) therefore estimates the errors of its nominal resolved in ECEF (Groves
2013 section 14.2.3; Shin 2001 section 2.4)::

    dr^e  = r^e_nom - r^e_true                       (ECEF position error [m])
    dv^e  = v^e_nom - v^e_true                       (ground velocity, ECEF [m/s])
    phi^e:  C_b^e,nom = exp([phi^e x]) C_b^e,true    (misalignment resolved in ECEF [rad])

followed by the same parameter states as the LLF model (biases, scale factors, extras), all
"nominal minus true". With ``v^e' = C_b^e f^b - 2 w_ie x v^e + g^e(r^e)``,
``C_b^e' = C_b^e [w_ib x] - [w_ie x] C_b^e`` and the sensor errors of :mod:`.models`::

    d(dr)/dt  = dv
    d(dv)/dt  = Gamma dr - 2 [w_ie x] dv - [f^e x] phi - C ba - C diag(f^b) sa
    d(phi)/dt = -[w_ie x] phi - C bg - C diag(w_ib^b) sg

with ``C = C_b^e``, ``w_ie = (0, 0, Omega)`` and the gradient of the normal-gravity vector
``g^e = -g(lat, h) u`` (``u``: the ellipsoid normal)::

    Gamma = C_w^e [[-g K_h, 0], [-(dg/dlat) n_h^T / (M + h), -dg/dh]] C_e^w

in the wander frame: ``K_h = I / (N + h) + kappa z_h z_h^T`` (2x2) is the curvature matrix of the
surface (ENU ``diag(1/(N+h), 1/(M+h))`` turned into w; ``kappa`` as in
:mod:`insgnss.mechanization.wander`; the normal tilts by ``K_h dr_h`` when the point moves by
``dr_h``), ``n_h`` the north direction, and ``dg/dlat n_h = (dg/dlat / cos lat) z_h`` with
``z_h`` the horizontal part of the polar axis, again regular (``dg/dlat`` vanishes like
``cos lat``). Nothing in F depends on the wander angle or is singular at a pole.
"""

from __future__ import annotations

import numpy as np

from ..earth import E2, OMEGA_E, A, gravity_gradient_somigliana, normal_gravity_sc
from ..jit import njit
from .models import _sensor_error_terms


@njit(cache=True)
def accumulate_ecef_error_dynamics(F, dt, Cne, h, Cbe, dth_b, dv_b, i_sg, i_sa):
    """Add ``F dt`` of the ECEF error dynamics (module docstring) for one IMU interval.

    Parameters
    ----------
    F : (n, n) array, modified in place
    dt : float
    Cne : (3, 3) array
        ``C_w^e`` of the nominal (its third row is the polar axis in w, its third column the
        ellipsoid normal in ECEF).
    h : float
        Nominal height [m].
    Cbe : (3, 3) array
        ``C_b^e = C_w^e C_b^w``.
    dth_b, dv_b : (3,) arrays
        Compensated angle and velocity increments of the interval (body frame).
    i_sg, i_sa : int
        First index of the gyro / accelerometer scale-factor blocks, -1 if absent.
    """
    z0, z1, s = Cne[2, 0], Cne[2, 1], Cne[2, 2]
    c = np.sqrt(z0 * z0 + z1 * z1)
    w = 1.0 - E2 * s * s
    N = A / np.sqrt(w)
    M = N * (1.0 - E2) / w
    a = 1.0 / (N + h)
    kap = N * E2 / (w * (M + h) * (N + h))
    g = normal_gravity_sc(s, c, h, 0)
    dg_dlat, dg_dh = gravity_gradient_somigliana(s, c, h)
    # gravity gradient in w: rows x, y = -g K_h with K_h = I / (N + h) + kappa z_h z_h^T
    # (ENU: diag(1/(N+h), 1/(M+h))); row z = the gradient of the magnitude
    G = np.zeros((3, 3))
    G[0, 0] = -g * (a + kap * z0 * z0)
    G[0, 1] = -g * kap * z0 * z1
    G[1, 0] = G[0, 1]
    G[1, 1] = -g * (a + kap * z1 * z1)
    q = dg_dlat / (c * (M + h)) if c > 0.0 else 0.0
    G[2, 0] = -q * z0
    G[2, 1] = -q * z1
    G[2, 2] = -dg_dh
    # Gamma = C_w^e G C_e^w
    T = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            T[i, j] = Cne[i, 0] * G[0, j] + Cne[i, 1] * G[1, j] + Cne[i, 2] * G[2, j]
    for i in range(3):
        for j in range(3):
            F[3 + i, j] += (T[i, 0] * Cne[j, 0] + T[i, 1] * Cne[j, 1] + T[i, 2] * Cne[j, 2]) * dt
        F[i, 3 + i] += dt
    # -2 [w_ie x] dv and -[w_ie x] phi, w_ie = (0, 0, Omega)
    F[3, 4] += 2.0 * OMEGA_E * dt
    F[4, 3] -= 2.0 * OMEGA_E * dt
    F[6, 7] += OMEGA_E * dt
    F[7, 6] -= OMEGA_E * dt
    _sensor_error_terms(F, dt, Cbe, dth_b, dv_b, i_sg, i_sa)


def ecef_error_dynamics(Cne, h: float, C_bw, f_b, w_ib, layout, decay=None) -> np.ndarray:
    """Continuous F (n x n) of the ECEF error state at a wander nominal (``C_w^e``, height,
    ``C_b^w``) with specific force ``f_b`` and angular rate ``w_ib`` (body frame); the Python
    wrapper of :func:`accumulate_ecef_error_dynamics`."""
    Cne = np.ascontiguousarray(Cne, dtype=float)
    F = np.zeros((layout.n, layout.n))
    accumulate_ecef_error_dynamics(F, 1.0, Cne, float(h), np.ascontiguousarray(Cne @ C_bw),
                                   np.asarray(w_ib, float), np.asarray(f_b, float),
                                   layout.index("gyro_scale"), layout.index("accel_scale"))
    if decay is not None:
        F[np.diag_indices(layout.n)] -= np.asarray(decay, float)
    return F
