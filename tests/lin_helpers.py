"""Numerical Jacobian of the continuous INS error dynamics (test helper, no hot paths).

The nominal and the true state move along their continuous-time rates (exact INS equations in
ENU: ``dlat = v_n/(M+h)``, ``dlon = v_e/((N+h) cos lat)``, ``dh = v_u``,
``dv = C f - (2 w_ie + w_el) x v + g``, ``dC = [C w x] C - [w_il x] C``); the error state is
``nominal - true`` as defined in insgnss.filter.models (ENU metres at the nominal point, ENU
velocity, ``phi = log(C_nom C_true^T)``, bias estimate minus true bias); the true sensors are
the nominal (compensated) ones plus the bias errors. ``F_num[:, j]`` is the central difference
of ``d(dx)/dt`` over +-eps along error component j (nothing here shares code with the
filter's F).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from insgnss.attitude import dcm_to_rotvec, rotvec_to_dcm, skew
from insgnss.earth import OMEGA_E, normal_gravity, radii


def rates(lat, h, v, C, f_b, w_b, gravity_model="somigliana"):
    M, N = radii(lat)
    wie = np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])
    wel = np.array([-v[1] / (M + h), v[0] / (N + h), v[0] * np.tan(lat) / (N + h)])
    dpos = np.array([v[1] / (M + h), v[0] / ((N + h) * np.cos(lat)), v[2]])
    dv = C @ f_b - np.cross(2 * wie + wel, v) + np.array([0.0, 0.0, -normal_gravity(lat, h, gravity_model)])
    Om = skew(C @ w_b) - skew(wie + wel)
    return dpos, dv, Om


def truth_from_error(nom, dx):
    lat, lon, h, v, C, b = nom
    M, N = radii(lat)
    return (lat - dx[1] / (M + h), lon - dx[0] / ((N + h) * np.cos(lat)), h - dx[2], v - dx[3:6],
            rotvec_to_dcm(-dx[6:9]) @ C, b - dx[9:])


def _radius_rates(lat, h, dlat, dh):
    """d/dt of (M + h) and of (N + h) cos(lat) along (dlat, dh) (radii derivatives by central
    differences, relative error ~1e-12)."""
    e = 1e-6
    (Mp, Np), (Mm, Nm) = radii(lat + e), radii(lat - e)
    dM, dN = (Mp - Mm) / (2 * e), (Np - Nm) / (2 * e)
    _, N = radii(lat)
    return dM * dlat + dh, (dN * dlat + dh) * np.cos(lat) - (N + h) * np.sin(lat) * dlat


def error_rate(nom, dx, f_hat, w_hat, gravity_model, tau=1e-4):
    """d(dx)/dt: position by the chain rule on the error definition (no cancellation),
    velocity from the rates, attitude by a central difference of ``log(C_nom C_true^T)``."""
    lat, lon, h, v, C, _ = nom
    tru = truth_from_error(nom, dx)
    p_n, v_n, O_n = rates(lat, h, v, C, f_hat, w_hat, gravity_model)
    p_t, v_t, O_t = rates(tru[0], tru[2], tru[3], tru[4], f_hat + dx[12:15], w_hat + dx[9:12],
                          gravity_model)
    M, N = radii(lat)
    dRm, dRn = _radius_rates(lat, h, p_n[0], p_n[2])
    Rm, Rn = M + h, (N + h) * np.cos(lat)
    out = np.zeros(15)
    out[0] = dRn * dx[0] / Rn + Rn * (p_n[1] - p_t[1])
    out[1] = dRm * dx[1] / Rm + Rm * (p_n[0] - p_t[0])
    out[2] = p_n[2] - p_t[2]
    out[3:6] = v_n - v_t
    E = C @ tru[4].T
    out[6:9] = (dcm_to_rotvec(expm(O_n * tau) @ E @ expm(-O_t * tau))
                - dcm_to_rotvec(expm(-O_n * tau) @ E @ expm(O_t * tau))) / (2 * tau)
    return out


EPS = np.array([10.0] * 3 + [0.1] * 3 + [1e-4] * 3 + [1e-5] * 3 + [1e-3] * 3)


def numerical_F(lat, lon, h, v, C, f_b, w_b, gravity_model="somigliana", eps=EPS):
    """(15, 15) numerical Jacobian of the core error dynamics."""
    nom = (lat, lon, h, np.asarray(v, float), np.asarray(C, float), np.zeros(6))
    F = np.zeros((15, 15))
    for j in range(15):
        d = np.zeros(15)
        d[j] = eps[j]
        F[:, j] = (error_rate(nom, d, f_b, w_b, gravity_model)
                   - error_rate(nom, -d, f_b, w_b, gravity_model)) / (2 * eps[j])
    return F
