"""Wander-azimuth strapdown mechanization: a navigation frame that is regular over the poles.

Frame
-----
The wander frame w has its z axis up along the ellipsoid normal, like the ENU frame l, and its
horizontal axes turned about that normal by the wander angle ``alpha``::

    C_w^l = Rz(alpha) = [[cos a, -sin a, 0], [sin a, cos a, 0], [0, 0, 1]]

so ``v^l = Rz(alpha) v^w`` and the true heading is ``A = A_w - alpha`` (``A_w``: heading from the
wander y axis, clockwise). The frame does not turn about its own vertical relative to the Earth,
``w_ew^w . z = 0``, which fixes ``d alpha / dt = -d lon / dt sin(lat)``
(Jekeli 2001 section 4.3.3; Groves 2013 section 5.3.5; Savage 2000 section 4.4.1.2). ``tan(lat)``
(the ENU transport rate's vertical component) and ``1/cos(lat)`` (the longitude rate) never
appear, so nothing is singular at the poles.

Position is carried as the direction-cosine matrix ``C_w^e`` (w to ECEF, "C_N^E" in Savage) and
the height. Its third row is the Earth's polar axis in w, ``z^w = (cos lat sin a, cos lat cos a,
sin lat)``, its third column the local up in ECEF; latitude, longitude and ``alpha`` are read from
it only for output.

Equations (the wander-frame mechanization in the regular curvature form)
-----------------------------------------------------------------------
- Earth rate ``w_ie^w = Omega z^w``; gravity ``g^w = (0, 0, -g(lat, h))``;
- transport rate ``rho^w = K v^w`` with ``rho_z = 0`` and the horizontal part
  ``rho_h = F (u x v)_h``, ``(u x v)_h = (-v_y, v_x)``, where the curvature matrix is the ENU
  ``diag(1/(M+h), 1/(N+h))`` turned into w::

      F = I / (N + h) + kappa u u^T,   u = (z_y, -z_x) = cos(lat) (cos a, -sin a),
      kappa = (1/(M+h) - 1/(N+h)) / cos^2(lat) = N e^2 / ((1 - e^2 sin^2 lat) (M+h) (N+h)),

  regular everywhere (``u -> 0`` and ``M = N`` at the poles);
- ``dC_w^e/dt = C_w^e [rho x]``, ``dh/dt = v_z``; velocity and attitude as in any frame with up z
  (:mod:`.core`).

Discrete step (second order, explicit, exactly invertible; the same stages as :mod:`.strapdown`)
------------------------------------------------------------------------------------------------
1. mid-interval Earth terms: ``z_m = normalise(z - dt/2 (K v_{k-1}) x z)`` (the polar axis seen
   from the frame half a step on: ``dz^w/dt = -rho x z^w``), ``h_m = h + v_z dt / 2``; ``K``,
   ``w_ie`` and ``g`` there;
2. velocity and attitude: :func:`.core.velocity_update`, :func:`.core.nav_frame_rotation`,
   :func:`.core.attitude_step` with ``w_ie^w`` and ``K``;
3. position: ``xi = K (v_{k-1} + v_k) / 2 dt`` (``xi_z = 0`` exactly), ``C_w^e <- C_w^e exp([xi x])``,
   ``h <- h + (v_z,k-1 + v_z,k) dt / 2``.

The inverse (:func:`inverse_increments_wander`) recovers ``alpha`` along a given trajectory from
consecutive ENU frames: with ``D = C_e^l(k-1) C_l^e(k)``, the step ``beta = alpha_k - alpha_{k-1}``
that makes ``C_w^e(k-1)^T C_w^e(k)`` a rotation with zero vertical component is
``beta = atan2(D_01 - D_10, D_00 + D_11)`` (invariant under the wander angle itself, so
``alpha = alpha_0 + cumsum(beta)``), then inverts stages 2 and 1 like the ENU inverse.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..attitude import Rz, rotvec_xyz_to_dcm_nb
from ..earth import E2, OMEGA_E, A, check_latitude, enu_to_ecef_dcm, normal_gravity_sc
from ..jit import njit
from .core import (
    NAV_COLS,
    STEP_WORK_SHAPE,
    NavState,
    _matmul3,
    attitude_step,
    body_rotation,
    inverse_step_increments,
    nav_frame_rotation,
    velocity_update,
)

#: output columns of the wander mechanization (ENU quantities plus the wander angle)
WANDER_COLS = NAV_COLS + ["wander_angle"]


# --- compiled pieces ---------------------------------------------------------------------------
@njit(cache=True, inline="always")
def transport_matrix(z0, z1, z2, h, K):
    """Write ``K`` (3x3) with ``rho^w = K v^w`` for the polar-axis direction ``z^w = (z0, z1, z2)``
    (unit; ``z2 = sin(lat)``) at height ``h``."""
    s2 = z2 * z2
    w = 1.0 - E2 * s2
    N = A / np.sqrt(w)
    M = N * (1.0 - E2) / w
    a = 1.0 / (N + h)
    kap = N * E2 / (w * (M + h) * (N + h))
    u0, u1 = z1, -z0
    f00 = a + kap * u0 * u0
    f01 = kap * u0 * u1
    f11 = a + kap * u1 * u1
    # rho_x = f00 (-v_y) + f01 v_x, rho_y = f01 (-v_y) + f11 v_x
    K[0, 0], K[0, 1], K[0, 2] = f01, -f00, 0.0
    K[1, 0], K[1, 1], K[1, 2] = f11, -f01, 0.0
    K[2, 0], K[2, 1], K[2, 2] = 0.0, 0.0, 0.0


@njit(cache=True, inline="always")
def wander_earth_terms(z, h, vel, dt, gravity_model, wie, K, zm):
    """Earth terms of one interval at its predicted middle (step 1 of the module docstring).

    ``z`` is the polar axis in w at the start (the third row of ``C_w^e``). Writes ``w_ie^w``
    into ``wie``, the transport-rate matrix into ``K`` and the mid polar axis into ``zm``;
    returns the normal gravity at the mid point.
    """
    transport_matrix(z[0], z[1], z[2], h, K)
    r0 = K[0, 0] * vel[0] + K[0, 1] * vel[1]
    r1 = K[1, 0] * vel[0] + K[1, 1] * vel[1]
    a = 0.5 * dt
    # z - a rho x z with rho = (r0, r1, 0)
    x = z[0] - a * (r1 * z[2])
    y = z[1] - a * (-r0 * z[2])
    u = z[2] - a * (r0 * z[1] - r1 * z[0])
    n = np.sqrt(x * x + y * y + u * u)
    zm[0], zm[1], zm[2] = x / n, y / n, u / n
    h_m = h + a * vel[2]
    transport_matrix(zm[0], zm[1], zm[2], h_m, K)
    wie[0], wie[1], wie[2] = OMEGA_E * zm[0], OMEGA_E * zm[1], OMEGA_E * zm[2]
    # sin(lat) = z_z, cos(lat) = |z_h|
    return normal_gravity_sc(zm[2], np.sqrt(zm[0] * zm[0] + zm[1] * zm[1]), h_m, gravity_model)


@njit(cache=True, inline="always")
def wander_position_step(Cne, hv, v0, v1, dt, K, E, tmp):
    """``C_w^e <- C_w^e exp([xi x])`` with ``xi = K (v0 + v1) / 2 dt``; ``hv[0] += v_z dt``
    (``E``, ``tmp``: 3x3 scratch)."""
    s0, s1, s2 = 0.5 * dt * (v0[0] + v1[0]), 0.5 * dt * (v0[1] + v1[1]), 0.5 * dt * (v0[2] + v1[2])
    rotvec_xyz_to_dcm_nb(K[0, 0] * s0 + K[0, 1] * s1 + K[0, 2] * s2,
                         K[1, 0] * s0 + K[1, 1] * s1 + K[1, 2] * s2,
                         K[2, 0] * s0 + K[2, 1] * s1 + K[2, 2] * s2, E)
    _matmul3(Cne, E, tmp)
    for i in range(3):
        for j in range(3):
            Cne[i, j] = tmp[i, j]
    hv[0] += s2


@njit(cache=True)
def wander_step(Cne, hv, vel, C, dth, dv, dt, gravity_model, attitude_update, fix_height, work):
    """Advance the position DCM ``Cne`` (C_w^e), the height ``hv[0]``, the wander-frame velocity
    ``vel`` and the attitude ``C`` (C_b^w) in place by one interval.

    ``work`` is a scratch array of shape :data:`~insgnss.mechanization.core.STEP_WORK_SHAPE`.
    """
    E0, E1, E2_, E3, K = work[0], work[1], work[2], work[3], work[4]
    vecs = work[6]
    th, zeta, v0, wie, zm = vecs[0], vecs[1], vecs[2], work[7, 0], work[5, 0]
    g = wander_earth_terms(Cne[2], hv[0], vel, dt, gravity_model, wie, K, zm)
    body_rotation(dth, attitude_update, th)
    velocity_update(vel, v0, C, th, dv, dt, wie, K, g, fix_height, E0, E1, E2_, E3)
    nav_frame_rotation(wie, K, v0, vel, dt, zeta)
    attitude_step(C, th, zeta, E0, E1, E2_)
    wander_position_step(Cne, hv, v0, vel, dt, K, E0, E1)


@njit(cache=True)
def wander_to_nav(Cne, h, vel, C, out):
    """Write ``lat lon height vel_e vel_n vel_u roll pitch heading wander_angle`` into ``out``
    (10,) from the wander state. ``alpha`` is taken from ``C_e^l(lat, lon) C_w^e = Rz(alpha)``
    so that it is consistent with the longitude returned (also at the pole itself, where the
    longitude is a convention: 0)."""
    lat = np.arctan2(Cne[2, 2], np.sqrt(Cne[0, 2] ** 2 + Cne[1, 2] ** 2))
    lon = np.arctan2(Cne[1, 2], Cne[0, 2])
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    # east = (-so, co, 0), north = (-sl co, -sl so, cl) applied to the first column of C_w^e
    ca = -so * Cne[0, 0] + co * Cne[1, 0]
    sa = -sl * co * Cne[0, 0] - sl * so * Cne[1, 0] + cl * Cne[2, 0]
    alpha = np.arctan2(sa, ca)
    ca, sa = np.cos(alpha), np.sin(alpha)
    out[0], out[1], out[2] = lat, lon, h
    out[3] = ca * vel[0] - sa * vel[1]
    out[4] = sa * vel[0] + ca * vel[1]
    out[5] = vel[2]
    # C_b^l = Rz(alpha) C_b^w: rows 0, 1 turned, row 2 unchanged
    c01 = ca * C[0, 1] - sa * C[1, 1]
    c11 = sa * C[0, 1] + ca * C[1, 1]
    out[6] = np.arctan2(-C[2, 0], C[2, 2])
    out[7] = np.arctan2(C[2, 1], np.sqrt(c01 * c01 + c11 * c11))
    a = np.arctan2(c01, c11)
    out[8] = a + 2.0 * np.pi if a < 0.0 else a
    out[9] = alpha


@njit(cache=True)
def _mechanize_wander_kernel(t, dth, dv, Cne0, h0, vel0, C0, gravity_model, attitude_update,
                             fix_height, out):
    Cne = Cne0.copy()
    hv = np.array([h0])
    vel = vel0.copy()
    C = C0.copy()
    work = np.empty(STEP_WORK_SHAPE)
    for k in range(t.shape[0]):
        if k > 0:
            wander_step(Cne, hv, vel, C, dth[k], dv[k], t[k] - t[k - 1], gravity_model,
                        attitude_update, fix_height, work)
        wander_to_nav(Cne, hv[0], vel, C, out[k])
    return Cne, hv[0], vel, C


@njit(cache=True)
def _integrate_position_wander(t, vel, Cne0, h0, Cne_out, h_out):
    Cne = Cne0.copy()
    hv = np.array([h0])
    work = np.empty(STEP_WORK_SHAPE)
    wie, zm, K = work[7, 0], work[5, 0], work[4]
    Cne_out[0] = Cne
    h_out[0] = h0
    for k in range(1, t.shape[0]):
        dt = t[k] - t[k - 1]
        wander_earth_terms(Cne[2], hv[0], vel[k - 1], dt, 0, wie, K, zm)
        wander_position_step(Cne, hv, vel[k - 1], vel[k], dt, K, work[0], work[1])
        Cne_out[k] = Cne
        h_out[k] = hv[0]


@njit(cache=True)
def _wander_mid_terms_batch(z, h, v, dt, gravity_model, wie, K, g):
    """:func:`wander_earth_terms` for every interval (inverse mechanization)."""
    zm = np.empty(3)
    for k in range(dt.shape[0]):
        g[k] = wander_earth_terms(z[k], h[k], v[k], dt[k], gravity_model, wie[k], K[k], zm)


# --- conversions (vectorised) ------------------------------------------------------------------
def wander_angles(lat, lon, alpha0: float = 0.0) -> np.ndarray:
    """Wander angle along a sampled path (the discrete wander condition, module docstring):
    ``alpha_k = alpha_0 + sum beta``, ``beta = atan2(D_01 - D_10, D_00 + D_11)``,
    ``D = C_e^l(k-1) C_l^e(k)``. Regular through the poles as long as no sample is exactly on
    one (where longitude, and so ``C_l^e``, is a convention)."""
    Cle = enu_to_ecef_dcm(lat, lon)
    D = np.swapaxes(Cle[:-1], 1, 2) @ Cle[1:]
    beta = np.arctan2(D[:, 0, 1] - D[:, 1, 0], D[:, 0, 0] + D[:, 1, 1])
    return float(alpha0) + np.concatenate([[0.0], np.cumsum(beta)])


def wander_state(initial: NavState):
    """``(C_w^e, h, v^w, C_b^w)`` of an ENU :class:`NavState` with its ``wander_angle``."""
    R = Rz(initial.wander_angle)
    Cne = enu_to_ecef_dcm(initial.lat, initial.lon) @ R
    return (np.ascontiguousarray(Cne), float(initial.height),
            np.ascontiguousarray(R.T @ np.asarray(initial.vel, float)),
            np.ascontiguousarray(R.T @ np.asarray(initial.C, float)))


def nav_state(Cne, h, vel, C, time: float = 0.0) -> NavState:
    """ENU :class:`NavState` (with ``wander_angle``) of a wander state."""
    out = np.empty(10)
    wander_to_nav(np.ascontiguousarray(Cne, dtype=float), float(h), np.asarray(vel, float),
                  np.ascontiguousarray(C, dtype=float), out)
    R = Rz(out[9])
    return NavState(out[0], out[1], out[2], out[3:6].copy(), R @ np.asarray(C, float),
                    float(time), float(out[9]))


def integrate_position_wander(t, vel_w, lat0: float, lon0: float, h0: float,
                              alpha0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``C_w^e`` (N, 3, 3) and height (N,) from the wander-frame velocity (N, 3) by exactly the
    forward step's position rule (the wander twin of
    :func:`insgnss.mechanization.inverse.integrate_position`)."""
    check_latitude(lat0, "lat0")
    t = np.ascontiguousarray(t, dtype=float)
    vel_w = np.ascontiguousarray(vel_w, dtype=float)
    Cne0 = np.ascontiguousarray(enu_to_ecef_dcm(lat0, lon0) @ Rz(alpha0))
    Cne = np.empty((t.size, 3, 3))
    h = np.empty(t.size)
    _integrate_position_wander(t, vel_w, Cne0, float(h0), Cne, h)
    return Cne, h


def wander_table(t, Cne, h, vel_w, C_bw) -> pd.DataFrame:
    """Trajectory table (:data:`WANDER_COLS`) from wander-frame arrays (N, ...)."""
    out = np.empty((len(t), 10))
    Cne = np.ascontiguousarray(Cne, dtype=float)
    vel_w = np.ascontiguousarray(vel_w, dtype=float)
    C_bw = np.ascontiguousarray(C_bw, dtype=float)
    _table_kernel(Cne, np.asarray(h, float), vel_w, C_bw, out)
    return pd.DataFrame(out, index=pd.Index(np.asarray(t, float), name="time"), columns=WANDER_COLS)


@njit(cache=True)
def _table_kernel(Cne, h, vel, C, out):
    for k in range(h.shape[0]):
        wander_to_nav(Cne[k], h[k], vel[k], C[k], out[k])


# --- batch API ---------------------------------------------------------------------------------
def mechanize_wander(t, dth, dv, initial: NavState, gravity_model: int, attitude_update: int,
                     fix_height: bool):
    """Run :func:`wander_step` over increment arrays; returns ``(out (N, 10), final NavState)``.
    Called by :func:`insgnss.mechanization.strapdown.mechanize` with ``frame="wander"``."""
    Cne0, h0, v0, C0 = wander_state(initial)
    out = np.empty((t.size, 10))
    Cne, h, vel, C = _mechanize_wander_kernel(t, dth, dv, Cne0, h0, v0, C0, gravity_model,
                                              attitude_update, bool(fix_height), out)
    return out, nav_state(Cne, h, vel, C, float(t[-1]))


def inverse_increments_wander(t, lat, lon, h, v, C, alpha0=0.0, gravity_model=0,
                              attitude_update="exact"):
    """IMU increments ``(dtheta, dv)`` (N, 3) of an ENU trajectory mechanized in the wander
    frame (the exact dual of :func:`wander_step`; see the module docstring).

    ``alpha0`` is the wander angle at the first sample (the increments do not depend on it).
    """
    t = np.asarray(t, float)
    alpha = wander_angles(lat, lon, alpha0)
    R = Rz(alpha)
    RT = np.swapaxes(R, 1, 2)
    Cne = enu_to_ecef_dcm(lat, lon) @ R
    vw = np.einsum("kij,kj->ki", RT, np.asarray(v, float))
    Cbw = RT @ np.asarray(C, float)
    dt = np.diff(t)
    n = dt.size
    wie = np.empty((n, 3))
    K = np.empty((n, 3, 3))
    g = np.empty(n)
    _wander_mid_terms_batch(np.ascontiguousarray(Cne[:-1, 2, :]), np.ascontiguousarray(h[:-1], float),
                            np.ascontiguousarray(vw[:-1]), dt, int(gravity_model), wie, K, g)
    return inverse_step_increments(dt, vw[:-1], vw[1:], Cbw[:-1], Cbw[1:], wie, K, g,
                                   attitude_update)
