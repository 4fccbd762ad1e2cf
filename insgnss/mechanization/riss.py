"""3D reduced inertial sensor system (3D RISS) mechanization in the local-level frame (ENU).

Sensors: one vertical gyro ``w_z`` (body z, up), two horizontal accelerometers ``f_x`` (right,
transversal) and ``f_y`` (forward), and a forward-speed odometer ``v_od``. The vehicle is assumed
to move along its forward axis (no side slip, no vertical body velocity: the non-holonomic
constraints of a land vehicle), so ``v^l = v_od C_b^l e_y``.

Equations (Noureldin, Karamat & Georgy 2013, ch. 14; Iqbal, Okou &
Noureldin, PLANS 2008). They follow from the LLF specific-force equation
``f^b = C_l^b (dv^l/dt + (2 w_ie^l + w_el^l) x v^l - g^l)`` with ``v^l = v_od C e_y`` and
``C = Rz(-A) Rx(p) Ry(r)``, whose third row is ``(-cos p sin r, sin p, cos p cos r)``:

1. pitch::

       f_y = a_od + g sin p + c_y        =>  p = asin((f_y - a_od - c_y) / g)

2. roll (the centripetal acceleration of a turn is ``-v_od w_lb,z`` on the x axis)::

       f_x = -v_od w_lb,z - g cos p sin r + c_x  =>  r = -asin((f_x + v_od w_lb,z - c_x) / (g cos p))

   ``c = C_l^b ((2 w_ie^l + w_el^l) x v^l)`` is the Coriolis/transport term (a few mm/s^2; the usual
   textbook form neglects it, ``coriolis=False``) and ``w_lb,z = w_z - (C_l^b w_il^l)_z`` the gyro reading
   minus the Earth and transport rates seen by the body z axis.

3. azimuth (heading clockwise from north). The body z rate relative to the l-frame in terms of
   Euler-angle rates is ``w_lb,z = -dA/dt cos p cos r + dp/dt sin r``, hence three variants:

   - ``"level"`` (the textbook form, level vehicle): ``dA/dt = -(w_z - we sin(lat) - v_e tan(lat)/(N+h))``;
   - ``"projected"`` (common in course implementations): the gyro multiplied by
     ``cos p cos r``: ``dA/dt = -(w_z cos p cos r - we sin(lat) - v_e tan(lat)/(N+h))``. This is
     the vertical projection of a body-z rate, the right correction only to first order: it errs
     by ``(1 - cos^2 p cos^2 r)`` of the turn rate, the same order as ``"level"`` but of the
     opposite sign to the exact relation;
   - ``"exact"`` (default, from the relation above)::

         dA/dt = (dp/dt sin r - w_lb,z) / (cos p cos r)

4. velocity: ``v_e = v_od sin A cos p``, ``v_n = v_od cos A cos p``, ``v_u = v_od sin p``.

5. position (meridian radius M in the latitude rate, prime-vertical radius N in the longitude
   rate): ``dlat/dt = v_n / (M + h)``, ``dlon/dt = v_e / ((N + h) cos lat)``, ``dh/dt = v_u``,
   integrated by the trapezoidal rule exactly as :func:`insgnss.mechanization.strapdown.position_update`.

Discretisation. Interval k is ``(t[k-1], t[k]]``. The gyro increment gives the exact mean rate;
the accelerometers give the mean specific force (``dv / dt``); the odometer acceleration of the
interval is ``(v_od[k] - v_od[k-1]) / dt``, so pitch and roll of interval k are the attitude at
its midpoint and are reported at ``t[k]`` (half a sample of lag). The heading is integrated with
these midpoint angles. Optionally (``window > 0``) the specific forces, the odometer acceleration
and the centripetal term are averaged over a centred box window of that length (the same window
for all, so the averages stay consistent): differencing a noisy odometer at 100 Hz would
otherwise ruin the pitch. The window is non-causal by ``window / 2`` (post-processing).

Error compensation: the kernel subtracts the estimated vertical gyro bias and horizontal
accelerometer biases and divides the odometer by ``1 + k`` (odometer scale factor ``k``), so the
same kernel is the nominal-state propagator of the RISS error-state filter
(:mod:`insgnss.filter.riss_model`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .. import earth
from ..aot import entry
from ..attitude import dcm_to_euler
from ..earth import OMEGA_E, normal_gravity_id, radii
from ..errors import DataGapError, InputFormatError, InvalidValueError
from ..imu import increments
from ..jit import njit
from .strapdown import NAV_COLS, NavState, position_update

#: azimuth update identifiers used by the kernel
AZIMUTH_LEVEL = 0
AZIMUTH_PROJECTED = 1
AZIMUTH_EXACT = 2
AZIMUTH_MODES = {"level": AZIMUTH_LEVEL, "projected": AZIMUTH_PROJECTED, "exact": AZIMUTH_EXACT}

#: indices into the kernel state vector ``st``
ST_LAT, ST_LON, ST_H, ST_VE, ST_VN, ST_VU, ST_A, ST_P, ST_R = range(9)
#: indices into the sensor-error parameter vector ``par``
PAR_ODO_SCALE, PAR_GYRO_BIAS_Z, PAR_ACCEL_BIAS_X, PAR_ACCEL_BIAS_Y, PAR_GYRO_SCALE_Z = range(5)
N_PAR = 5

TWO_PI = 2.0 * np.pi


def azimuth_mode_id(name: str | int) -> int:
    """Map ``"level"``, ``"projected"`` or ``"exact"`` to the kernel id."""
    if isinstance(name, int | np.integer) and int(name) in AZIMUTH_MODES.values():
        return int(name)
    try:
        return AZIMUTH_MODES[str(name).lower()]
    except KeyError:
        raise ValueError(
            f"unknown RISS azimuth mode {name!r}; expected one of {sorted(AZIMUTH_MODES)}"
        ) from None


# --- inputs -------------------------------------------------------------------------------------
@dataclass
class RissInputs:
    """Per-interval RISS inputs on the IMU time grid (row k = interval ``(t[k-1], t[k]]``; row 0
    is unused except ``v_od[0]``).

    Attributes
    ----------
    t : (N,) sample times [s]
    dtheta_z : (N,) vertical gyro increment [rad] (raw)
    f_x, f_y : (N,) mean (window-averaged) transversal / forward specific force [m/s^2] (raw)
    a_od : (N,) mean odometer acceleration [m/s^2] (raw odometer, same window)
    v_w : (N,) mean of ``v_od * w_z`` [m/s^2] (raw, same window) - the centripetal term
    v_bar : (N,) mean odometer speed over the same window [m/s] (raw)
    v_od : (N,) odometer speed at the sample times [m/s] (raw)
    window : float
        The averaging window [s] (0: per interval).
    """

    t: np.ndarray
    dtheta_z: np.ndarray
    f_x: np.ndarray
    f_y: np.ndarray
    a_od: np.ndarray
    v_w: np.ndarray
    v_bar: np.ndarray
    v_od: np.ndarray
    window: float = 0.0

    def __len__(self) -> int:
        return int(self.t.size)

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays in kernel argument order."""
        return (self.t, self.dtheta_z, self.f_x, self.f_y, self.a_od, self.v_w, self.v_bar,
                self.v_od)


def odometer_speed(odometer: pd.DataFrame, t: np.ndarray, *, tolerance: float = 1e-6) -> np.ndarray:
    """Odometer forward speed [m/s] at times ``t``.

    ``odometer`` is indexed by time [s] and holds either ``speed`` [m/s] (sampled at its index
    times; linearly interpolated) or ``distance`` increments [m] (row k = distance travelled over
    ``(t[k-1], t[k]]``; the mean speed of each interval is assigned to its midpoint and then
    interpolated linearly). Times outside the odometer span by more than ``tolerance`` raise
    :class:`~insgnss.errors.DataGapError`.
    """
    t = np.asarray(t, float)
    to = np.asarray(odometer.index, float)
    if to.size < 2:
        raise InputFormatError("odometer table needs at least two rows", found=to.size)
    if np.any(np.diff(to) <= 0):
        raise InvalidValueError("odometer times are not strictly increasing", column="time")
    if "speed" in odometer.columns:
        ts, vs = to, odometer["speed"].to_numpy(float)
    elif "distance" in odometer.columns:
        ds = odometer["distance"].to_numpy(float)[1:]
        dto = np.diff(to)
        ts = 0.5 * (to[1:] + to[:-1])
        vs = ds / dto
        # extend to the first and last odometer times (constant mean speed at the ends)
        ts = np.concatenate([[to[0]], ts, [to[-1]]])
        vs = np.concatenate([[vs[0]], vs, [vs[-1]]])
    else:
        raise InputFormatError("odometer table needs a 'speed' or a 'distance' column",
                               expected="speed [m/s] or distance [m]", found=list(odometer.columns))
    if not np.all(np.isfinite(vs)):
        raise InvalidValueError("odometer holds NaN or inf", column="speed/distance")
    if t[0] < ts[0] - tolerance or t[-1] > ts[-1] + tolerance:
        raise DataGapError(
            "odometer does not cover the IMU time span",
            expected=f"[{t[0]:.3f}, {t[-1]:.3f}] s", found=f"[{ts[0]:.3f}, {ts[-1]:.3f}] s",
        )
    return np.interp(t, ts, vs)


def _box_average(t: np.ndarray, cum: np.ndarray, window: float) -> np.ndarray:
    """Centred box average of a signal whose running integral at the times ``t`` is ``cum``.

    Returns the average over ``[m_k - w/2, m_k + w/2]`` (clipped to the data span) for each
    interval midpoint ``m_k``, k = 1..N-1 (row 0 set to row 1). ``cum`` is interpolated linearly
    (exact for a signal that is constant over each interval).
    """
    m = 0.5 * (t[1:] + t[:-1])
    lo = np.maximum(m - 0.5 * window, t[0])
    hi = np.minimum(m + 0.5 * window, t[-1])
    out = np.empty_like(t)
    out[1:] = (np.interp(hi, t, cum) - np.interp(lo, t, cum)) / (hi - lo)
    out[0] = out[1] if t.size > 1 else 0.0
    return out


def riss_inputs(imu: pd.DataFrame, odometer: pd.DataFrame | np.ndarray, *,
                window: float = 0.0) -> RissInputs:
    """Build the per-interval RISS inputs from an IMU table and an odometer.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments, :mod:`insgnss.imu`), body frame right-forward-up. Only
        ``gyro_z``/``dtheta_z`` and the x and y accelerometers are used.
    odometer : DataFrame or array
        Odometer table (``speed`` or ``distance``, see :func:`odometer_speed`) or an array of
        forward speeds at the IMU times.
    window : float
        Centred averaging window [s] for the specific forces, the odometer acceleration and
        the centripetal term (0: one IMU interval).
    """
    t, dth, dv = increments(imu)
    if t.size < 2:
        raise InputFormatError("IMU table needs at least two rows", found=t.size)
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise InvalidValueError("IMU times are not strictly increasing", column="time")
    if isinstance(odometer, pd.DataFrame):
        v = odometer_speed(odometer, t)
    else:
        v = np.asarray(odometer, float)
        if v.shape != t.shape:
            raise InputFormatError("odometer array must have one speed per IMU sample",
                                   expected=t.shape, found=v.shape)
    dthz = np.ascontiguousarray(dth[:, 2], dtype=float)
    vbar_k = 0.5 * (v[1:] + v[:-1])
    if window <= 0.0:
        fx = np.empty_like(t)
        fy = np.empty_like(t)
        a = np.empty_like(t)
        vw = np.empty_like(t)
        vb = np.empty_like(t)
        fx[1:] = dv[1:, 0] / dt
        fy[1:] = dv[1:, 1] / dt
        a[1:] = np.diff(v) / dt
        vw[1:] = vbar_k * dthz[1:] / dt
        vb[1:] = vbar_k
        for x in (fx, fy, a, vw, vb):
            x[0] = x[1]
    else:
        zero = np.zeros(1)
        fx = _box_average(t, np.concatenate([zero, np.cumsum(dv[1:, 0])]), window)
        fy = _box_average(t, np.concatenate([zero, np.cumsum(dv[1:, 1])]), window)
        a = _box_average(t, v - v[0], window)
        vw = _box_average(t, np.concatenate([zero, np.cumsum(vbar_k * dthz[1:])]), window)
        vb = _box_average(t, np.concatenate([zero, np.cumsum(vbar_k * dt)]), window)
    return RissInputs(t, dthz, fx, fy, a, vw, vb, np.ascontiguousarray(v), float(window))


# --- the compiled step ------------------------------------------------------------------------------
@entry
@njit(cache=True)
def riss_dcm_col(A, p, r, out):
    """Rows of ``C_b^l`` needed by the kernel: ``out[0] = C[:, 0]`` (body x in ENU),
    ``out[1] = C[:, 1]`` (body y), ``out[2] = C[:, 2]`` (body z)."""
    sa, ca = np.sin(A), np.cos(A)
    sp, cp = np.sin(p), np.cos(p)
    sr, cr = np.sin(r), np.cos(r)
    out[0, 0] = ca * cr + sa * sp * sr
    out[0, 1] = -sa * cr + ca * sp * sr
    out[0, 2] = -cp * sr
    out[1, 0] = sa * cp
    out[1, 1] = ca * cp
    out[1, 2] = sp
    out[2, 0] = ca * sr - sa * sp * cr
    out[2, 1] = -sa * sr - ca * sp * cr
    out[2, 2] = cp * cr


@njit(cache=True)
def riss_step(st, k, t, dthz, fx, fy, aod, vw, vbar, vod, par, gravity_model, az_mode, coriolis,
              cols, aux):
    """Advance the RISS state ``st`` (see ``ST_*``) in place over interval k = (t[k-1], t[k]].

    ``par`` holds the sensor-error estimates (``PAR_*``: odometer scale, gyro z bias, accel x and
    y biases, gyro z scale factor); ``cols`` is a (5, 3) scratch array. ``aux`` (length 9)
    receives quantities of the interval for the error model (all compensated):
    ``[w_lb_z, v_mean, a_od, g, dA/dt, w_il_bz, v_od(t[k]), w_z, dp/dt]``.
    """
    dt = t[k] - t[k - 1]
    lat, lon, h = st[ST_LAT], st[ST_LON], st[ST_H]
    ve, vn, vu = st[ST_VE], st[ST_VN], st[ST_VU]
    A0, p0, r0 = st[ST_A], st[ST_P], st[ST_R]
    s = 1.0 / (1.0 + par[PAR_ODO_SCALE])
    bgz = par[PAR_GYRO_BIAS_Z]
    sg = 1.0 / (1.0 + par[PAR_GYRO_SCALE_Z])
    M, N = radii(lat)
    slat, clat = np.sin(lat), np.cos(lat)
    g = normal_gravity_id(lat, h, gravity_model)
    wie_n, wie_u = OMEGA_E * clat, OMEGA_E * slat
    wel_e = -vn / (M + h)
    wel_n = ve / (N + h)
    wel_u = ve * slat / clat / (N + h)
    riss_dcm_col(A0, p0, r0, cols)
    # Earth + transport rate seen by the body z axis
    wil_bz = cols[2, 0] * wel_e + cols[2, 1] * (wie_n + wel_n) + cols[2, 2] * (wie_u + wel_u)
    if coriolis:
        ce, cn, cu = wel_e, 2.0 * wie_n + wel_n, 2.0 * wie_u + wel_u
        ae = cn * vu - cu * vn
        an = cu * ve - ce * vu
        au = ce * vn - cn * ve
        cor_x = cols[0, 0] * ae + cols[0, 1] * an + cols[0, 2] * au
        cor_y = cols[1, 0] * ae + cols[1, 1] * an + cols[1, 2] * au
        wil_cent = wil_bz
    else:
        cor_x = 0.0
        cor_y = 0.0
        wil_cent = 0.0
    # pitch (item 1 of the module docstring) and roll (item 2) of the interval
    a = aod[k] * s
    u = (fy[k] - par[PAR_ACCEL_BIAS_Y] - a - cor_y) / g
    u = min(1.0, max(-1.0, u))
    p = np.arcsin(u)
    cp = np.cos(p)
    v_mean = vbar[k] * s
    cent = s * sg * (vw[k] - bgz * vbar[k]) - v_mean * wil_cent
    w = -(fx[k] - par[PAR_ACCEL_BIAS_X] + cent - cor_x) / (g * cp)
    w = min(1.0, max(-1.0, w))
    r = np.arcsin(w)
    cr = np.cos(r)
    # azimuth (item 3 and its variants)
    wz = (dthz[k] / dt - bgz) * sg
    pdot = (p - p0) / dt if k > 1 else 0.0
    wil_up = wie_u + wel_u
    if az_mode == AZIMUTH_LEVEL:
        adot = -(wz - wil_up)
    elif az_mode == AZIMUTH_PROJECTED:
        adot = -(wz * cp * cr - wil_up)
    else:
        adot = (pdot * np.sin(r) - (wz - wil_bz)) / (cp * cr)
    A = A0 + adot * dt
    if A < 0.0:
        A += TWO_PI
    elif A >= TWO_PI:
        A -= TWO_PI
    # velocity (item 4) at t[k] and position (item 5)
    vk = vod[k] * s
    vel_old = cols[3]
    vel_old[0], vel_old[1], vel_old[2] = ve, vn, vu
    vel_new = cols[4]
    vel_new[0] = vk * np.sin(A) * cp
    vel_new[1] = vk * np.cos(A) * cp
    vel_new[2] = vk * u
    lat1, lon1, h1 = position_update(lat, lon, h, vel_old, vel_new, dt)
    st[ST_LAT], st[ST_LON], st[ST_H] = lat1, lon1, h1
    st[ST_VE], st[ST_VN], st[ST_VU] = vel_new[0], vel_new[1], vel_new[2]
    st[ST_A], st[ST_P], st[ST_R] = A, p, r
    aux[0] = wz - wil_bz
    aux[1] = v_mean
    aux[2] = a
    aux[3] = g
    aux[4] = adot
    aux[5] = wil_bz
    aux[6] = vk
    aux[7] = wz
    aux[8] = pdot


@entry
@njit(cache=True)
def riss_velocity(st, v):
    """Set the velocity of ``st`` from speed ``v`` (odometer, corrected), heading and pitch."""
    cp = np.cos(st[ST_P])
    st[ST_VE] = v * np.sin(st[ST_A]) * cp
    st[ST_VN] = v * np.cos(st[ST_A]) * cp
    st[ST_VU] = v * np.sin(st[ST_P])


@njit(cache=True)
def _riss_kernel(t, dthz, fx, fy, aod, vw, vbar, vod, st0, par, gravity_model, az_mode, coriolis,
                 out):
    st = st0.copy()
    cols = np.empty((5, 3))
    aux = np.empty(9)
    riss_velocity(st, vod[0] / (1.0 + par[PAR_ODO_SCALE]))
    for j in range(9):
        out[0, j] = st[j]
    for k in range(1, t.shape[0]):
        riss_step(st, k, t, dthz, fx, fy, aod, vw, vbar, vod, par, gravity_model, az_mode,
                  coriolis, cols, aux)
        for j in range(9):
            out[k, j] = st[j]
    return st


def initial_riss_state(initial: NavState) -> np.ndarray:
    """Kernel state vector ``[lat, lon, h, ve, vn, vu, A, p, r]`` from a :class:`NavState`."""
    r, p, a = dcm_to_euler(initial.C)
    v = np.asarray(initial.vel, float)
    return np.array([initial.lat, initial.lon, initial.height, v[0], v[1], v[2],
                     float(a), float(p), float(r)])


def mechanize_riss(
    imu: pd.DataFrame,
    odometer: pd.DataFrame | np.ndarray,
    initial: NavState,
    *,
    azimuth: str = "exact",
    coriolis: bool = True,
    window: float = 0.0,
    gravity_model: str = "somigliana",
    odometer_scale: float = 0.0,
    gyro_bias_z: float = 0.0,
    accel_bias_xy: tuple[float, float] = (0.0, 0.0),
    gyro_scale_z: float = 0.0,
    inputs: RissInputs | None = None,
) -> pd.DataFrame:
    """3D RISS mechanization of an IMU table and an odometer.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments), body right-forward-up; only the vertical gyro and the
        x (transversal) and y (forward) accelerometers are used.
    odometer : DataFrame or array
        Forward speed ``speed`` [m/s] or ``distance`` increments [m] indexed by time, or an
        array of speeds at the IMU times.
    initial : NavState
        Position and attitude at the first IMU sample (heading is used; the initial pitch and
        roll are reported for row 0 only; the initial velocity comes from the odometer).
    azimuth : {"exact", "projected", "level"}
        Azimuth equation (module docstring, item 3).
    coriolis : bool
        Compensate the Coriolis/transport term in pitch and roll and the Earth/transport rate
        seen by the body z axis in the centripetal term (False: the textbook pitch and roll, items 1-2). The
        azimuth always removes the Earth and transport rates.
    window : float
        Centred averaging window [s] for specific force, odometer acceleration and centripetal
        term (0: per IMU interval).
    gravity_model : {"somigliana", "grs80_series"}
    odometer_scale, gyro_bias_z, accel_bias_xy, gyro_scale_z
        Known sensor errors to compensate: odometer scale factor ``k`` (``v = v_od / (1 + k)``),
        vertical gyro bias [rad/s], x and y accelerometer biases [m/s^2], vertical gyro scale
        factor (``w = (w_z - b) / (1 + s)``).
    inputs : RissInputs, optional
        Pre-built inputs (skips :func:`riss_inputs`; ``imu``, ``odometer`` and ``window`` are
        then ignored).

    Returns
    -------
    DataFrame
        Indexed by time with ``NAV_COLS`` (``lat lon height vel_e vel_n vel_u roll pitch
        heading``; rad, m, m/s).
    """
    if inputs is None:
        inputs = riss_inputs(imu, odometer, window=window)
    st0 = initial_riss_state(initial)
    par = np.array([odometer_scale, gyro_bias_z, accel_bias_xy[0], accel_bias_xy[1],
                    gyro_scale_z], float)
    out = np.empty((len(inputs), 9))
    _riss_kernel(*inputs.arrays(), st0, par, earth.gravity_model_id(gravity_model),
                 azimuth_mode_id(azimuth), bool(coriolis), out)
    # kernel order is lat lon h ve vn vu A p r; NAV_COLS ends roll pitch heading
    data = out[:, [0, 1, 2, 3, 4, 5, 8, 7, 6]]
    return pd.DataFrame(data, index=pd.Index(inputs.t, name="time"), columns=NAV_COLS)
