"""Local-level-frame (ENU) strapdown mechanization.

One step from epoch k-1 to k, given the angular and velocity increments ``dtheta``, ``dv`` of
the interval (body frame, right-forward-up), follows seed 000 sections 2.4-2.6 (Noureldin et al.
2013, section 5.5):

1. Earth and transport rates at k-1 (eqs. 15, 22, 23)::

       w_il^l = w_ie^l + w_el^l
       theta_lb = dtheta - C_l^b w_il^l dt                         (eq. 16)

2. Attitude: ``C_k = C_{k-1} exp([theta_lb x])`` (exact rotation-vector update), or the seed's
   first-order quaternion update ``q_k = q_{k-1} + 1/2 U q_{k-1}`` followed by normalisation
   (eq. 18). The normalised first-order update is exactly a rotation about ``theta_lb`` by the
   angle ``2 atan(|theta_lb| / 2)``, which is how it is computed here.

3. Velocity with the specific-force increment rotated by the mid-interval attitude
   ``C_mid = C_{k-1} exp([theta_lb/2 x])`` (rotation compensation), Coriolis and normal
   gravity at k-1 (eq. 24)::

       v_k = v_{k-1} + C_mid dv + (g^l - (2 w_ie^l + w_el^l) x v_{k-1}) dt

   For rate inputs the increments are the trapezoidal integrals of the samples, so this is the
   seed's trapezoidal velocity integration (eq. 25).

4. Position by the trapezoidal rule on velocity (eqs. 26-28) with the radii at k-1.

Every step is invertible in closed form, which is what makes :mod:`.inverse` an exact dual.
The same compiled step serves the batch :func:`mechanize`, the seed-compatible
:class:`INSMechanization` and the Kalman filter's nominal-state propagation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numba import njit

from .. import earth
from ..attitude import dcm_to_euler, euler_to_dcm, rotvec_to_dcm_nb
from ..earth import OMEGA_E, normal_gravity_id, radii
from ..imu import coning_sculling, increments

NAV_COLS = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]

#: attitude update identifiers used by the kernel
ATTITUDE_EXACT = 0
ATTITUDE_FIRST_ORDER = 1
ATTITUDE_UPDATES = {"exact": ATTITUDE_EXACT, "first_order": ATTITUDE_FIRST_ORDER}


@dataclass
class NavState:
    """Navigation state: position (lat, lon [rad], height [m]), ENU velocity [m/s] and
    attitude ``C_b^l``.

    Use :meth:`from_euler` to build one from roll, pitch, heading.
    """

    lat: float
    lon: float
    height: float
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    C: np.ndarray = field(default_factory=lambda: np.eye(3))
    time: float = 0.0

    @classmethod
    def from_euler(
        cls,
        lat: float,
        lon: float,
        height: float,
        vel=(0.0, 0.0, 0.0),
        roll: float = 0.0,
        pitch: float = 0.0,
        heading: float = 0.0,
        time: float = 0.0,
        degrees: bool = False,
    ) -> NavState:
        """State from Euler angles (seed convention). ``degrees`` applies to lat, lon, angles."""
        k = np.pi / 180.0 if degrees else 1.0
        C = euler_to_dcm(roll * k, pitch * k, heading * k)
        return cls(lat * k, lon * k, float(height), np.asarray(vel, float).copy(), C, float(time))

    @property
    def euler(self) -> tuple[float, float, float]:
        """(roll, pitch, heading) [rad]."""
        r, p, a = dcm_to_euler(self.C)
        return float(r), float(p), float(a)

    def copy(self) -> NavState:
        return NavState(self.lat, self.lon, self.height, self.vel.copy(), self.C.copy(), self.time)


# --- the compiled step -----------------------------------------------------------------------------
@njit(cache=True)
def position_update(lat, lon, h, v_old, v_new, dt):
    """Trapezoidal position update (seed eqs. 26-28) with the radii at the old position."""
    M, N = radii(lat)
    lat_new = lat + 0.5 * (v_old[1] + v_new[1]) / (M + h) * dt
    lon_new = lon + 0.5 * (v_old[0] + v_new[0]) / ((N + h) * np.cos(lat)) * dt
    h_new = h + 0.5 * (v_old[2] + v_new[2]) * dt
    return lat_new, lon_new, h_new


@njit(cache=True)
def first_order_angle_scale(theta_norm):
    """Ratio of the rotation angle applied by the normalised first-order quaternion update to
    ``|theta|``: ``2 atan(|theta|/2) / |theta|``."""
    if theta_norm < 1e-8:
        return 1.0 - theta_norm * theta_norm / 12.0
    return 2.0 * np.arctan(0.5 * theta_norm) / theta_norm


@njit(cache=True)
def strapdown_step(pos, vel, C, dth, dv, dt, gravity_model, attitude_update, fix_height, work):
    """Advance ``pos = [lat, lon, h]``, ``vel`` (ENU) and ``C`` (C_b^l) in place by one interval.

    ``work`` is a (4, 3, 3) scratch array (avoids allocations in the hot loop).
    """
    lat, lon, h = pos[0], pos[1], pos[2]
    ve, vn, vu = vel[0], vel[1], vel[2]
    M, N = radii(lat)
    slat, clat = np.sin(lat), np.cos(lat)
    # Earth rate (eq. 22) and transport rate (eq. 23) in ENU
    wie_n, wie_u = OMEGA_E * clat, OMEGA_E * slat
    wel_e = -vn / (M + h)
    wel_n = ve / (N + h)
    wel_u = ve * slat / clat / (N + h)
    wil_e, wil_n, wil_u = wel_e, wie_n + wel_n, wie_u + wel_u
    # theta_lb = dtheta - C^T w_il dt   (eq. 16)
    th = work[3, 0]
    th[0] = dth[0] - (C[0, 0] * wil_e + C[1, 0] * wil_n + C[2, 0] * wil_u) * dt
    th[1] = dth[1] - (C[0, 1] * wil_e + C[1, 1] * wil_n + C[2, 1] * wil_u) * dt
    th[2] = dth[2] - (C[0, 2] * wil_e + C[1, 2] * wil_n + C[2, 2] * wil_u) * dt
    if attitude_update == ATTITUDE_FIRST_ORDER:
        k = first_order_angle_scale(np.sqrt(th[0] ** 2 + th[1] ** 2 + th[2] ** 2))
        th[0] *= k
        th[1] *= k
        th[2] *= k
    half = work[3, 1]
    half[0], half[1], half[2] = 0.5 * th[0], 0.5 * th[1], 0.5 * th[2]
    E = work[0]
    Eh = work[1]
    Cm = work[2]
    rotvec_to_dcm_nb(th, E)
    rotvec_to_dcm_nb(half, Eh)
    # C_mid = C Exp(theta/2);  C_new = C Exp(theta)
    for i in range(3):
        c0, c1, c2 = C[i, 0], C[i, 1], C[i, 2]
        for j in range(3):
            Cm[i, j] = c0 * Eh[0, j] + c1 * Eh[1, j] + c2 * Eh[2, j]
        for j in range(3):
            C[i, j] = c0 * E[0, j] + c1 * E[1, j] + c2 * E[2, j]
    # velocity (eq. 24): C_mid dv - (2 w_ie + w_el) x v dt + g dt
    g = normal_gravity_id(lat, h, gravity_model)
    ce = wel_e
    cn = 2.0 * wie_n + wel_n
    cu = 2.0 * wie_u + wel_u
    ae = cn * vu - cu * vn  # (2 w_ie + w_el) x v
    an = cu * ve - ce * vu
    au = ce * vn - cn * ve
    dve = Cm[0, 0] * dv[0] + Cm[0, 1] * dv[1] + Cm[0, 2] * dv[2] - ae * dt
    dvn = Cm[1, 0] * dv[0] + Cm[1, 1] * dv[1] + Cm[1, 2] * dv[2] - an * dt
    dvu = Cm[2, 0] * dv[0] + Cm[2, 1] * dv[1] + Cm[2, 2] * dv[2] - (au + g) * dt
    v_old = work[3, 2]
    v_old[0], v_old[1], v_old[2] = ve, vn, vu
    vel[0] = ve + dve
    vel[1] = vn + dvn
    vel[2] = 0.0 if fix_height else vu + dvu
    pos[0], pos[1], pos[2] = position_update(lat, lon, h, v_old, vel, dt)


@njit(cache=True)
def _mechanize_kernel(t, dth, dv, pos0, vel0, C0, gravity_model, attitude_update, fix_height, out):
    """Run the strapdown over all samples; ``out`` (N, 9) receives NAV_COLS per sample."""
    pos = pos0.copy()
    vel = vel0.copy()
    C = C0.copy()
    work = np.empty((4, 3, 3))
    n = t.shape[0]
    for k in range(n):
        if k > 0:
            strapdown_step(pos, vel, C, dth[k], dv[k], t[k] - t[k - 1], gravity_model,
                           attitude_update, fix_height, work)
        out[k, 0], out[k, 1], out[k, 2] = pos[0], pos[1], pos[2]
        out[k, 3], out[k, 4], out[k, 5] = vel[0], vel[1], vel[2]
        out[k, 6] = np.arctan2(-C[2, 0], C[2, 2])
        out[k, 7] = np.arctan2(C[2, 1], np.sqrt(C[0, 1] ** 2 + C[1, 1] ** 2))
        a = np.arctan2(C[0, 1], C[1, 1])
        out[k, 8] = a + 2.0 * np.pi if a < 0.0 else a
    return pos, vel, C


def attitude_update_id(name: str | int) -> int:
    if isinstance(name, int | np.integer):
        return int(name)
    try:
        return ATTITUDE_UPDATES[name]
    except KeyError:
        raise ValueError(
            f"unknown attitude update {name!r}; expected one of {sorted(ATTITUDE_UPDATES)}"
        ) from None


def mechanize(
    imu: pd.DataFrame,
    initial: NavState,
    *,
    gravity_model: str = "somigliana",
    attitude_update: str = "exact",
    coning: bool = False,
    fix_height: bool = False,
    return_final: bool = False,
):
    """Free-inertial strapdown mechanization of an IMU table.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments, see :mod:`insgnss.imu`) indexed by time [s]. The first
        row is the epoch of ``initial``; navigation starts with the second row.
    initial : NavState
        State at the time of the first row.
    gravity_model : {"somigliana", "grs80_series"}
    attitude_update : {"exact", "first_order"}
        Exact rotation-vector update, or the seed's first-order quaternion update (eq. 18).
    coning : bool
        Apply two-sample coning/sculling corrections to the increments.
    fix_height : bool
        Hold height and vertical velocity at their initial values (a 2-D free-inertial run;
        the free vertical channel is unstable with time constant ``sqrt(R / 2g)`` ~ 9.5 min).
    return_final : bool
        Also return the final :class:`NavState`.

    Returns
    -------
    DataFrame
        Indexed by time with columns ``lat lon height vel_e vel_n vel_u roll pitch heading``
        (rad, m, m/s).
    """
    t, dth, dv = increments(imu)
    if coning:
        dth, dv = coning_sculling(dth, dv)
    out = np.empty((t.size, 9))
    pos0 = np.array([initial.lat, initial.lon, initial.height], float)
    pos, vel, C = _mechanize_kernel(
        t, np.ascontiguousarray(dth), np.ascontiguousarray(dv), pos0,
        np.asarray(initial.vel, float), np.ascontiguousarray(initial.C, dtype=float),
        earth.gravity_model_id(gravity_model), attitude_update_id(attitude_update),
        bool(fix_height), out,
    )
    df = pd.DataFrame(out, index=pd.Index(t, name="time"), columns=NAV_COLS)
    if return_final:
        return df, NavState(pos[0], pos[1], pos[2], vel, C, float(t[-1]))
    return df
