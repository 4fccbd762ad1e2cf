"""Error-state model: layout, process noise from the IMU model, F against finite differences of
the strapdown, discretisation (second order vs van Loan vs scipy)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from filter_sim import turning_truth

from insgnss.attitude import attitude_error, euler_to_dcm, rotvec_to_dcm
from insgnss.earth import normal_gravity, radii
from insgnss.filter import ExtraState, StateLayout, error_dynamics, kernels, process_model
from insgnss.imu import grade, increments
from insgnss.mechanization.inverse import inverse_mechanize


def test_layout_blocks_and_extras():
    lay = StateLayout()
    assert lay.n == 15 and lay["att"] == slice(6, 9) and lay.index("gyro_scale") == -1
    lay = StateLayout(True, [ExtraState("odo", 1, 0.01), ExtraState("mis", 3, 0.02)])
    assert lay.n == 25
    assert lay["gyro_scale"] == slice(15, 18) and lay["accel_scale"] == slice(18, 21)
    assert lay["odo"] == slice(21, 22) and lay["mis"] == slice(22, 25)
    assert lay.labels[21:] == ["odo", "mis_0", "mis_1", "mis_2"]
    # the same extra state declared twice (e.g. by NHC and odometer models) is shared
    lay2 = StateLayout(False, [ExtraState("odo", 1, 0.01), ExtraState("odo", 1, 0.01)])
    assert lay2.n == 16
    with pytest.raises(ValueError):
        StateLayout(False, [ExtraState("odo", 1, 0.01), ExtraState("odo", 1, 0.02)])
    with pytest.raises(KeyError):
        lay["nope"]


def test_process_model_from_grade():
    m = grade("tactical")
    lay = StateLayout(True)
    gm = process_model(lay, m, "gauss_markov")
    tau = m.bias_correlation_time
    assert np.allclose(gm.decay[9:12], 1 / tau) and np.allclose(gm.decay[12:15], 1 / tau)
    assert np.allclose(gm.qdiag[9:12], 2 * m.gyro_bias_instability**2 / tau)
    assert np.allclose(gm.qdiag[12:15], 2 * m.accel_bias_instability**2 / tau)
    assert np.allclose(gm.p0[9:12], np.hypot(m.gyro_bias, m.gyro_bias_instability))
    assert np.allclose(gm.p0[15:18], m.gyro_scale) and np.allclose(gm.p0[18:21], m.accel_scale)
    assert np.allclose(gm.gyro_psd, m.gyro_arw**2) and np.allclose(gm.accel_psd, m.accel_vrw**2)
    rw = process_model(lay, m, "random_walk")
    assert np.all(rw.decay == 0) and np.allclose(rw.qdiag[9:12], 2 * m.gyro_bias_instability**2 / tau)
    rw2 = process_model(lay, m.scaled(gyro_rrw=1e-7), "random_walk")
    assert np.allclose(rw2.qdiag[9:12], 1e-14)
    rc = process_model(lay, m, "random_constant")
    assert np.all(rc.qdiag == 0) and np.all(rc.decay == 0)
    with pytest.raises(ValueError):
        process_model(lay, m, "pink")


def _run(t, dth, dv, pos, vel, C, pnom, n, i_sg, i_sa, t_end):
    N = t.size
    Fint = np.zeros((200, n, n))
    Qint = np.zeros((200, 2, 3, 3))
    sub_dt = np.zeros(200)
    out = (np.empty((N, 9)), np.zeros(N, np.int64))
    _, _, ns = kernels.propagate_nominal(t, dth, dv, 1, 0.0, t_end, pos, vel, C, pnom, i_sg, i_sa,
                                         0, 0, 0.1, Fint, Qint, sub_dt, np.zeros(3), np.zeros(3),
                                         *out, 1, np.zeros((4, 3)))
    Phi, Qd = np.eye(n), np.zeros((n, n))
    kernels.discretize(Fint, Qint, sub_dt, ns, np.zeros(n), np.zeros(n), 0, Phi, Qd)
    return Phi


def _err(a, b):
    (pa, va, Ca, qa), (pb, vb, Cb, qb) = a, b
    M, N = radii(pb[0])
    h = pb[2]
    dr = [(pa[1] - pb[1]) * (N + h) * np.cos(pb[0]), (pa[0] - pb[0]) * (M + h), pa[2] - pb[2]]
    return np.concatenate([dr, va - vb, attitude_error(Ca, Cb), qa - qb])


@pytest.mark.parametrize("scale_factors", [False, True])
def test_transition_matrix_matches_perturbed_strapdown(scale_factors):
    """Phi from the compiled F (1 s, 0.1 s sub-intervals, manoeuvring car at 20 m/s turning
    17 deg/s) predicts the difference of two strapdown runs started from states that differ
    by one error-state direction, for every direction (signs and couplings of all blocks)."""
    truth = turning_truth()
    t, dth, dv = increments(inverse_mechanize(truth))
    lay = StateLayout(scale_factors)
    n = lay.n
    r0 = truth.iloc[0]
    pos0 = np.array([r0.lat, r0.lon, r0.height])
    vel0 = r0[["vel_e", "vel_n", "vel_u"]].to_numpy(float)
    C0 = euler_to_dcm(r0.roll, r0.pitch, r0.heading)
    bt = np.array([1e-5, -2e-5, 1.5e-5, 0.01, -0.02, 0.015])
    st = np.array([1e-3, -2e-3, 5e-4, 2e-3, -1e-3, 1e-3]) if scale_factors else np.zeros(6)
    dts = np.diff(t, prepend=t[0])[:, None]
    dthr = dth * (1 + st[:3]) + bt[:3] * dts
    dvr = dv * (1 + st[3:]) + bt[3:] * dts
    dthr[0] = dvr[0] = 0.0
    ptrue = np.concatenate([bt, st]) if scale_factors else bt.copy()
    i_sg, i_sa = lay.index("gyro_scale"), lay.index("accel_scale")
    true_state = (pos0.copy(), vel0.copy(), C0.copy(), ptrue.copy())
    Phi = _run(t, dthr, dvr, *true_state, n, i_sg, i_sa, t[0] + 1.0)
    scales = np.array([5.0] * 3 + [0.05] * 3 + [1e-3] * 3 + [2e-5] * 3 + [2e-3] * 3
                      + ([1e-3] * 6 if scale_factors else []))
    M, N = radii(pos0[0])
    for k in range(n):
        d0 = np.zeros(n)
        d0[k] = scales[k]
        posn = pos0 + np.array([d0[1] / (M + pos0[2]), d0[0] / ((N + pos0[2]) * np.cos(pos0[0])), d0[2]])
        nominal = (posn, vel0 + d0[3:6], rotvec_to_dcm(d0[6:9]) @ C0, ptrue + d0[9:])
        _run(t, dthr, dvr, *nominal, n, i_sg, i_sa, t[0] + 1.0)
        d1 = _err(nominal, true_state)
        pred = Phi @ d0
        resid = np.max(np.abs((d1 - pred) / scales))
        assert resid < 1e-3 * np.max(np.abs(pred / scales)), (lay.labels[k], resid)
        # the coupling is really there (not a trivially satisfied check)
        if k in (6, 7, 12, 13):
            assert np.max(np.abs(pred[3:6] / scales[3:6])) > 0.01


def test_error_dynamics_wrapper_matches_known_blocks():
    lat, h = np.deg2rad(45.0), 100.0
    C = euler_to_dcm(0.0, 0.0, 0.0)
    f_b = np.array([0.0, 1.0, 9.8])
    F = error_dynamics(lat, h, np.zeros(3), C, f_b, np.zeros(3), StateLayout())
    assert np.allclose(F[0:3, 3:6], np.eye(3))
    # -[f^l x] with f^l = (0, 1, 9.8)
    assert np.allclose(F[3:6, 6:9], -np.array([[0, -9.8, 1.0], [9.8, 0, 0], [-1.0, 0, 0]]))
    assert np.allclose(F[3:6, 12:15], -C) and np.allclose(F[6:9, 9:12], -C)
    M, N = radii(lat)
    # gravity gradient: -dg/dh (0.34 % above 2 g / sqrt(M N)) and -dg/dlat / (M + h)
    assert F[5, 2] == pytest.approx((normal_gravity(lat, h - 1) - normal_gravity(lat, h + 1)) / 2,
                                    rel=1e-9)
    assert F[5, 2] == pytest.approx(1.0034 * 2 * normal_gravity(lat, h) / (np.sqrt(M * N) + h),
                                    rel=3e-4)
    e = 1e-5
    assert F[5, 1] == pytest.approx(-(normal_gravity(lat + e, h) - normal_gravity(lat - e, h))
                                    / (2 * e) / (M + h), rel=1e-6)


def _random_FQ(rng, n=15, T=0.1):
    F = np.zeros((n, n))
    F[0:3, 3:6] = np.eye(3)
    F[3:6, 6:9] = rng.standard_normal((3, 3)) * 5
    F[3:6, 12:15] = -np.eye(3)
    F[6:9, 9:12] = -np.eye(3)
    F[6:9, 6:9] = rng.standard_normal((3, 3)) * 1e-4
    Q = np.zeros((n, n))
    Q[3:6, 3:6] = np.diag([1e-6, 2e-6, 3e-6])
    Q[6:9, 6:9] = np.diag([1e-9, 1e-9, 2e-9])
    Q[9:15, 9:15] = np.eye(6) * 1e-12
    return F, Q


def test_discretize_vanloan_matches_scipy_and_second_order():
    rng = np.random.default_rng(3)
    n, T = 15, 0.1
    F, Q = _random_FQ(rng, n, T)
    Fint = (F * T)[None].copy()
    Qint = np.zeros((1, 2, 3, 3))
    Qint[0, 0] = Q[6:9, 6:9] * T
    Qint[0, 1] = Q[3:6, 3:6] * T
    qdiag = np.diag(Q).copy()
    qdiag[3:9] = 0.0
    decay = np.zeros(n)
    decay[9:15] = 1 / 300.0
    Fd = F - np.diag(decay)
    Mb = np.block([[-Fd, Q], [np.zeros((n, n)), Fd.T]]) * T
    E = scipy.linalg.expm(Mb)
    Phi_ref = E[n:, n:].T
    Qd_ref = Phi_ref @ E[:n, n:]
    assert np.allclose(kernels.expm_nb(Mb), E, atol=1e-14, rtol=1e-12)
    out = {}
    for method in (0, 1):
        Phi, Qd = np.eye(n), np.zeros((n, n))
        tot = kernels.discretize(Fint, Qint, np.array([T]), 1, decay, qdiag, method, Phi, Qd)
        assert tot == pytest.approx(T)
        out[method] = (Phi, Qd)
    assert np.allclose(out[1][0], Phi_ref, atol=1e-13)
    assert np.allclose(out[1][1], Qd_ref, atol=1e-18, rtol=1e-10)
    # second order: Phi to O((F T)^3), Qd to O(T^4)
    assert np.max(np.abs(out[0][0] - Phi_ref)) < 0.05 * np.max(np.abs(F * T)) ** 3
    assert np.allclose(out[0][1], Qd_ref, rtol=1e-2, atol=1e-3 * np.max(np.abs(Qd_ref)))
    # analytic: velocity random walk into position, Qd_rr = q T^3 / 3, Qd_rv = q T^2 / 2
    assert out[1][1][0, 0] == pytest.approx(1e-6 * T**3 / 3, rel=1e-3)
    assert out[1][1][0, 3] == pytest.approx(1e-6 * T**2 / 2, rel=1e-3)


def test_discretize_composition_equals_sequential_propagation():
    rng = np.random.default_rng(5)
    n, T = 15, 0.1
    subs = [_random_FQ(rng, n, T) for _ in range(4)]
    Fint = np.array([F * T for F, _ in subs])
    Qint = np.zeros((4, 2, 3, 3))
    for s, (_, Q) in enumerate(subs):
        Qint[s, 0] = Q[6:9, 6:9] * T
        Qint[s, 1] = Q[3:6, 3:6] * T
    qdiag = np.diag(subs[0][1]).copy()
    qdiag[3:9] = 0
    decay = np.zeros(n)
    Phi, Qd = np.eye(n), np.zeros((n, n))
    kernels.discretize(Fint, Qint, np.full(4, T), 4, decay, qdiag, 1, Phi, Qd)
    P0 = np.diag(rng.uniform(0.5, 2, n))
    P = P0.copy()
    for s in range(4):
        Phi_s, Qd_s = np.eye(n), np.zeros((n, n))
        kernels.discretize(Fint[s:s + 1], Qint[s:s + 1], np.array([T]), 1, decay, qdiag, 1, Phi_s, Qd_s)
        P = Phi_s @ P @ Phi_s.T + Qd_s
    assert np.allclose(Phi @ P0 @ Phi.T + Qd, P, rtol=1e-12, atol=1e-15)


def test_coupled_extra_state_block_discretizes_exactly():
    """An augmenting block with its own dynamics and noise (a GNSS receiver clock: bias [m],
    drift [m/s], Phi = [[1, dt], [0, 1]]) gets the exact transition and the exact integrated
    noise ``[[q_b T + q_d T^3/3, q_d T^2/2], [q_d T^2/2, q_d T]]``, also composed over
    sub-intervals, and is untouched by the navigation states."""
    qb, qd = 0.4, 0.02
    clock = ExtraState("clock", 2, initial_std=(30.0, 1.0), labels=("clock_bias", "clock_drift"),
                       dynamics=((0.0, 1.0), (0.0, 0.0)), noise=((qb, 0.0), (0.0, qd)))
    lay = StateLayout(False, [clock])
    pm = process_model(lay, grade("tactical"))
    assert lay.n == 17 and pm.Fx is not None and pm.Qx is not None
    n, T, ns = lay.n, 0.1, 5
    Fint = np.zeros((ns, n, n))
    Qint = np.zeros((ns, 2, 3, 3))
    Phi, Qd = np.eye(n), np.zeros((n, n))
    kernels.discretize(Fint, Qint, np.full(ns, T), ns, pm.decay, pm.qdiag, 0, Phi, Qd, pm.Fx,
                       pm.Qx)
    c = lay["clock"]
    tt = ns * T
    np.testing.assert_allclose(Phi[c, c], [[1.0, tt], [0.0, 1.0]], atol=1e-15)
    np.testing.assert_allclose(Qd[c, c], [[qb * tt + qd * tt**3 / 3, qd * tt**2 / 2],
                                          [qd * tt**2 / 2, qd * tt]], rtol=1e-12)
    assert np.all(Phi[c, :15] == 0) and np.all(Qd[c, :15] == 0)
    with pytest.raises(ValueError):
        ExtraState("clock", 2, dynamics=((0.0, 1.0),))
