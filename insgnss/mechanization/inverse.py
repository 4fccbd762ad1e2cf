"""Inverse mechanization: IMU increments from a trajectory, the exact dual of
:func:`insgnss.mechanization.strapdown.mechanize`.

Each forward step (see :mod:`.strapdown`) is inverted in closed form, vectorised over samples:

- attitude: ``dtheta = log(C_{k-1}^T exp([zeta x]) C_k)`` with ``zeta = w_il^l dt`` (for the
  first-order update the angle is mapped back by ``|theta| = 2 tan(|theta'| / 2)``);
- velocity: ``dv = C_mid^T (v_k - v_{k-1} - (g^l - (2 w_ie^l + w_el^l) x v_mid) dt)`` with
  ``C_mid = exp(-[zeta/2 x]) C_{k-1} exp([theta'/2 x])``.

Position enters only through the Earth quantities at k-1. The forward run reproduces the
position of the trajectory when the trajectory's position is the trapezoidal integral of its
velocity (as :func:`integrate_position` makes it, and as :mod:`insgnss.simulate` generates it);
velocity and attitude are reproduced in any case.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from numba import njit

from .. import earth
from ..attitude import dcm_to_rotvec, euler_to_dcm, rotvec_to_dcm
from ..earth import OMEGA_E, radii
from ..imu import increments_table
from .strapdown import ATTITUDE_FIRST_ORDER, attitude_update_id, position_update


def inverse_mechanize(
    trajectory: pd.DataFrame,
    *,
    gravity_model: str = "somigliana",
    attitude_update: str = "exact",
) -> pd.DataFrame:
    """IMU increments that make the forward mechanization follow ``trajectory`` exactly.

    Parameters
    ----------
    trajectory : DataFrame
        Indexed by time [s] with columns ``lat lon height`` [rad, m], ``vel_e vel_n vel_u``
        [m/s] and ``roll pitch heading`` [rad].
    gravity_model, attitude_update
        Must match the forward run.

    Returns
    -------
    DataFrame
        Increment IMU table (``dtheta_* dv_*``), body frame RFU; row 0 is zero.
    """
    t = np.asarray(trajectory.index, float)
    lat = trajectory["lat"].to_numpy(float)
    h = trajectory["height"].to_numpy(float)
    v = trajectory[["vel_e", "vel_n", "vel_u"]].to_numpy(float)
    C = euler_to_dcm(
        trajectory["roll"].to_numpy(float),
        trajectory["pitch"].to_numpy(float),
        trajectory["heading"].to_numpy(float),
    )
    dth, dv = inverse_increments(t, lat, h, v, C, gravity_model, attitude_update)
    return increments_table(t, dth, dv)


def inverse_increments(t, lat, h, v, C, gravity_model="somigliana", attitude_update="exact"):
    """Array form of :func:`inverse_mechanize`: returns ``(dtheta, dv)`` of shape (N, 3)."""
    dt = np.diff(t)
    la, hh, v0 = lat[:-1], h[:-1], v[:-1]
    # Earth terms at the predicted mid-interval point, as strapdown.llf_earth_terms
    M0, _ = radii(la)
    lat_m = la + 0.5 * dt * v0[:, 1] / (M0 + hh)
    h_m = hh + 0.5 * dt * v0[:, 2]
    M, N = radii(lat_m)
    slat, clat = np.sin(lat_m), np.cos(lat_m)
    wie = np.stack([np.zeros_like(la), OMEGA_E * clat, OMEGA_E * slat], -1)
    K = np.zeros((la.size, 3, 3))
    K[:, 0, 1] = -1.0 / (M + h_m)
    K[:, 1, 0] = 1.0 / (N + h_m)
    K[:, 2, 0] = slat / clat / (N + h_m)
    g = earth.normal_gravity(lat_m, h_m, gravity_model)
    return inverse_step_increments(dt, v0, v[1:], C[:-1], C[1:], wie, K, g, attitude_update)


def inverse_step_increments(dt, v0, v1, C0, C1, wie, K, g, attitude_update="exact"):
    """Invert the velocity and attitude stages of the strapdown step (any navigation frame).

    Given per interval the start/end velocity ``v0, v1`` (N-1, 3) and attitude ``C0, C1``
    (N-1, 3, 3) in the navigation frame, the Earth rate ``wie`` (N-1, 3), the transport-rate
    matrix ``K`` (N-1, 3, 3: ``w_en = K v``) and gravity ``g`` (N-1,) at mid-interval, returns
    ``(dtheta, dv)`` of shape (N, 3) with a zero first row. Exact dual of
    :func:`insgnss.mechanization.strapdown.velocity_update` and ``attitude_step``:

    - ``zeta = (w_ie + K (v0 + v1) / 2) dt``, ``theta' = log(C0^T exp([zeta x]) C1)``;
    - ``dv = C_mid^T (v1 - v0 - g^n dt + (w_ie x (v0 + v1) + B(v0, v1)) dt)`` with
      ``C_mid = exp(-[zeta0/2 x]) C0 exp([theta'/2 x])``, ``zeta0 = (w_ie + K v0) dt``.
    """
    dt = np.asarray(dt, float)
    rho0 = np.einsum("kij,kj->ki", K, v0)
    rho1 = np.einsum("kij,kj->ki", K, v1)
    zeta = (wie + 0.5 * (rho0 + rho1)) * dt[:, None]
    C0T = np.swapaxes(C0, 1, 2)
    th_applied = dcm_to_rotvec(C0T @ rotvec_to_dcm(zeta) @ C1)
    dth = th_applied
    if attitude_update_id(attitude_update) == ATTITUDE_FIRST_ORDER:
        a = np.linalg.norm(th_applied, axis=1)
        small = a < 1e-8
        a_safe = np.where(small, 1.0, a)
        scale = np.where(small, 1.0 + a * a / 12.0, 2.0 * np.tan(0.5 * a_safe) / a_safe)
        dth = th_applied * scale[:, None]
    zeta0 = (wie + rho0) * dt[:, None]
    Cmid = rotvec_to_dcm(-0.5 * zeta0) @ C0 @ rotvec_to_dcm(0.5 * th_applied)
    acc = np.cross(wie, v0 + v1) + 0.5 * (np.cross(rho0, v1) + np.cross(rho1, v0))
    rhs = (v1 - v0) + acc * dt[:, None]
    rhs[:, 2] += g * dt
    dvb = np.einsum("kji,kj->ki", Cmid, rhs)
    zero = np.zeros((1, 3))
    return np.vstack([zero, dth]), np.vstack([zero, dvb])


@njit(cache=True)
def _integrate_position(t, vel, lat0, lon0, h0, out):
    pos_lat, pos_lon, pos_h = lat0, lon0, h0
    out[0, 0], out[0, 1], out[0, 2] = lat0, lon0, h0
    for k in range(1, t.shape[0]):
        pos_lat, pos_lon, pos_h = position_update(
            pos_lat, pos_lon, pos_h, vel[k - 1], vel[k], t[k] - t[k - 1]
        )
        out[k, 0], out[k, 1], out[k, 2] = pos_lat, pos_lon, pos_h


def integrate_position(t, vel, lat0: float, lon0: float, h0: float) -> np.ndarray:
    """Position (N, 3: lat, lon [rad], h [m]) from ENU velocity by exactly the forward
    mechanization's trapezoidal rule, so that trajectories built with it are reproduced by
    ``mechanize(inverse_mechanize(...))`` to rounding."""
    t = np.ascontiguousarray(t, dtype=float)
    vel = np.ascontiguousarray(vel, dtype=float)
    out = np.empty((t.size, 3))
    _integrate_position(t, vel, float(lat0), float(lon0), float(h0), out)
    return out
