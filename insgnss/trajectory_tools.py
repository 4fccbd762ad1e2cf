"""Trajectory tools as in the ``inu`` package (D. Woodburn): velocity from positions, attitude from
velocity, wind from ground velocity and heading.

Conventions (docs/conventions.md) and how they differ from ``inu``
-----------------------------------------------------------------
``inu`` works in NED: its ``llh_to_vne`` returns (north, east, down) velocity from the *forward
Euler* derivative of position, its ``vne_to_rpy`` and ``est_wind`` take NED velocity. Here
everything is ENU: velocities are ``(vel_e, vel_n, vel_u)``, the body frame is right-forward-up,
and the position rule is the one of our strapdown step (trapezoidal velocity with mid-interval
radii, :func:`insgnss.mechanization.strapdown.position_update`), so ``llh_to_vne`` is its exact
inverse. The Euler angles coincide with inu's NED/FRD ones (roll = roll, pitch = pitch,
heading = yaw, see :mod:`insgnss.attitude`); use :func:`insgnss.attitude.enu_to_ned` to convert
velocities. Arrays hold one sample per *row* (N, 3), not per column as in inu.

References: Groves 2013 sections 2.4 and 5.3 (kinematics); Stevens, Lewis, Johnson 2016
section 2.5 (coordinated turn ``tan(roll) = v omega / g``); inu documentation.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .attitude import wrap_pi
from .earth import check_latitude, normal_gravity, radii
from .errors import InvalidValueError
from .jit import njit
from .mechanization.strapdown import llf_mid_point

VEL_COLS = ["vel_e", "vel_n", "vel_u"]


# --- velocity from positions -----------------------------------------------------------------
@njit(cache=True)
def _trapezoid_inverse(t, lat, dlon, h, v0, out):
    """Invert ``position_update`` sample by sample: ``v_k = 2 dp_k / dt - v_{k-1}`` in metres
    with the radii at the mid point predicted from ``(p_{k-1}, v_{k-1})``."""
    out[0, 0], out[0, 1], out[0, 2] = v0[0], v0[1], v0[2]
    for k in range(1, t.shape[0]):
        dt = t[k] - t[k - 1]
        _, c, h_m, M, N = llf_mid_point(lat[k - 1], h[k - 1], out[k - 1], dt)
        out[k, 1] = 2.0 * (lat[k] - lat[k - 1]) * (M + h_m) / dt - out[k - 1, 1]
        out[k, 0] = 2.0 * dlon[k - 1] * ((N + h_m) * c) / dt - out[k - 1, 0]
        out[k, 2] = 2.0 * (h[k] - h[k - 1]) / dt - out[k - 1, 2]


def llh_to_vne(llh, t=None, *, vel0=None, method: str = "trapezoid"):
    """ENU velocity from geodetic positions over time (``inu.llh_to_vne``).

    Parameters
    ----------
    llh : DataFrame or (N, 3) array
        ``lat lon height`` [rad, rad, m]; a DataFrame is indexed by time [s].
    t : (N,) array, optional
        Times [s] (required for an array ``llh``).
    vel0 : 3-vector, optional
        ENU velocity at the first sample (``"trapezoid"`` only). Without it, the one that makes
        the result smoothest is used (see Notes).
    method : {"trapezoid", "central"}
        ``"trapezoid"``: the exact inverse of the strapdown step's position rule
        (:func:`~insgnss.mechanization.strapdown.position_update`), so
        ``integrate_position(t, llh_to_vne(llh, t, vel0=v0), ...)`` gives back ``llh`` to
        rounding, and a trajectory built from these velocities is reproduced exactly by
        ``mechanize(inverse_mechanize(...))``. ``"central"``: second-order central differences
        (one-sided at the ends), for measured positions.

    Returns
    -------
    DataFrame (``vel_e vel_n vel_u``, same index) for a DataFrame input, else an (N, 3) array.

    Notes
    -----
    The trapezoidal rule ``p_k - p_{k-1} = (v_{k-1} + v_k) dt / 2`` determines the velocities
    only up to an alternating sequence ``(-1)^k c``; without ``vel0``, ``c`` is chosen to
    minimise the sum of squared velocity changes (exact for a trajectory whose velocity changes
    are smooth). It also accumulates position noise in that alternating mode, which is why
    ``"central"`` is offered for measured tracks. Unlike inu (forward Euler, NED: north, east,
    down), the result is ENU.
    """
    if isinstance(llh, pd.DataFrame):
        index = llh.index
        t = np.asarray(index, float)
        arr = llh[["lat", "lon", "height"]].to_numpy(float)
    else:
        index = None
        arr = np.asarray(llh, float)
        if t is None:
            raise InvalidValueError("times are required with an array of positions", column="t")
        t = np.asarray(t, float)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] != t.size or t.size < 2:
        raise InvalidValueError("positions must be (N, 3) lat, lon, height with N >= 2 times",
                                found=arr.shape)
    if not np.all(np.diff(t) > 0):
        raise InvalidValueError("times must increase", column="time")
    lat, lon, h = (np.ascontiguousarray(arr[:, i]) for i in range(3))
    check_latitude(lat, "lat")
    dlon = wrap_pi(np.diff(lon))
    if method == "central":
        M, N = radii(lat)
        ulon = lon[0] + np.concatenate([[0.0], np.cumsum(dlon)])
        vel = np.column_stack([np.gradient(ulon, t, edge_order=2) * (N + h) * np.cos(lat),
                               np.gradient(lat, t, edge_order=2) * (M + h),
                               np.gradient(h, t, edge_order=2)])
    elif method == "trapezoid":
        vel = np.empty((t.size, 3))
        if vel0 is None:
            # remove the alternating mode; repeated because the mid-point radii make the
            # recursion slightly nonlinear in the initial velocity
            v0 = np.zeros(3)
            sign = (-1.0) ** np.arange(1, t.size)
            for _ in range(5):
                _trapezoid_inverse(t, lat, dlon, h, v0, vel)
                c = -(sign[:, None] * np.diff(vel, axis=0)).sum(axis=0) / (2.0 * (t.size - 1))
                v0 = v0 + c
                if np.abs(c).max() < 1e-12:
                    break
        else:
            v0 = np.asarray(vel0, float).reshape(3)
        _trapezoid_inverse(t, lat, dlon, h, v0, vel)
    else:
        raise InvalidValueError(f"unknown method {method!r}", column="method",
                                expected=["trapezoid", "central"])
    if index is not None:
        return pd.DataFrame(vel, index=index, columns=VEL_COLS)
    return vel


# --- attitude from velocity ------------------------------------------------------------------
def vne_to_rpy(vel, t=None, *, g=None, lat=None, height=0.0, turn_rate=None):
    """Roll, pitch and heading of a vehicle that flies along its velocity in coordinated turns
    (``inu.vne_to_rpy``).

    - heading = course ``atan2(v_e, v_n)`` (clockwise from north; held through samples with no
      horizontal speed);
    - pitch = flight-path angle ``atan2(v_u, v_h)`` (no angle of attack);
    - roll = coordinated-turn bank ``atan(v_h dpsi/dt / g)`` (no sideslip; positive right wing
      down in a right turn), with ``dpsi/dt = (v_n a_e - v_e a_n) / v_h^2`` from the velocity's
      second-order time derivative unless ``turn_rate`` is given.

    Parameters
    ----------
    vel : (N, 3) array or DataFrame with ``vel_e vel_n vel_u``
        ENU velocity [m/s] (inu: NED).
    t : (N,) array, optional
        Times [s]; needed unless ``turn_rate`` is given (a DataFrame gives its index).
    g : float or (N,) array, optional
        Gravity [m/s^2]; default the normal gravity at ``lat``, ``height``.
    lat, height : float or (N,) array
        Used for ``g`` when it is not given [rad, m].
    turn_rate : (N,) array, optional
        Known course rate ``dpsi/dt`` [rad/s] (e.g. analytic, in the simulator).

    Returns
    -------
    (roll, pitch, heading) : three (N,) arrays [rad], heading in [0, 2 pi).
    """
    if isinstance(vel, pd.DataFrame):
        if t is None:
            t = np.asarray(vel.index, float)
        vel = vel[VEL_COLS].to_numpy(float)
    v = np.asarray(vel, float)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InvalidValueError("velocity must be (N, 3) east, north, up", found=v.shape)
    if g is None:
        if lat is None:
            raise InvalidValueError("give the gravity g or the latitude lat", column="g")
        check_latitude(lat, "lat")
        g = normal_gravity(lat, height)
    ve, vn, vu = v[:, 0], v[:, 1], v[:, 2]
    vh = np.hypot(ve, vn)
    moving = vh > 1e-9
    if turn_rate is None:
        if t is None:
            raise InvalidValueError("times are required to differentiate the velocity", column="t")
        a = np.gradient(v, np.asarray(t, float), axis=0, edge_order=2)
        turn_rate = np.where(moving, (vn * a[:, 0] - ve * a[:, 1]) / np.where(moving, vh, 1.0) ** 2,
                             0.0)
    roll = np.arctan(vh * np.asarray(turn_rate, float) / g)
    pitch = np.arctan2(vu, vh)
    course = pd.Series(np.where(moving, np.arctan2(ve, vn), np.nan)).ffill().bfill()
    heading = np.mod(course.fillna(0.0).to_numpy(), 2.0 * np.pi)
    return roll, pitch, heading


# --- wind ------------------------------------------------------------------------------------
def _window_sums(t, x, window):
    """Sums of the rows of ``x`` over ``[t_k - window/2, t_k + window/2]`` for every k."""
    c = np.vstack([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    lo = np.searchsorted(t, t - 0.5 * window, side="left")
    hi = np.searchsorted(t, t + 0.5 * window, side="right")
    return c[hi] - c[lo]


def est_wind(vel, heading, airspeed=None, *, t=None, window: float | None = None):
    """Horizontal wind from ground velocity and heading (``inu.est_wind``), for aircraft.

    The ground velocity is the air velocity plus the wind, ``v_g = s (sin A, cos A) + w`` (no
    sideslip; ``s`` the horizontal true airspeed, ``A`` the heading).

    - ``airspeed`` given: ``w = v_g - s (sin A, cos A)`` sample by sample;
    - otherwise airspeed and wind are estimated together by linear least squares, assuming both
      constant over the whole record or over a sliding ``window`` [s] centred on each sample.
      This needs turns: with a constant heading airspeed and wind cannot be told apart, which
      raises :class:`~insgnss.errors.InvalidValueError`.

    Parameters
    ----------
    vel : (N, 2 or 3) array or DataFrame with ``vel_e vel_n``
        Ground velocity, ENU [m/s] (inu: NED).
    heading : (N,) array [rad]
    airspeed : float or (N,) array, optional
        Horizontal true airspeed [m/s].
    t : (N,) array, optional
        Times [s] for ``window`` (a DataFrame gives its index).
    window : float, optional
        Length of the sliding least-squares window [s].

    Returns
    -------
    wind : (N, 2) array
        East and north wind [m/s] (the direction the air moves *to*).
    airspeed : (N,) array
        The given or estimated airspeed [m/s].
    """
    if isinstance(vel, pd.DataFrame):
        if t is None:
            t = np.asarray(vel.index, float)
        vel = vel[["vel_e", "vel_n"]].to_numpy(float)
    v = np.asarray(vel, float)[:, :2]
    A = np.asarray(heading, float)
    s, c = np.sin(A), np.cos(A)
    if airspeed is not None:
        sp = np.broadcast_to(np.asarray(airspeed, float), A.shape).copy()
        return v - sp[:, None] * np.column_stack([s, c]), sp
    # normal equations of [s_k 1 0; c_k 0 1] (airspeed, w_e, w_n) = (v_e, v_n)
    rows = np.column_stack([np.ones_like(s), s, c, v[:, 0] * s + v[:, 1] * c, v[:, 0], v[:, 1]])
    if window is None:
        S = np.broadcast_to(rows.sum(axis=0), rows.shape)
    else:
        if t is None:
            raise InvalidValueError("times are required with a window", column="t")
        S = _window_sums(np.asarray(t, float), rows, float(window))
    n, ss, sc, b0, b1, b2 = S.T
    N = np.zeros((len(A), 3, 3))
    N[:, 0, 0] = n
    N[:, 0, 1] = N[:, 1, 0] = ss
    N[:, 0, 2] = N[:, 2, 0] = sc
    N[:, 1, 1] = N[:, 2, 2] = n
    # determinant relative to n^3: 1 - (mean sin)^2 - (mean cos)^2 = spread of the heading
    spread = 1.0 - (ss / n) ** 2 - (sc / n) ** 2
    if np.any(spread < 1e-6):
        k = int(np.argmax(spread < 1e-6))
        raise InvalidValueError("the heading varies too little to separate wind from airspeed; "
                                "give the airspeed or a longer window", row=k + 1,
                                column="heading", found=f"heading spread {spread[k]:.2e}")
    x = np.linalg.solve(N, np.column_stack([b0, b1, b2])[..., None])[..., 0]
    return x[:, 1:3].copy(), x[:, 0].copy()
