"""Inverse mechanization: IMU increments from a trajectory, the exact dual of
:func:`insgnss.mechanization.strapdown.mechanize` (local-level ENU or wander-azimuth frame).

Each forward step (see :mod:`.strapdown`, :mod:`.wander`) is inverted in closed form, vectorised
over samples (:func:`insgnss.mechanization.core.inverse_step_increments`):

- Earth terms at the predicted mid-interval point from the trajectory's state at k-1 (exactly
  the forward's :func:`~.strapdown.llf_earth_terms` / :func:`~.wander.wander_earth_terms`);
- attitude: ``dtheta = log(C_{k-1}^T exp([zeta x]) C_k)`` with
  ``zeta = (w_ie + K (v_{k-1} + v_k) / 2) dt`` (for the first-order update the angle is mapped
  back by ``|theta| = 2 tan(|theta'| / 2)``);
- velocity: ``dv = C_mid^T (v_k - v_{k-1} - g^n dt + (w_ie x (v_{k-1} + v_k) + B(v_{k-1}, v_k)) dt)``
  with ``C_mid = exp(-[zeta0/2 x]) C_{k-1} exp([theta'/2 x])``, ``zeta0 = (w_ie + K v_{k-1}) dt``.

Position enters only through the Earth quantities. The forward run reproduces the position of
the trajectory when the trajectory's position is the forward position rule's integral of its
velocity (as :func:`integrate_position` and
:func:`~insgnss.mechanization.wander.integrate_position_wander` make it, and as
:mod:`insgnss.simulate` generates it); velocity and attitude then follow to rounding.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .. import earth
from ..aot import entry
from ..attitude import euler_to_dcm
from ..earth import check_latitude
from ..errors import ConfigError
from ..imu import increments_table
from ..jit import njit
from .core import FRAME_WANDER, frame_id, inverse_step_increments
from .strapdown import llf_earth_terms, position_update
from .wander import inverse_increments_wander


def inverse_mechanize(
    trajectory: pd.DataFrame,
    *,
    gravity_model: str = "somigliana",
    attitude_update: str = "exact",
    frame: str = "enu",
    wander_angle: float | None = None,
) -> pd.DataFrame:
    """IMU increments that make the forward mechanization follow ``trajectory`` exactly.

    Parameters
    ----------
    trajectory : DataFrame
        Indexed by time [s] with columns ``lat lon height`` [rad, m], ``vel_e vel_n vel_u``
        [m/s] and ``roll pitch heading`` [rad].
    gravity_model, attitude_update, frame
        Must match the forward run (:func:`~insgnss.mechanization.strapdown.mechanize`).
        ``frame="wander"`` runs the dual of the wander-azimuth step, which is regular over the
        poles (no sample may lie exactly on a pole, where the ENU columns are undefined).
    wander_angle : float, optional
        Wander angle at the first sample [rad] (default: the trajectory's ``wander_angle``
        column if present, else 0). The increments do not depend on it.

    Returns
    -------
    DataFrame
        Increment IMU table (``dtheta_* dv_*``), body frame RFU; row 0 is zero.
    """
    t = np.asarray(trajectory.index, float)
    lat = trajectory["lat"].to_numpy(float)
    check_latitude(lat, "lat")
    h = trajectory["height"].to_numpy(float)
    v = trajectory[["vel_e", "vel_n", "vel_u"]].to_numpy(float)
    C = euler_to_dcm(
        trajectory["roll"].to_numpy(float),
        trajectory["pitch"].to_numpy(float),
        trajectory["heading"].to_numpy(float),
    )
    if frame_id(frame) == FRAME_WANDER:
        if wander_angle is None:
            wander_angle = (float(trajectory["wander_angle"].iloc[0])
                            if "wander_angle" in trajectory else 0.0)
        dth, dv = inverse_increments_wander(t, lat, trajectory["lon"].to_numpy(float), h, v, C,
                                            wander_angle, earth.gravity_model_id(gravity_model),
                                            attitude_update)
    else:
        if wander_angle is not None:
            raise ConfigError("wander_angle is only used with frame='wander'", column="wander_angle")
        dth, dv = inverse_increments(t, lat, h, v, C, gravity_model, attitude_update)
    return increments_table(t, dth, dv)


@entry
@njit(cache=True)
def _llf_mid_terms_batch(lat, h, v, dt, gravity_model, wie, K, g):
    """:func:`~.strapdown.llf_earth_terms` for every interval."""
    for k in range(dt.shape[0]):
        g[k] = llf_earth_terms(lat[k], h[k], v[k], dt[k], gravity_model, wie[k], K[k])[0]


def inverse_increments(t, lat, h, v, C, gravity_model="somigliana", attitude_update="exact"):
    """Array form of :func:`inverse_mechanize` (ENU frame): returns ``(dtheta, dv)`` (N, 3)."""
    dt = np.diff(np.asarray(t, float))
    n = dt.size
    wie = np.empty((n, 3))
    K = np.empty((n, 3, 3))
    g = np.empty(n)
    _llf_mid_terms_batch(np.ascontiguousarray(lat[:-1], dtype=float),
                         np.ascontiguousarray(h[:-1], dtype=float),
                         np.ascontiguousarray(v[:-1], dtype=float), dt,
                         earth.gravity_model_id(gravity_model), wie, K, g)
    return inverse_step_increments(dt, v[:-1], v[1:], C[:-1], C[1:], wie, K, g, attitude_update)


@entry
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
    check_latitude(lat0, "lat0")
    t = np.ascontiguousarray(t, dtype=float)
    vel = np.ascontiguousarray(vel, dtype=float)
    out = np.empty((t.size, 3))
    _integrate_position(t, vel, float(lat0), float(lon0), float(h0), out)
    return out
