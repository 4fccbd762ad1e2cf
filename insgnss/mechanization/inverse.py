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
    la, hh, vv, C0, C1 = lat[:-1], h[:-1], v[:-1], C[:-1], C[1:]
    M, N = radii(la)
    slat, clat = np.sin(la), np.cos(la)
    wie = np.stack([np.zeros_like(la), OMEGA_E * clat, OMEGA_E * slat], -1)
    wel = np.stack([-vv[:, 1] / (M + hh), vv[:, 0] / (N + hh), vv[:, 0] * slat / clat / (N + hh)], -1)
    C0T = np.swapaxes(C0, 1, 2)
    zeta = (wie + wel) * dt[:, None]
    # C_k = exp(-zeta) C_{k-1} exp(theta)  ->  theta = log(C_{k-1}^T exp(zeta) C_k)
    th_applied = dcm_to_rotvec(C0T @ rotvec_to_dcm(zeta) @ C1)
    dth = th_applied
    if attitude_update_id(attitude_update) == ATTITUDE_FIRST_ORDER:
        a = np.linalg.norm(th_applied, axis=1)
        small = a < 1e-8
        a_safe = np.where(small, 1.0, a)
        scale = np.where(small, 1.0 + a * a / 12.0, 2.0 * np.tan(0.5 * a_safe) / a_safe)
        dth = th_applied * scale[:, None]
    Cmid = rotvec_to_dcm(-0.5 * zeta) @ C0 @ rotvec_to_dcm(0.5 * th_applied)
    g = earth.normal_gravity(la, hh, gravity_model)
    acc = np.cross(2.0 * wie + wel, 0.5 * (vv + v[1:]))  # Coriolis at the mid velocity
    rhs = (v[1:] - vv) + acc * dt[:, None]
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
