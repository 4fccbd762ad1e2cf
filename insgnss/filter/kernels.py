"""Compiled (numba) kernels of the strapdown error-state model: nominal propagation with
accumulation of the error dynamics, discretisation (second order or van Loan), feedback and the
assembly of the IMU-rate output tables (the smoother's backward pass is in :mod:`.smoother`).

Nothing here loops in Python per IMU sample; the engine calls :func:`propagate_nominal` and
:func:`discretize` once per filter epoch.

Splitting at epochs between samples: an IMU increment row covers ``(t[j-1], t[j]]``; when an
epoch falls inside it, the increment is split linearly (constant rate over the sample
interval), the first share is applied up to the epoch and the rest on the next call. ``frac``
is the share of row ``j`` already consumed.
"""

from __future__ import annotations

import numpy as np

from ..aot import entry
from ..attitude import euler_to_dcm_nb, rotvec_to_dcm_nb
from ..earth import gravity_somigliana, normal_gravity_sc, radii
from ..jit import njit
from ..mechanization.core import _matmul3
from ..mechanization.strapdown import STEP_WORK_SHAPE, strapdown_step
from ..mechanization.wander import wander_step, wander_to_nav
from .ecef_dynamics import accumulate_ecef_error_dynamics
from .linalg import _copy, _mm, _mmspt, _sparse, _spmm
from .models import accumulate_error_dynamics, accumulate_short_term_dynamics

DISC_SECOND_ORDER = 0
DISC_VANLOAN = 1


@entry
@njit(cache=True)
def store_nav(nav_out, j, pos, vel, C):
    """Write position, velocity and the Euler angles of ``C`` into ``nav_out[j, 0:9]``."""
    nav_out[j, 0] = pos[0]
    nav_out[j, 1] = pos[1]
    nav_out[j, 2] = pos[2]
    nav_out[j, 3] = vel[0]
    nav_out[j, 4] = vel[1]
    nav_out[j, 5] = vel[2]
    nav_out[j, 6] = np.arctan2(-C[2, 0], C[2, 2])
    nav_out[j, 7] = np.arctan2(C[2, 1], np.sqrt(C[0, 1] ** 2 + C[1, 1] ** 2))
    a = np.arctan2(C[0, 1], C[1, 1])
    nav_out[j, 8] = a + 2.0 * np.pi if a < 0.0 else a


@njit(cache=True)
def store_nav_wander(nav_out, j, Cne, h, vel, C, buf):
    """:func:`store_nav` for a wander nominal (``C_w^e``, height, ``v^w``, ``C_b^w``): the same
    ENU columns (:func:`insgnss.mechanization.wander.wander_to_nav`; ``buf``: (10,) scratch)."""
    wander_to_nav(Cne, h, vel, C, buf)
    for i in range(9):
        nav_out[j, i] = buf[i]


_euler_dcm = euler_to_dcm_nb  # one compiled implementation (insgnss.attitude)


# inline="always": called at every IMU sample of the high-rate path (highrate._model_step)
@entry
@njit(cache=True, inline="always")
def interval_step(
    pos,
    vel,
    C,
    pnom,
    dth_j,
    dv_j,
    a,
    dt_s,
    i_sg,
    i_sa,
    gravity_model,
    attitude_update,
    F,
    Qg,
    Qa,
    q_g,
    q_a,
    dyn,
    dthc,
    dvc,
    work,
    dynamics=0,
    Cne=None,
    hv=None,
    Cbe=None,
):
    """One IMU interval (share ``a`` of row ``dth_j, dv_j``, duration ``dt_s``) of the strapdown
    process model: compensate the increments with the nominal biases (and scale factors) in
    ``pnom``, add ``F dt`` (``dynamics`` 0: :func:`.models.accumulate_error_dynamics`, 1: the
    short-term model :func:`.models.accumulate_short_term_dynamics`) to ``F`` and the rotated
    white-noise integrals ``C diag(q_g) C^T dt``, ``C diag(q_a) C^T dt`` to ``Qg``, ``Qa``, then
    advance the nominal ``pos, vel, C`` (:func:`strapdown_step`). ``dthc, dvc`` receive the
    compensated increments.

    ``dyn = (k_a, k_g)`` adds dynamics-dependent white noise (unmodelled scale-factor,
    g-sensitivity and vibration errors): a white error of the fraction ``k_a`` of the interval's
    dynamic velocity increment and ``k_g`` of its angle increment, i.e. the variances
    ``(k_a |C dv - g dt|)^2`` and ``(k_g |dtheta|)^2`` (isotropic) on the velocity and attitude.

    Wander nominal (:mod:`.wander_model`): given ``Cne`` (``C_w^e``), ``hv`` (height, (1,)) and
    the scratch ``Cbe`` (3x3), ``vel`` and ``C`` are ``v^w`` and ``C_b^w``, ``F`` is the ECEF
    error dynamics (:func:`.ecef_dynamics.accumulate_ecef_error_dynamics`), the noise is
    rotated by ``C_b^e`` and the nominal advances by
    :func:`insgnss.mechanization.wander.wander_step` (``pos`` unused).
    """
    for i in range(3):
        g = a * dth_j[i] - pnom[i] * dt_s
        f = a * dv_j[i] - pnom[3 + i] * dt_s
        if i_sg >= 0:
            g /= 1.0 + pnom[i_sg - 9 + i]
        if i_sa >= 0:
            f /= 1.0 + pnom[i_sa - 9 + i]
        dthc[i] = g
        dvc[i] = f
    if Cne is None:
        Ce = C
        if dynamics == 0:
            accumulate_error_dynamics(F, dt_s, pos[0], pos[2], vel, C, dthc, dvc, i_sg, i_sa)
        else:
            accumulate_short_term_dynamics(F, dt_s, C, dthc, dvc, i_sg, i_sa)
    else:
        _matmul3(Cne, C, Cbe)
        Ce = Cbe
        accumulate_ecef_error_dynamics(F, dt_s, Cne, hv[0], Cbe, dthc, dvc, i_sg, i_sa)
    va_dyn = 0.0
    vg_dyn = 0.0
    if dyn[0] > 0.0 or dyn[1] > 0.0:
        de = Ce[0, 0] * dvc[0] + Ce[0, 1] * dvc[1] + Ce[0, 2] * dvc[2]
        dn = Ce[1, 0] * dvc[0] + Ce[1, 1] * dvc[1] + Ce[1, 2] * dvc[2]
        du = Ce[2, 0] * dvc[0] + Ce[2, 1] * dvc[1] + Ce[2, 2] * dvc[2]
        if Cne is None:
            du -= gravity_somigliana(pos[0], pos[2]) * dt_s
        else:  # minus g^e dt = +g u dt, u = C_w^e[:, 2]
            gdt = normal_gravity_sc(Cne[2, 2], np.sqrt(Cne[2, 0] ** 2 + Cne[2, 1] ** 2), hv[0], 0) * dt_s
            de -= gdt * Cne[0, 2]
            dn -= gdt * Cne[1, 2]
            du -= gdt * Cne[2, 2]
        va_dyn = dyn[0] * dyn[0] * (de * de + dn * dn + du * du)
        vg_dyn = dyn[1] * dyn[1] * (dthc[0] ** 2 + dthc[1] ** 2 + dthc[2] ** 2)
    for r in range(3):
        for c in range(r, 3):
            qg = 0.0
            qa = 0.0
            for k in range(3):
                qg += Ce[r, k] * q_g[k] * Ce[c, k]
                qa += Ce[r, k] * q_a[k] * Ce[c, k]
            Qg[r, c] += qg * dt_s
            Qa[r, c] += qa * dt_s
            if c != r:
                Qg[c, r] += qg * dt_s
                Qa[c, r] += qa * dt_s
        Qg[r, r] += vg_dyn
        Qa[r, r] += va_dyn
    # a typed (not literal) False: the step's compiled version with a run-time flag, shared
    # with the free mechanization, instead of a second specialisation for the constant
    fix_height = np.bool_(False)
    if Cne is None:
        strapdown_step(pos, vel, C, dthc, dvc, dt_s, gravity_model, attitude_update, fix_height, work)
    else:
        wander_step(Cne, hv, vel, C, dthc, dvc, dt_s, gravity_model, attitude_update, fix_height, work)


@entry
@njit(cache=True)
def propagate_nominal(
    t,
    dth,
    dv,
    j,
    frac,
    t_end,
    pos,
    vel,
    C,
    pnom,
    i_sg,
    i_sa,
    gravity_model,
    attitude_update,
    sub_T,
    Fint,
    Qint,
    sub_dt,
    q_g,
    q_a,
    nav_out,
    out_seg,
    seg_id,
    rates,
    dyn=None,
    dynamics=0,
    Cne=None,
    hv=None,
):
    """Mechanize from the current point (row ``j``, share ``frac`` consumed) to ``t_end``.

    The nominal state ``pos, vel, C`` is advanced in place using the increments compensated
    with the current bias (and scale-factor) estimates held in ``pnom`` (the parameter part of
    the nominal state, error-state indices 9 onwards). Each completed row ``j`` is stored in
    ``nav_out[j, 0:9]`` (NAV_COLS: lat lon height vel_e vel_n vel_u roll pitch heading) with
    ``out_seg[j] = seg_id``.

    Over covariance sub-intervals of length ``sub_T`` (restarted at the segment start, the
    last one possibly shorter), ``Fint[s]`` receives ``int F dt``, ``Qint[s, 0 / 1]`` the
    integrals of ``C diag(q_g) C^T`` and ``C diag(q_a) C^T`` and ``sub_dt[s]`` the duration
    (:func:`interval_step`; ``dyn``: its dynamics-dependent noise, default none; ``dynamics``:
    its error model, default the full one).

    ``rates`` (4, 3) receives the compensated angular rate and specific force of the last
    interval (rows 0, 2) and their means over the segment (rows 1, 3).

    Wander nominal: ``Cne`` (``C_w^e``) and ``hv`` (height, (1,)) given, ``vel`` and ``C`` are
    ``v^w`` and ``C_b^w`` (:func:`interval_step`); the stored rows have the same ENU columns.

    Returns ``(j, frac, n_sub)``.
    """
    n_t = t.shape[0]
    n = Fint.shape[1]
    work = np.empty(STEP_WORK_SHAPE)  # strapdown_step scratch
    dthc = np.empty(3)
    dvc = np.empty(3)
    dyn_k = np.zeros(2)
    if dyn is not None:
        dyn_k[0] = dyn[0]
        dyn_k[1] = dyn[1]
    sum_th = np.zeros(3)
    sum_dv = np.zeros(3)
    sum_dt = 0.0
    s = -1
    acc = 0.0
    Cbe = np.empty((3, 3))
    buf = np.empty(10)
    while j < n_t:
        dt_full = t[j] - t[j - 1]
        t_start = t[j - 1] + frac * dt_full
        if t_end <= t_start:
            break
        full = t[j] <= t_end
        if full:
            a = 1.0 - frac
        else:
            a = (t_end - t_start) / dt_full
        dt_s = a * dt_full
        if s < 0 or acc >= sub_T * (1.0 - 1e-9):
            s += 1
            for r in range(n):
                for c in range(n):
                    Fint[s, r, c] = 0.0
            for r in range(2):
                for c in range(3):
                    for k in range(3):
                        Qint[s, r, c, k] = 0.0
            sub_dt[s] = 0.0
            acc = 0.0
        interval_step(
            pos,
            vel,
            C,
            pnom,
            dth[j],
            dv[j],
            a,
            dt_s,
            i_sg,
            i_sa,
            gravity_model,
            attitude_update,
            Fint[s],
            Qint[s, 0],
            Qint[s, 1],
            q_g,
            q_a,
            dyn_k,
            dthc,
            dvc,
            work,
            dynamics,
            Cne,
            hv,
            Cbe,
        )
        sub_dt[s] += dt_s
        acc += dt_s
        for i in range(3):
            sum_th[i] += dthc[i]
            sum_dv[i] += dvc[i]
            if dt_s > 0.0:
                rates[0, i] = dthc[i] / dt_s
                rates[2, i] = dvc[i] / dt_s
        sum_dt += dt_s
        if full:
            if Cne is None:
                store_nav(nav_out, j, pos, vel, C)
            else:
                store_nav_wander(nav_out, j, Cne, hv[0], vel, C, buf)
            out_seg[j] = seg_id
            j += 1
            frac = 0.0
        else:
            frac += a
            break
    if sum_dt > 0.0:
        for i in range(3):
            rates[1, i] = sum_th[i] / sum_dt
            rates[3, i] = sum_dv[i] / sum_dt
    return j, frac, s + 1


@njit(cache=True)
def expm_nb(A):
    """Matrix exponential by scaling and squaring with a Taylor series (relative accuracy
    ~1e-15 for the block matrices of van Loan's method)."""
    n = A.shape[0]
    nrm = 0.0
    for i in range(n):
        r = 0.0
        for k in range(n):
            r += abs(A[i, k])
        nrm = max(nrm, r)
    sq = 0
    if nrm > 0.5:
        sq = int(np.ceil(np.log2(nrm / 0.5)))
    scale = 1.0 / 2.0**sq
    X = np.empty((n, n))
    E = np.empty((n, n))
    term = np.empty((n, n))
    for i in range(n):
        for k in range(n):
            X[i, k] = A[i, k] * scale
            E[i, k] = X[i, k] + (1.0 if i == k else 0.0)
            term[i, k] = X[i, k]
    tmp = np.empty((n, n))
    for k in range(2, 20):
        _mm(term, X, tmp)
        mx = 0.0
        for i in range(n):
            for j in range(n):
                term[i, j] = tmp[i, j] / k
                E[i, j] += term[i, j]
                mx = max(mx, abs(term[i, j]))
        if mx < 1e-18:
            break
    for _ in range(sq):
        _mm(E, E, tmp)
        _copy(tmp, E)
    return E


@entry
@njit(cache=True)
def discretize(Fint, Qint, sub_dt, n_sub, decay, qdiag, method, Phi_tot, Qd_tot, Fx=None, Qx=None):
    """Transition matrix and process noise of a segment from its covariance sub-intervals.

    For each sub-interval of duration T with ``FT = int F dt - diag(decay) T (+ Fx T)`` and
    ``QT = int G Q G^T dt (+ Qx T)`` (``Fx``, ``Qx``: the constant dynamics and noise PSD of
    coupled augmenting states, e.g. a receiver clock's bias-drift block; default none):

    - ``method = 0`` (second order): ``Phi = I + FT + FT^2 / 2``,
      ``Qd = QT + (FT QT + QT FT^T) / 2 + (FT^2 QT + 2 FT QT FT^T + QT FT^T^2) / 6``
      (the Taylor series of van Loan's integral to third order in T);
    - ``method = 1`` (van Loan): ``expm([[-F, Q], [0, F^T]] T)`` gives ``Phi`` and ``Qd``
      exactly for the interval-averaged F and Q.

    The sub-interval results are composed: ``Phi_tot <- Phi Phi_tot``,
    ``Qd_tot <- Phi Qd_tot Phi^T + Qd``, which is exactly what propagating P over every
    sub-interval in turn would give. Returns the total duration.
    """
    n = Phi_tot.shape[0]
    total = 0.0
    FT = np.empty((n, n))
    QT = np.zeros((n, n))
    Phi = np.empty((n, n))
    Qd = np.empty((n, n))
    A = np.empty((n, n))
    B = np.empty((n, n))
    Cq = np.empty((n, n))
    tmp = np.empty((n, n))
    ri = np.empty(n * n, np.int64)
    ci = np.empty(n * n, np.int64)
    vals = np.empty(n * n)
    first = True
    for s in range(n_sub):
        T = sub_dt[s]
        if T <= 0.0:
            continue
        total += T
        for r in range(n):
            for c in range(n):
                FT[r, c] = Fint[s, r, c]
                QT[r, c] = 0.0
            FT[r, r] -= decay[r] * T
            QT[r, r] = qdiag[r] * T
        if Fx is not None:
            for r in range(n):
                for c in range(n):
                    FT[r, c] += Fx[r, c] * T
        if Qx is not None:
            for r in range(n):
                for c in range(n):
                    QT[r, c] += Qx[r, c] * T
        for r in range(3):
            for c in range(3):
                QT[6 + r, 6 + c] += Qint[s, 0, r, c]
                QT[3 + r, 3 + c] += Qint[s, 1, r, c]
        if method == DISC_VANLOAN:
            Mb = np.zeros((2 * n, 2 * n))
            for r in range(n):
                for c in range(n):
                    Mb[r, c] = -FT[r, c]
                    Mb[r, n + c] = QT[r, c]
                    Mb[n + r, n + c] = FT[c, r]
            E = expm_nb(Mb)
            for r in range(n):
                for c in range(n):
                    Phi[r, c] = E[n + c, n + r]
                    A[r, c] = E[r, n + c]
            _mm(Phi, A, Qd)
        else:
            nf = _sparse(FT, ri, ci, vals)
            _spmm(ri, ci, vals, nf, FT, A)  # FT^2
            for r in range(n):
                for c in range(n):
                    Phi[r, c] = FT[r, c] + 0.5 * A[r, c]
                Phi[r, r] += 1.0
            _spmm(ri, ci, vals, nf, QT, A)  # A = FT QT
            _spmm(ri, ci, vals, nf, A, B)  # B = FT^2 QT
            _mmspt(A, ri, ci, vals, nf, Cq)  # Cq = FT QT FT^T
            for r in range(n):
                for c in range(n):
                    Qd[r, c] = (
                        QT[r, c] + 0.5 * (A[r, c] + A[c, r]) + (B[r, c] + B[c, r] + 2.0 * Cq[r, c]) / 6.0
                    )
        for r in range(n):
            for c in range(r + 1, n):
                v = 0.5 * (Qd[r, c] + Qd[c, r])
                Qd[r, c] = v
                Qd[c, r] = v
        if first:
            _copy(Phi, Phi_tot)
            _copy(Qd, Qd_tot)
            first = False
        else:
            npf = _sparse(Phi, ri, ci, vals)
            _spmm(ri, ci, vals, npf, Phi_tot, tmp)
            _copy(tmp, Phi_tot)
            _spmm(ri, ci, vals, npf, Qd_tot, tmp)
            _mmspt(tmp, ri, ci, vals, npf, A)
            for r in range(n):
                for c in range(n):
                    Qd_tot[r, c] = A[r, c] + Qd[r, c]
    if first:
        for r in range(n):
            for c in range(n):
                Phi_tot[r, c] = 1.0 if r == c else 0.0
                Qd_tot[r, c] = 0.0
    return total


@entry
@njit(cache=True)
def apply_feedback(pos, vel, C, pnom, x):
    """Closed-loop correction of the nominal state by the error estimate ``x`` (nominal minus
    true): position (ENU metres -> lat/lon/h), velocity, attitude ``C <- exp(-[phi x]) C``
    and the parameters ``pnom -= x[9:]``."""
    apply_feedback_into(pos, vel, C, pnom, x, np.empty((3, 3, 3)))


@njit(cache=True)
def apply_feedback_into(pos, vel, C, pnom, x, work):
    """:func:`apply_feedback` with the scratch ``work`` (3, 3, 3) (no allocation)."""
    M, N = radii(pos[0])
    h = pos[2]
    lat = pos[0]
    pos[0] -= x[1] / (M + h)
    pos[1] -= x[0] / ((N + h) * np.cos(lat))
    pos[2] -= x[2]
    for i in range(3):
        vel[i] -= x[3 + i]
    phi = work[2, 0]
    phi[0], phi[1], phi[2] = -x[6], -x[7], -x[8]
    R = work[0]
    rotvec_to_dcm_nb(phi, R)
    Cn = work[1]
    _mm(R, C, Cn)
    _copy(Cn, C)
    for i in range(pnom.shape[0]):
        pnom[i] -= x[9 + i]


@njit(cache=True, inline="always")
def _euler_std(C, P, o, out):
    """Std of roll, pitch, heading from the misalignment covariance ``P[o:o+3, o:o+3]`` at
    ``C`` (linearised: ``C_nom = (I + [phi x]) C``), written into ``out``.

    The rows of the Jacobian ``J = d(roll, pitch, heading) / d phi`` are held in scalars and
    its structural zeros (``J[0, 2] = J[1, 2] = 0``) skipped: the same sums in the same order
    as ``J P J^T`` over all entries, without the products with zero, and no slice of ``P``
    (inlined where it is called, once per IMU sample on the compiled high-rate path)."""
    # d roll = (C20 dC22 - C22 dC20) / (C20^2 + C22^2); dC = [phi x] C
    # dC20 = -phi_n C00 + phi_e C10 ; dC22 = -phi_n C02 + phi_e C12 ; dC21 = -phi_n C01 + phi_e C11
    d = C[2, 0] ** 2 + C[2, 2] ** 2
    if d < 1e-12:
        d = 1e-12
    j00 = (C[2, 0] * C[1, 2] - C[2, 2] * C[1, 0]) / d
    j01 = (-C[2, 0] * C[0, 2] + C[2, 2] * C[0, 0]) / d
    cp = np.sqrt(max(1.0 - C[2, 1] ** 2, 1e-12))
    j10 = C[1, 1] / cp
    j11 = -C[0, 1] / cp
    h = C[0, 1] ** 2 + C[1, 1] ** 2
    if h < 1e-12:
        h = 1e-12
    j20 = C[0, 1] * C[2, 1] / h
    j21 = C[1, 1] * C[2, 1] / h
    p00, p01, p02 = P[o, o], P[o, o + 1], P[o, o + 2]
    p10, p11, p12 = P[o + 1, o], P[o + 1, o + 1], P[o + 1, o + 2]
    p20, p21, p22 = P[o + 2, o], P[o + 2, o + 1], P[o + 2, o + 2]
    v0 = 0.0 + j00 * p00 * j00 + j00 * p01 * j01
    v0 = v0 + j01 * p10 * j00 + j01 * p11 * j01
    v1 = 0.0 + j10 * p00 * j10 + j10 * p01 * j11
    v1 = v1 + j11 * p10 * j10 + j11 * p11 * j11
    # J[2, 2] = -1
    v2 = (
        0.0
        + j20 * p00 * j20
        + j20 * p01 * j21
        + j20 * p02 * -1.0
        + j21 * p10 * j20
        + j21 * p11 * j21
        + j21 * p12 * -1.0
        + -1.0 * p20 * j20
        + -1.0 * p21 * j21
        + -1.0 * p22 * -1.0
    )
    out[0] = np.sqrt(max(v0, 0.0))
    out[1] = np.sqrt(max(v1, 0.0))
    out[2] = np.sqrt(max(v2, 0.0))


@njit(cache=True, inline="always")
def correct_position_velocity(nav, j, x, out):
    """Row ``j`` of ``out`` (lat, lon, height, vel_e, vel_n, vel_u) = the nominal row ``j`` of
    ``nav`` corrected by the error state ``x`` (ENU position error [m] in ``x[0:3]``, velocity
    error in ``x[3:6]``; errors are nominal minus true): ``lat - dn / (M + h)``,
    ``lon - de / ((N + h) cos lat)``, ``h - du``, ``v - dv``."""
    lat = nav[j, 0]
    h = nav[j, 2]
    M, N = radii(lat)
    out[j, 0] = lat - x[1] / (M + h)
    out[j, 1] = nav[j, 1] - x[0] / ((N + h) * np.cos(lat))
    out[j, 2] = h - x[2]
    for i in range(3):
        out[j, 3 + i] = nav[j, 3 + i] - x[3 + i]


@njit(cache=True, inline="always")
def _node_covariance(P, e, nd, attitude, pdiag, Pa):
    """The first ``nd`` variances of node ``e`` into ``pdiag`` and (``attitude``) its
    attitude block into ``Pa`` (:func:`assemble_output`)."""
    for a in range(nd):
        pdiag[a] = P[e, a, a]
    if attitude:
        for a in range(3):
            for b in range(3):
                Pa[a, b] = P[e, 6 + a, 6 + b]


@njit(cache=True, inline="always")
def _interpolated_covariance(P_start, P_end, e, w, nd, attitude, pdiag, Pa):
    """:func:`_node_covariance` of ``(1 - w) P_start[e-1] + w P_end[e]``."""
    for a in range(nd):
        pdiag[a] = (1.0 - w) * P_start[e - 1, a, a] + w * P_end[e, a, a]
    if attitude:
        for a in range(3):
            for b in range(3):
                Pa[a, b] = (1.0 - w) * P_start[e - 1, 6 + a, 6 + b] + w * P_end[e, 6 + a, 6 + b]


@entry
@njit(cache=True)
def assemble_output(
    t,
    nav_in,
    out_seg,
    out_post,
    ep_t,
    P_start,
    P_end,
    X_start,
    X_end,
    pnom_ep,
    n_rows,
    correct,
    out,
    X_hr,
    hr_node,
    stds,
    position_only,
):
    """IMU-rate output rows: nominal (optionally corrected) navigation state, stds, parameters.

    ``nav_in[j, 0:9]`` is the stored forward nominal (NAV_COLS). Sample ``j`` belongs to
    segment ``e = out_seg[j]`` (``t[e-1] < t_j <= t[e]`` in epoch times). If ``out_post[j]`` the
    sample sits on epoch ``e`` and holds the post-feedback nominal: it takes ``X_start[e]``,
    ``P_start[e]``. Otherwise the error and covariance are interpolated linearly in time between
    ``(X_start[e-1], P_start[e-1])`` at ``t[e-1]`` and ``(X_end[e], P_end[e])`` at ``t[e]``; the
    parameter nominal is ``pnom_ep[e-1]``.

    Forward run (``correct=False``, ``X`` unused, ``out`` may be ``nav_in`` itself: columns 0-8
    are then left as they are): ``P_start = P(e|e)``, ``P_end = P(e|e-1)``.
    Smoothed run: ``X_start = xs_plus``, ``X_end = xs_minus``, ``P_start = P_end = Ps``.

    Rows of the compiled high-rate path have ``out_seg[j] = -1 - i`` (high-rate sample ``i``,
    between nodes ``hr_node[i] - 1`` and ``hr_node[i]``): their forward row is complete already
    (skipped); smoothed, they take ``X_hr[i]``, the parameter nominal of their forward row and
    the covariance interpolated between those two nodes.

    ``out`` columns: lat lon height vel_e vel_n vel_u roll pitch heading, 9 stds (east north
    up, vel, roll pitch heading), then for each parameter state its value and its std.
    The corrected attitude is ``exp(-[phi x]) C``. ``stds=False`` (a smoothed run without
    smoothed covariances): the std columns are NaN and ``P_start``, ``P_end`` are not read.
    ``position_only``: only ``lat lon height`` and ``east_std north_std up_std`` are written
    (the same values; the other columns are left as they are): what the evaluation reads, a
    fraction of the cost of a row (no attitude, its std or parameters).
    """
    n = P_start.shape[1]
    npar = n - 9
    # the error and covariance entries a row needs: all, or position (velocity with it)
    nx = 6 if position_only else n
    nd = 3 if position_only else n
    x = np.zeros(n)
    pdiag = np.empty(n)
    Pa = np.empty((3, 3))
    C = np.empty((3, 3))
    Cc = np.empty((3, 3))
    R = np.empty((3, 3))
    phi = np.empty(3)
    es = np.empty(3)
    n_nodes = ep_t.shape[0]
    for j in range(n_rows):
        e = out_seg[j]
        hr = e < 0
        if hr:
            if not correct:
                continue
            i_hr = -1 - e
            for a in range(nx):
                x[a] = X_hr[i_hr, a]
            e = hr_node[i_hr]
            if not stds:
                pass
            elif e >= n_nodes:  # after the last node (a stopped run): its covariance
                e = n_nodes - 1
                _node_covariance(P_start, e, nd, not position_only, pdiag, Pa)
            else:
                w = (t[j] - ep_t[e - 1]) / (ep_t[e] - ep_t[e - 1])
                _interpolated_covariance(P_start, P_end, e, w, nd, not position_only, pdiag, Pa)
            ep = -1
        elif out_post[j]:
            if correct:
                for a in range(nx):
                    x[a] = X_start[e, a]
            if stds:
                _node_covariance(P_start, e, nd, not position_only, pdiag, Pa)
            ep = e
        else:
            w = (t[j] - ep_t[e - 1]) / (ep_t[e] - ep_t[e - 1])
            if correct:
                for a in range(nx):
                    x[a] = (1.0 - w) * X_start[e - 1, a] + w * X_end[e, a]
            if stds:
                _interpolated_covariance(P_start, P_end, e, w, nd, not position_only, pdiag, Pa)
            ep = e - 1
        if position_only:
            if correct:
                correct_position_velocity(nav_in, j, x, out)
            else:
                for i in range(3):
                    out[j, i] = nav_in[j, i]
            for i in range(3):
                out[j, 9 + i] = np.sqrt(max(pdiag[i], 0.0)) if stds else np.nan
            continue
        _euler_dcm(nav_in[j, 6], nav_in[j, 7], nav_in[j, 8], C)
        if correct:
            correct_position_velocity(nav_in, j, x, out)
            for i in range(3):
                phi[i] = -x[6 + i]
            rotvec_to_dcm_nb(phi, R)
            for r in range(3):
                for c in range(3):
                    Cc[r, c] = R[r, 0] * C[0, c] + R[r, 1] * C[1, c] + R[r, 2] * C[2, c]
            out[j, 6] = np.arctan2(-Cc[2, 0], Cc[2, 2])
            out[j, 7] = np.arctan2(Cc[2, 1], np.sqrt(Cc[0, 1] ** 2 + Cc[1, 1] ** 2))
            hd = np.arctan2(Cc[0, 1], Cc[1, 1])
            out[j, 8] = hd + 2.0 * np.pi if hd < 0.0 else hd
            if stds:
                _euler_std(Cc, Pa, 0, es)
        elif stds:
            _euler_std(C, Pa, 0, es)
        for i in range(npar):
            p_nom = nav_in[j, 18 + i] if hr else pnom_ep[ep, i]
            out[j, 18 + i] = p_nom - x[9 + i]
        if not stds:
            for i in range(9):
                out[j, 9 + i] = np.nan
            for i in range(npar):
                out[j, 18 + npar + i] = np.nan
            continue
        for i in range(6):
            out[j, 9 + i] = np.sqrt(max(pdiag[i], 0.0))
        for i in range(3):
            out[j, 15 + i] = es[i]
        for i in range(npar):
            out[j, 18 + npar + i] = np.sqrt(max(pdiag[9 + i], 0.0))
