"""Foot-mounted pedestrian INS: stance detection, ZUPT + ZARU error-state filter, smoother.

Model
-----
The nominal trajectory is the LLF (ENU) strapdown of :mod:`insgnss.mechanization.strapdown`
driven by bias-compensated increments. A 15-state error-state Kalman filter estimates

    x = [dp (ENU, m), dv (ENU, m/s), phi (l-frame misalignment, rad), dbg (rad/s), dba (m/s^2)]

with the conventions ``est = true + error`` for p, v and the biases and
``C_est = exp([phi x]) C_true`` for attitude (:func:`insgnss.attitude.attitude_error`). The
continuous error dynamics used between updates are the short-term pedestrian form
(Groves 2013 eq. 14.63 with the Earth-rate, transport-rate and gravity-gradient couplings
dropped: over a walk of minutes they are below 1e-4 of the retained terms)::

    d(dp)/dt  = dv
    d(dv)/dt  = -[f^l x] phi - C dba + w_a
    d(phi)/dt = -C dbg + w_g
    d(db)/dt  = w_b        (random walk)

discretised per IMU interval as ``Phi = I + F dt``, ``Qd = diag(q) dt``. The nominal itself keeps
the full Earth model (Earth rate, transport rate, normal gravity).

Measurements (the same models as :mod:`insgnss.filter.measurements` ``Zupt`` / ``Zaru``)::

    ZUPT  z = v_est               H = [0  I  0  0  0]   R = sigma_zupt^2 I
    ZARU  z = w_meas - bg_est - C^T w_ie^l
                                  H = [0  0  0 -I  0]   R = sigma_zaru^2 I

applied on samples the stillness detector (:mod:`insgnss.detect`) declares still, every
``update_every``-th still sample. Closed loop: after each update the estimate is fed back into
the nominal and the error state reset to zero.

Smoother: the optional backward pass is the modified Bryson-Frazier form of the RTS smoother
(Bierman 1973), which needs no inverse of the predicted covariance::

    lambda~_k = H^T S^-1 nu + (I - K H)^T lambda^_k      (per update, in reverse order)
    lambda^_{k-1} = Phi^T lambda~_k
    x^s_k = P_{k|k} lambda^_k                          (relative to the fed-back nominal)

Everything per IMU sample (strapdown, covariance, updates, smoother) runs in one compiled
kernel, so the whole filter costs a few microseconds per sample.

Initial conditions: roll and pitch from accelerometer levelling over the first still window
(``f^b = C^T [0, 0, g]``, so ``roll = atan2(-f_x, f_z)``, ``pitch = atan2(f_y, hypot(f_x,
f_z))``), gyro bias from the mean rate over that window, and heading given by the caller or 0:
with only ZUPT and ZARU the heading is unobservable (no measurement depends on it), so the
filter keeps the initial heading up to gyro drift, and a foot-mounted trajectory is determined
up to a rotation about the vertical through its start.

References: Foxlin 2005 (IEEE CG&A 25(6), "Pedestrian tracking with shoe-mounted inertial
sensors"); Skog et al. 2010 (IEEE TBME 57(11)); Nilsson et al. 2012 ("Foot-mounted INS for
everybody - an open-source embedded implementation", OpenShoe); Wagstaff et al. 2019 (PyShoe).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

import numpy as np
import pandas as pd
from numba import njit

from . import earth
from .align import level
from .attitude import euler_to_dcm, euler_to_dcm_nb, rotvec_to_dcm_nb
from .detect import DetectorConfig, Stillness, detect_arrays, imu_rates
from .earth import OMEGA_E, radii
from .errors import AlignmentError, ConfigError
from .imu import increments
from .mechanization.strapdown import NAV_COLS, STEP_WORK_SHAPE, NavState, strapdown_step

N_STATES = 15
IP, IV, IA, IG, IB = 0, 3, 6, 9, 12  # block offsets: position, velocity, attitude, gyro, accel bias

BIAS_COLS = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "accel_bias_x", "accel_bias_y",
             "accel_bias_z"]
STD_COLS = ["east_std", "north_std", "up_std", "vel_e_std", "vel_n_std", "vel_u_std",
            "roll_std", "pitch_std", "heading_std"]


# --- compiled pieces -------------------------------------------------------------------------
@njit(cache=True)
def _propagate_cov(P, A, f, C, dt, qv, qa, qg, qb):
    """``P <- Phi P Phi^T + Q dt`` with the sparse ``Phi = I + F dt`` of the module docstring."""
    n = N_STATES
    for j in range(n):
        for i in range(3):
            A[i, j] = P[i, j] + dt * P[3 + i, j]
        pa0, pa1, pa2 = P[6, j], P[7, j], P[8, j]
        cx = pa1 * f[2] - pa2 * f[1]  # phi x f  (= -[f x] phi)
        cy = pa2 * f[0] - pa0 * f[2]
        cz = pa0 * f[1] - pa1 * f[0]
        b0, b1, b2 = P[12, j], P[13, j], P[14, j]
        g0, g1, g2 = P[9, j], P[10, j], P[11, j]
        A[3, j] = P[3, j] + dt * (cx - (C[0, 0] * b0 + C[0, 1] * b1 + C[0, 2] * b2))
        A[4, j] = P[4, j] + dt * (cy - (C[1, 0] * b0 + C[1, 1] * b1 + C[1, 2] * b2))
        A[5, j] = P[5, j] + dt * (cz - (C[2, 0] * b0 + C[2, 1] * b1 + C[2, 2] * b2))
        A[6, j] = pa0 - dt * (C[0, 0] * g0 + C[0, 1] * g1 + C[0, 2] * g2)
        A[7, j] = pa1 - dt * (C[1, 0] * g0 + C[1, 1] * g1 + C[1, 2] * g2)
        A[8, j] = pa2 - dt * (C[2, 0] * g0 + C[2, 1] * g1 + C[2, 2] * g2)
        for i in range(9, n):
            A[i, j] = P[i, j]
    # P = A Phi^T: apply the same row operation to the rows of A, written as columns of P
    for j in range(n):
        for i in range(3):
            P[j, i] = A[j, i] + dt * A[j, 3 + i]
        pa0, pa1, pa2 = A[j, 6], A[j, 7], A[j, 8]
        cx = pa1 * f[2] - pa2 * f[1]
        cy = pa2 * f[0] - pa0 * f[2]
        cz = pa0 * f[1] - pa1 * f[0]
        b0, b1, b2 = A[j, 12], A[j, 13], A[j, 14]
        g0, g1, g2 = A[j, 9], A[j, 10], A[j, 11]
        P[j, 3] = A[j, 3] + dt * (cx - (C[0, 0] * b0 + C[0, 1] * b1 + C[0, 2] * b2))
        P[j, 4] = A[j, 4] + dt * (cy - (C[1, 0] * b0 + C[1, 1] * b1 + C[1, 2] * b2))
        P[j, 5] = A[j, 5] + dt * (cz - (C[2, 0] * b0 + C[2, 1] * b1 + C[2, 2] * b2))
        P[j, 6] = pa0 - dt * (C[0, 0] * g0 + C[0, 1] * g1 + C[0, 2] * g2)
        P[j, 7] = pa1 - dt * (C[1, 0] * g0 + C[1, 1] * g1 + C[1, 2] * g2)
        P[j, 8] = pa2 - dt * (C[2, 0] * g0 + C[2, 1] * g1 + C[2, 2] * g2)
        for i in range(9, n):
            P[j, i] = A[j, i]
    for i in range(3):
        P[3 + i, 3 + i] += qv * dt
        P[6 + i, 6 + i] += qa * dt
        P[9 + i, 9 + i] += qg * dt
        P[12 + i, 12 + i] += qb * dt


@njit(cache=True)
def _adjoint_back(lam, f, C, dt):
    """``lambda <- Phi^T lambda`` for the same ``Phi`` as :func:`_propagate_cov`."""
    l0, l1, l2 = lam[0], lam[1], lam[2]
    v0, v1, v2 = lam[3], lam[4], lam[5]
    a0, a1, a2 = lam[6], lam[7], lam[8]
    # (F^T lam)[3:6] += lam_p ; [6:9] += f x lam_v ; [12:15] += -C^T lam_v ; [9:12] += -C^T lam_a
    lam[3] = v0 + dt * l0
    lam[4] = v1 + dt * l1
    lam[5] = v2 + dt * l2
    lam[6] = a0 + dt * (f[1] * v2 - f[2] * v1)
    lam[7] = a1 + dt * (f[2] * v0 - f[0] * v2)
    lam[8] = a2 + dt * (f[0] * v1 - f[1] * v0)
    for i in range(3):
        lam[9 + i] -= dt * (C[0, i] * a0 + C[1, i] * a1 + C[2, i] * a2)
        lam[12 + i] -= dt * (C[0, i] * v0 + C[1, i] * v1 + C[2, i] * v2)


@njit(cache=True)
def _inv3(S, out):
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 0], S[1, 1], S[1, 2]
    g, h, i = S[2, 0], S[2, 1], S[2, 2]
    A = e * i - f * h
    B = -(d * i - f * g)
    Cc = d * h - e * g
    det = a * A + b * B + c * Cc
    out[0, 0] = A / det
    out[1, 0] = B / det
    out[2, 0] = Cc / det
    out[0, 1] = -(b * i - c * h) / det
    out[1, 1] = (a * i - c * g) / det
    out[2, 1] = -(a * h - b * g) / det
    out[0, 2] = (b * f - c * e) / det
    out[1, 2] = -(a * f - c * d) / det
    out[2, 2] = (a * e - b * d) / det
    return det


@njit(cache=True)
def _update_block(P, b, sign, z, r, K, Sinv, dx, S, HP, gate):
    """Kalman update for ``H = sign * [I at block b]``, ``R = r I``; ``dx = K z``.

    Returns False (and leaves P unchanged) if the innovation covariance is not positive or the
    normalised innovation squared ``z^T S^-1 z`` exceeds ``gate``.
    """
    n = N_STATES
    for i in range(3):
        for j in range(3):
            S[i, j] = P[b + i, b + j]
        S[i, i] += r
    det = _inv3(S, Sinv)
    if not det > 0.0:
        return False
    nis = 0.0
    for i in range(3):
        for j in range(3):
            nis += z[i] * Sinv[i, j] * z[j]
    if nis > gate:
        return False
    for i in range(n):
        for m in range(3):
            K[i, m] = sign * (P[i, b] * Sinv[0, m] + P[i, b + 1] * Sinv[1, m] + P[i, b + 2] * Sinv[2, m])
    for i in range(n):
        dx[i] = K[i, 0] * z[0] + K[i, 1] * z[1] + K[i, 2] * z[2]
    # P <- P - K (H P);  H P = sign * P[b:b+3, :] (copied first: P is overwritten in place)
    for m in range(3):
        for j in range(n):
            HP[m, j] = sign * P[b + m, j]
    for i in range(n):
        k0, k1, k2 = K[i, 0], K[i, 1], K[i, 2]
        for j in range(i, n):
            P[i, j] -= k0 * HP[0, j] + k1 * HP[1, j] + k2 * HP[2, j]
    for i in range(n):
        for j in range(i):
            P[i, j] = P[j, i]
    return True


@njit(cache=True)
def _feedback(pos, vel, C, bg, ba, dx, work):
    """Apply an error estimate to the nominal: ``true = est - error``."""
    M, N = radii(pos[0])
    pos[0] -= dx[1] / (M + pos[2])
    pos[1] -= dx[0] / ((N + pos[2]) * np.cos(pos[0]))
    pos[2] -= dx[2]
    for i in range(3):
        vel[i] -= dx[3 + i]
        bg[i] -= dx[9 + i]
        ba[i] -= dx[12 + i]
    phi = work[3, 0]
    phi[0], phi[1], phi[2] = -dx[6], -dx[7], -dx[8]
    E = work[0]
    rotvec_to_dcm_nb(phi, E)
    Cn = work[1]
    for i in range(3):
        for j in range(3):
            Cn[i, j] = E[i, 0] * C[0, j] + E[i, 1] * C[1, j] + E[i, 2] * C[2, j]
    for i in range(3):
        for j in range(3):
            C[i, j] = Cn[i, j]


@njit(cache=True)
def _nav_row(pos, vel, C, out):
    out[0], out[1], out[2] = pos[0], pos[1], pos[2]
    out[3], out[4], out[5] = vel[0], vel[1], vel[2]
    out[6] = np.arctan2(-C[2, 0], C[2, 2])
    out[7] = np.arctan2(C[2, 1], np.sqrt(C[0, 1] ** 2 + C[1, 1] ** 2))
    a = np.arctan2(C[0, 1], C[1, 1])
    out[8] = a + 2.0 * np.pi if a < 0.0 else a


@njit(cache=True)
def zupt_filter_kernel(t, dth, dv, rate, still, zaru, pos0, vel0, C0, bg0, ba0, P0, q, qdyn,
                       r_zupt, r_zaru, gate, gate_zaru, update_every, gravity_model, smooth,
                       nav_out, bias_out, std_out, nav_s_out, upd_nu):
    """Forward ZUPT/ZARU filter over all samples and optional MBF smoother.

    Parameters (arrays are C-contiguous float64 unless noted)
    ----------
    t (N,), dth (N,3), dv (N,3) : increments over (t[k-1], t[k]]
    rate (N,3) : angular-rate samples for ZARU [rad/s]
    still (N,) bool : ZUPT allowed at sample k;  zaru (N,) bool : ZARU allowed at sample k
    pos0 (3,), vel0 (3,), C0 (3,3), bg0 (3,), ba0 (3,), P0 (15,15) : initial state
    q (4,) : PSDs [vel (m/s)^2/s, att rad^2/s, gyro-bias (rad/s)^2/s, accel-bias (m/s^2)^2/s]
    qdyn (2,) : dynamic noise factors: the velocity and attitude PSDs of an interval grow by
        ``(qdyn[0] |f - g|)^2 dt`` and ``(qdyn[1] |w|)^2 dt``
    r_zupt (N,) : ZUPT measurement variance per sample;  r_zaru : ZARU variance
    gate, gate_zaru : chi-square (3 dof) innovation gates (``inf`` disables)
    update_every : apply updates on every n-th sample of a still run (the first included)
    nav_out (N,9), bias_out (N,6), std_out (N,9) : forward (filtered) outputs
    nav_s_out (N,9) : smoothed navigation (written when ``smooth``)
    upd_nu (N,6) : ZUPT and ZARU innovations (NaN where none)

    Returns the number of updates applied.
    """
    n = t.shape[0]
    pos = pos0.copy()
    vel = vel0.copy()
    C = C0.copy()
    bg = bg0.copy()
    ba = ba0.copy()
    P = P0.copy()
    A = np.empty((N_STATES, N_STATES))
    work = np.empty((4, 3, 3))
    # separate scratch for the strapdown kernel (its size is private to strapdown_step; 16 is
    # generous)
    sd_work = np.empty(STEP_WORK_SHAPE)
    dthc = np.empty(3)
    dvc = np.empty(3)
    f = np.empty(3)
    z = np.empty(3)
    dx = np.empty(N_STATES)
    S = np.empty((3, 3))
    HP = np.empty((3, N_STATES))
    Kt = np.empty((N_STATES, 3))
    St = np.empty((3, 3))
    wie = np.empty(3)
    # smoother storage
    m_alloc = 1
    if smooth:
        m_alloc = n
    Prow = np.empty((m_alloc, 9, N_STATES))
    fl = np.empty((m_alloc, 3))
    Cs = np.empty((m_alloc, 3, 3))
    n_upd_alloc = 1
    if smooth:
        n_upd_alloc = 2 * n
    uk = np.empty(n_upd_alloc, np.int64)
    ub = np.empty(n_upd_alloc, np.int64)
    us = np.empty(n_upd_alloc)
    uK = np.empty((n_upd_alloc, N_STATES, 3))
    uSi = np.empty((n_upd_alloc, 3, 3))
    unu = np.empty((n_upd_alloc, 3))
    nupd = 0
    run = 0
    _nav_row(pos, vel, C, nav_out[0])
    for i in range(3):
        bias_out[0, i] = bg[i]
        bias_out[0, 3 + i] = ba[i]
    for i in range(9):
        std_out[0, i] = np.sqrt(P[i, i])
    for i in range(6):
        upd_nu[0, i] = np.nan
    if smooth:
        for i in range(9):
            for j in range(N_STATES):
                Prow[0, i, j] = P[i, j]
        for i in range(3):
            fl[0, i] = 0.0
            for j in range(3):
                Cs[0, i, j] = C[i, j]
    for k in range(1, n):
        dt = t[k] - t[k - 1]
        for i in range(3):
            dthc[i] = dth[k, i] - bg[i] * dt
            dvc[i] = dv[k, i] - ba[i] * dt
        # the error-propagation matrix uses the attitude at the start of the interval
        Cprev = work[2]
        for i in range(3):
            for j in range(3):
                Cprev[i, j] = C[i, j]
        for i in range(3):
            f[i] = (Cprev[i, 0] * dvc[0] + Cprev[i, 1] * dvc[1] + Cprev[i, 2] * dvc[2]) / dt
        if smooth:
            for i in range(3):
                fl[k, i] = f[i]
                for j in range(3):
                    Cs[k, i, j] = Cprev[i, j]
        qv, qa = q[0], q[1]
        if qdyn[0] > 0.0 or qdyn[1] > 0.0:
            # unmodelled scale-factor / dynamics errors: white noise proportional to the
            # dynamic specific force and the angular rate of this interval
            fd2 = f[0] * f[0] + f[1] * f[1] + (f[2] - 9.80665) ** 2
            w2 = (dthc[0] * dthc[0] + dthc[1] * dthc[1] + dthc[2] * dthc[2]) / (dt * dt)
            qv += qdyn[0] * qdyn[0] * fd2 * dt
            qa += qdyn[1] * qdyn[1] * w2 * dt
        _propagate_cov(P, A, f, Cprev, dt, qv, qa, q[2], q[3])
        strapdown_step(pos, vel, C, dthc, dvc, dt, gravity_model, 0, False, sd_work)
        for i in range(6):
            upd_nu[k, i] = np.nan
        if still[k]:
            if run % update_every == 0:
                # ZUPT
                z[0], z[1], z[2] = vel[0], vel[1], vel[2]
                if _update_block(P, IV, 1.0, z, r_zupt[k], Kt, St, dx, S, HP, gate):
                    _feedback(pos, vel, C, bg, ba, dx, work)
                    for i in range(3):
                        upd_nu[k, i] = z[i]
                    if smooth:
                        uk[nupd] = k
                        ub[nupd] = IV
                        us[nupd] = 1.0
                        uK[nupd] = Kt
                        uSi[nupd] = St
                        unu[nupd, 0], unu[nupd, 1], unu[nupd, 2] = z[0], z[1], z[2]
                    nupd += 1
                if zaru[k]:
                    cl, sl = np.cos(pos[0]), np.sin(pos[0])
                    wie[0], wie[1], wie[2] = 0.0, OMEGA_E * cl, OMEGA_E * sl
                    for i in range(3):
                        z[i] = rate[k, i] - bg[i] - (C[0, i] * wie[0] + C[1, i] * wie[1]
                                                     + C[2, i] * wie[2])
                    if _update_block(P, IG, -1.0, z, r_zaru, Kt, St, dx, S, HP, gate_zaru):
                        _feedback(pos, vel, C, bg, ba, dx, work)
                        for i in range(3):
                            upd_nu[k, 3 + i] = z[i]
                        if smooth:
                            uk[nupd] = k
                            ub[nupd] = IG
                            us[nupd] = -1.0
                            uK[nupd] = Kt
                            uSi[nupd] = St
                            unu[nupd, 0], unu[nupd, 1], unu[nupd, 2] = z[0], z[1], z[2]
                        nupd += 1
            run += 1
        else:
            run = 0
        _nav_row(pos, vel, C, nav_out[k])
        for i in range(3):
            bias_out[k, i] = bg[i]
            bias_out[k, 3 + i] = ba[i]
        for i in range(9):
            std_out[k, i] = np.sqrt(P[i, i])
        if smooth:
            for i in range(9):
                for j in range(N_STATES):
                    Prow[k, i, j] = P[i, j]
    if not smooth:
        return nupd
    # --- backward pass (modified Bryson-Frazier) ---
    lam = np.zeros(N_STATES)
    xs = np.empty(9)
    ps = np.empty(3)
    vs = np.empty(3)
    Cn = np.empty((3, 3))
    u = nupd - 1
    for k in range(n - 1, -1, -1):
        for i in range(9):
            s = 0.0
            for j in range(N_STATES):
                s += Prow[k, i, j] * lam[j]
            xs[i] = s
        row = nav_out[k]
        M, N = radii(row[0])
        ps[0] = row[0] - xs[1] / (M + row[2])
        ps[1] = row[1] - xs[0] / ((N + row[2]) * np.cos(row[0]))
        ps[2] = row[2] - xs[2]
        for i in range(3):
            vs[i] = row[3 + i] - xs[3 + i]
        # attitude: C_s = exp(-[phi x]) C_f
        Cf = work[2]
        euler_to_dcm_into(row[6], row[7], row[8], Cf)
        E = work[0]
        ph = work[3, 0]
        ph[0], ph[1], ph[2] = -xs[6], -xs[7], -xs[8]
        rotvec_to_dcm_nb(ph, E)
        for i in range(3):
            for j in range(3):
                Cn[i, j] = E[i, 0] * Cf[0, j] + E[i, 1] * Cf[1, j] + E[i, 2] * Cf[2, j]
        _nav_row(ps, vs, Cn, nav_s_out[k])
        # updates at k, in reverse order: lam += H^T (S^-1 nu - K^T lam)
        while u >= 0 and uk[u] == k:
            b = ub[u]
            sg = us[u]
            for m in range(3):
                ktl = 0.0
                for i in range(N_STATES):
                    ktl += uK[u, i, m] * lam[i]
                sn = uSi[u, m, 0] * unu[u, 0] + uSi[u, m, 1] * unu[u, 1] + uSi[u, m, 2] * unu[u, 2]
                z[m] = sg * (sn - ktl)
            for m in range(3):
                lam[b + m] += z[m]
            u -= 1
        if k > 0:
            _adjoint_back(lam, fl[k], Cs[k], t[k] - t[k - 1])
    return nupd


euler_to_dcm_into = euler_to_dcm_nb  # one compiled implementation (insgnss.attitude)


# --- configuration ---------------------------------------------------------------------------
#: pyshoe's SHOE noise levels (Wagstaff et al. 2019): sigma_a [m/s^2], sigma_w [rad/s]
PYSHOE_SIGMA_A = 0.00098
PYSHOE_SIGMA_W = 8.7266e-5


def foot_detector() -> DetectorConfig:
    """The foot preset's stance detector: gait-adaptive SHOE (see :mod:`insgnss.detect`)."""
    return DetectorConfig(method="adaptive", window=0.04, threshold=1.0e6,
                          sigma_a=PYSHOE_SIGMA_A, sigma_w=PYSHOE_SIGMA_W, adapt_window=3.0,
                          adapt_factor=10.0, adapt_peak_ratio=30.0, adapt_gait_peak=5.0e8,
                          quiet_duration=0.5)


@dataclass
class FootConfig:
    """Foot-mounted INS settings (SI units).

    Attributes
    ----------
    detector : DetectorConfig
        Stance detector (see :mod:`insgnss.detect`).
    zaru : bool
        Apply ZARU together with ZUPT on still samples.
    zaru_max_rate : float
        ZARU only on still samples whose angular rate is below this [rad/s] (the quiet core of
        a stance; the foot rolls at its edges).
    sigma_zupt, sigma_zaru : float
        Measurement standard deviations [m/s], [rad/s].
    zupt_noise_exponent, zupt_noise_ref : float
        Soft ZUPT: the ZUPT standard deviation of sample k is
        ``sigma_zupt * max(1, T_k / zupt_noise_ref) ** zupt_noise_exponent`` with ``T_k`` the
        detector statistic, so samples at the edge of a stance (where the foot still rolls)
        weigh less than its quiet core (0: constant ``sigma_zupt``).
    update_every : int
        Apply the updates on every n-th still sample (1 = every sample).
    gate_zupt, gate_zaru : float
        Chi-square gates on the normalised innovation squared (3 degrees of freedom); an update
        above it is skipped (``inf``: no gating). 16.27 is the 99.9 % point.
    accel_psd, gyro_psd : float
        Velocity / angle random walk of the process model [m/s/sqrt(s)], [rad/sqrt(s)]
        (larger than the datasheet values: they also cover the unmodelled dynamics of a foot).
    accel_dyn_noise, gyro_dyn_noise : float
        Dynamics-dependent process noise [sqrt(s)]: the velocity and attitude noise densities
        of an interval grow by ``accel_dyn_noise * |f - g|`` and ``gyro_dyn_noise * |w|``
        (unmodelled scale-factor, g-sensitivity and vibration errors, which dominate on a foot).
    gyro_bias_rw, accel_bias_rw : float
        Bias random walks [rad/s/sqrt(s)], [m/s^2/sqrt(s)].
    init_att_std, init_heading_std, init_vel_std, init_pos_std : float
        Initial standard deviations [rad], [rad], [m/s], [m].
    init_gyro_bias_std, init_accel_bias_std : float
        Initial bias standard deviations [rad/s], [m/s^2].
    level_window : float
        Length [s] of the start window used for levelling (the first still run is used if
        the detector finds one starting within it, else the first ``level_window`` seconds).
    heading : float
        Initial heading [rad] (unobservable; 0 unless known).
    smooth : bool
        Run the backward (smoother) pass and report the smoothed trajectory.
    gravity_model : str
        Normal-gravity model of the nominal mechanization.
    """

    detector: DetectorConfig = field(default_factory=foot_detector)
    zaru: bool = True
    zaru_max_rate: float = 0.05
    sigma_zupt: float = 0.01
    sigma_zaru: float = 0.01
    update_every: int = 1
    zupt_noise_exponent: float = 0.25
    zupt_noise_ref: float = 1.0e5
    gate_zupt: float = np.inf
    gate_zaru: float = np.inf
    accel_psd: float = 0.01
    gyro_psd: float = 3e-3
    accel_dyn_noise: float = 0.01
    gyro_dyn_noise: float = 0.0
    gyro_bias_rw: float = 1e-5
    accel_bias_rw: float = 1e-4
    init_att_std: float = np.radians(1.0)
    init_heading_std: float = np.radians(0.1)
    init_vel_std: float = 0.01
    init_pos_std: float = 1e-3
    init_gyro_bias_std: float = np.radians(0.1)
    init_accel_bias_std: float = 0.05
    level_window: float = 0.5
    heading: float = 0.0
    smooth: bool = True
    gravity_model: str = "somigliana"

    def __post_init__(self):
        if isinstance(self.detector, dict):
            self.detector = DetectorConfig.from_dict(self.detector)
        if int(self.update_every) < 1:
            raise ConfigError("update_every must be >= 1", column="update_every",
                              found=self.update_every)
        self.update_every = int(self.update_every)

    @classmethod
    def from_dict(cls, d: dict) -> FootConfig:
        """Build from a mapping (e.g. the ``[foot]`` table of a job file)."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ConfigError("unknown foot-mounted settings", column=unknown[0],
                              expected=sorted(names), found=unknown)
        return cls(**d)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["detector"] = self.detector.to_dict()
        return d


@dataclass
class FootResult:
    """Output of :func:`run_foot_ins`.

    ``trajectory`` is the reported solution (smoothed when ``config.smooth``), ``forward`` the
    filtered one; both have ``NAV_COLS`` plus ``east north up`` [m] relative to the start.
    ``std`` holds the forward standard deviations, ``biases`` the bias estimates, ``stillness``
    the detector output and ``innovations`` the ZUPT (``zupt_*``) and ZARU (``zaru_*``)
    innovations (NaN where no update).
    """

    trajectory: pd.DataFrame
    forward: pd.DataFrame
    std: pd.DataFrame
    biases: pd.DataFrame
    stillness: Stillness
    innovations: pd.DataFrame
    n_updates: int
    initial: NavState


# --- front end -------------------------------------------------------------------------------
def level_window_mask(t: np.ndarray, still: np.ndarray, seconds: float) -> np.ndarray:
    """Samples used for levelling: the first still run if it starts within ``seconds`` of the
    start (capped at 4 * ``seconds``), else the first ``seconds``."""
    t0 = t[0]
    idx = np.flatnonzero(still)
    if idx.size and t[idx[0]] - t0 <= seconds:
        a = idx[0]
        ends = np.flatnonzero(~still[a:])
        b = a + (ends[0] if ends.size else still.size - a)
        m = np.zeros(t.size, bool)
        m[a:b] = True
        m &= t - t[a] <= 4.0 * seconds
        if m.sum() >= 3:
            return m
    return t - t0 <= seconds


def initial_state(t, gyro, acc, still, config: FootConfig, lat=0.0, lon=0.0, height=0.0):
    """Levelled initial :class:`NavState` and gyro bias from the start window."""
    m = level_window_mask(t, still, config.level_window)
    if m.sum() < 2:
        raise AlignmentError("fewer than 2 samples in the levelling window",
                             expected=f">= 2 samples within {config.level_window} s")
    fm = acc[m].mean(axis=0)
    roll, pitch = level(fm)
    C = euler_to_dcm(roll, pitch, config.heading)
    bg0 = np.zeros(3)
    if still[m].all():  # mean rate minus the Earth rate seen by the levelled body
        bg0 = gyro[m].mean(axis=0) - C.T @ earth.earth_rate_l(lat)
    return NavState(lat, lon, height, np.zeros(3), C, float(t[0])), bg0


def _enu(nav: np.ndarray, lat0: float, lon0: float, h0: float) -> np.ndarray:
    e, n, u = earth.geodetic_to_enu(nav[:, 0], nav[:, 1], nav[:, 2], lat0, lon0, h0)
    return np.column_stack([e, n, u])


def _arr(x, dtype=float) -> np.ndarray:
    """C-contiguous, writeable array (pandas may hand out read-only views; numba would compile
    a separate read-only specialisation of the kernels for them)."""
    return np.require(x, dtype=dtype, requirements=["C", "W"])


def foot_filter_arrays(t, dth, dv, gyro, still, stat, initial: NavState, bg0,
                       cfg: FootConfig) -> dict:
    """Array core of :func:`run_foot_ins` (no pandas): increments ``dth, dv`` (N,3), rates
    ``gyro`` (N,3) for ZARU, ``still`` flags, detector statistic ``stat`` (NaN: no soft ZUPT),
    initial state and gyro bias. Returns a dict of arrays: ``nav``, ``nav_smoothed`` (N,9
    :data:`NAV_COLS`), ``bias`` (N,6), ``std`` (N,9), ``innovations`` (N,6), ``n_updates``."""
    n = t.size
    P0 = np.diag(np.concatenate([
        np.full(3, cfg.init_pos_std**2), np.full(3, cfg.init_vel_std**2),
        [cfg.init_att_std**2, cfg.init_att_std**2, cfg.init_heading_std**2],
        np.full(3, cfg.init_gyro_bias_std**2), np.full(3, cfg.init_accel_bias_std**2)]))
    q = np.array([cfg.accel_psd**2, cfg.gyro_psd**2, cfg.gyro_bias_rw**2, cfg.accel_bias_rw**2])
    qdyn = np.array([cfg.accel_dyn_noise, cfg.gyro_dyn_noise])
    still = _arr(still, bool)
    zaru = still.copy() if cfg.zaru else np.zeros(n, bool)
    if cfg.zaru and cfg.zaru_max_rate < np.inf:
        zaru &= np.linalg.norm(gyro - bg0, axis=1) < cfg.zaru_max_rate
    r_zupt = np.full(n, cfg.sigma_zupt**2)
    stat = _arr(stat)
    if cfg.zupt_noise_exponent > 0 and np.all(np.isfinite(stat)):
        r_zupt *= np.maximum(1.0, stat / cfg.zupt_noise_ref) ** (2.0 * cfg.zupt_noise_exponent)
    nav = np.empty((n, 9))
    bias = np.empty((n, 6))
    std = np.empty((n, 9))
    nav_s = np.empty((n, 9)) if cfg.smooth else np.empty((1, 9))
    nu = np.empty((n, 6))
    nupd = zupt_filter_kernel(
        _arr(t), _arr(dth), _arr(dv), _arr(gyro), still, zaru,
        np.array([initial.lat, initial.lon, initial.height], float),
        np.array(initial.vel, float), np.array(initial.C, float),
        np.asarray(bg0, float).copy(), np.zeros(3), P0, q, qdyn, r_zupt, cfg.sigma_zaru**2,
        float(cfg.gate_zupt), float(cfg.gate_zaru), cfg.update_every,
        earth.gravity_model_id(cfg.gravity_model), bool(cfg.smooth), nav, bias, std, nav_s, nu)
    return {"nav": nav, "nav_smoothed": nav_s if cfg.smooth else nav, "bias": bias, "std": std,
            "innovations": nu, "n_updates": int(nupd)}


def run_foot_ins(
    imu: pd.DataFrame,
    config: FootConfig | None = None,
    *,
    initial: NavState | None = None,
    still: Stillness | pd.Series | np.ndarray | None = None,
    lat: float = 0.0,
    lon: float = 0.0,
    height: float = 0.0,
) -> FootResult:
    """Foot-mounted ZUPT(+ZARU) INS on an IMU table (body RFU, rates or increments).

    Parameters
    ----------
    imu : DataFrame
        IMU table indexed by time [s], body frame right-forward-up.
    config : FootConfig, optional
        Settings (default: the foot preset).
    initial : NavState, optional
        Initial state; by default levelled from the first still window with heading
        ``config.heading`` at (``lat``, ``lon``, ``height``) [rad, rad, m].
    still : Stillness, bool Series or array, optional
        Declared still samples (a :class:`Stillness` also brings its statistic for the soft
        ZUPT); by default ``config.detector`` decides.

    Returns
    -------
    FootResult
    """
    cfg = config or FootConfig()
    t, gyro, acc = imu_rates(imu)
    if still is None:
        st_flags, stat, thr = detect_arrays(t, gyro, acc, cfg.detector)
    elif isinstance(still, Stillness):
        st_flags = still.still.to_numpy(bool)
        stat = still.statistic.to_numpy(float)
        thr = still.threshold.to_numpy(float)
        if st_flags.size != t.size:
            raise ConfigError("stillness length differs from the IMU table", column="still",
                              expected=t.size, found=st_flags.size)
    else:
        st_flags = np.asarray(still, bool)
        if st_flags.size != t.size:
            raise ConfigError("still mask length differs from the IMU table", column="still",
                              expected=t.size, found=st_flags.size)
        stat = np.full(t.size, np.nan)
        thr = np.full(t.size, np.nan)
    bg0 = np.zeros(3)
    if initial is None:
        initial, bg0 = initial_state(t, gyro, acc, st_flags, cfg, lat, lon, height)
    _, dth, dv = increments(imu)
    out = foot_filter_arrays(t, dth, dv, gyro, st_flags, stat, initial, bg0, cfg)
    nav, nav_s, bias, std, nu, nupd = (out[k] for k in ("nav", "nav_smoothed", "bias", "std",
                                                        "innovations", "n_updates"))
    idx = pd.Index(t, name="time")

    def table(arr):
        df = pd.DataFrame(arr, index=idx, columns=NAV_COLS)
        enu = _enu(arr, initial.lat, initial.lon, initial.height)
        df["east"], df["north"], df["up"] = enu[:, 0], enu[:, 1], enu[:, 2]
        return df

    fwd = table(nav)
    traj = table(nav_s) if cfg.smooth else fwd
    stillness = Stillness(pd.Series(st_flags, idx, name="still"),
                          pd.Series(stat, idx, name="statistic"),
                          pd.Series(thr, idx, name="threshold"),
                          cfg.detector.method if still is None else
                          getattr(still, "method", "declared"))
    innov = pd.DataFrame(nu, index=idx, columns=["zupt_e", "zupt_n", "zupt_u", "zaru_x", "zaru_y",
                                                 "zaru_z"])
    return FootResult(traj, fwd, pd.DataFrame(std, index=idx, columns=STD_COLS),
                      pd.DataFrame(bias, index=idx, columns=BIAS_COLS), stillness, innov,
                      int(nupd), initial)
