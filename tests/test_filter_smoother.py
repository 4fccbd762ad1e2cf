"""RTS smoother: exact equivalence with filterpy's smoother on a linear system run in closed
loop, and the 60 s GNSS-outage must-show (forward inside 3 sigma, smoother >= 5x better)."""

from __future__ import annotations

import numpy as np
from filter_sim import car_truth, corrupt_imu, gnss_from_truth, nav_errors, perturbed_initial
from filterpy.kalman import predict, rts_smoother, update

from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity, rts_error_state, run_filter
from insgnss.imu import grade


def test_closed_loop_error_state_smoother_equals_filterpy_rts():
    """On a linear system the closed-loop (feedback + reset) error-state filter and smoother
    must reproduce the ordinary Kalman filter and filterpy's RTS smoother exactly."""
    rng = np.random.default_rng(0)
    n, m, K = 4, 2, 60
    dt = 0.5
    F = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 0.98]])
    Q = np.diag([1e-3, 1e-2, 1e-3, 5e-2])
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    R = np.diag([0.5, 0.8])
    P0 = np.diag([4.0, 1.0, 4.0, 1.0])
    x = rng.multivariate_normal(np.zeros(n), P0)
    zs = []
    for k in range(K):
        if k:
            x = F @ x + rng.multivariate_normal(np.zeros(n), Q)
        zs.append(H @ x + rng.multivariate_normal(np.zeros(m), R))
    # ordinary KF + filterpy RTS
    xh, P = np.zeros(n), P0.copy()
    Xs, Ps = [], []
    for k in range(K):
        if k:
            xh, P = predict(xh, P, F, Q)
        if k % 7 != 3:  # some epochs without measurement
            xh, P = update(xh, P, zs[k], R, H)
        Xs.append(xh)
        Ps.append(P)
    xs_ref, Ps_ref, _, _ = rts_smoother(np.array(Xs), np.array(Ps), np.array([F] * K), np.array([Q] * K))
    # closed loop: nominal propagated by F, error state estimated, fed back, reset
    nom = np.zeros(n)
    dx, P = np.zeros(n), P0.copy()
    Pf, Pp, Phi, fb, noms = [], [], [], [], []
    for k in range(K):
        if k:
            nom = F @ nom
            dx, P = predict(dx, P, F, Q)
        Pp.append(P)
        Phi.append(F if k else np.eye(n))
        if k % 7 != 3:
            dx, P = update(dx, P, H @ nom - zs[k], R, H)  # z = h(nominal) - measured
        fb.append(dx)
        nom = nom - dx
        dx = np.zeros(n)
        Pf.append(P)
        noms.append(nom)
    assert np.allclose(np.array(noms), np.array(Xs), atol=1e-12)
    xs_plus, xs_minus, Psm = rts_error_state(np.array(Pf), np.array(Pp), np.array(Phi), np.array(fb))
    assert np.allclose(np.array(noms) - xs_plus, xs_ref, atol=1e-10)
    assert np.allclose(Psm, Ps_ref, atol=1e-10)
    assert np.allclose(xs_minus, xs_plus + np.array(fb))


def test_outages_forward_within_3_sigma_and_smoother_5x_better():
    outages = [(100.0, 160.0), (220.0, 280.0)]
    truth = car_truth(330.0, 50.0)
    model = grade("tactical")
    rng = np.random.default_rng(31)
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng, horizontal_std=0.3, vertical_std=0.6, velocity_std=0.03,
                           vertical_velocity_std=0.06)
    keep = np.ones(len(gnss), bool)
    for a, b in outages:
        keep &= ~((gnss.index > a) & (gnss.index < b))
    gnss = gnss[keep]
    init, _ = perturbed_initial(truth, rng, 0.3, 0.05, (0.005, 0.005, 0.02))
    cfg = FilterConfig(imu_model=model, initial_pos_std=0.3, initial_vel_std=0.05,
                       initial_att_std=(0.005, 0.005, 0.02))
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    ef = nav_errors(res.forward, truth)
    es = nav_errors(res.smoothed, truth)
    t = ef.index.to_numpy()
    for a, b in outages:
        w = (t > a) & (t < b)
        f = res.forward[w]
        for c, s in (("east", "east_std"), ("north", "north_std"), ("up", "up_std"),
                     ("vel_e", "vel_e_std"), ("vel_n", "vel_n_std")):
            assert np.all(np.abs(ef[c].to_numpy()[w]) <= 3 * f[s].to_numpy()), (a, c)
        # the smoothed error is inside its own 3 sigma too
        for c, s in (("east", "east_std"), ("north", "north_std")):
            assert np.all(np.abs(es[c].to_numpy()[w]) <= 3 * res.smoothed[s].to_numpy()[w]), (a, c)
        hf = np.hypot(ef["east"], ef["north"]).to_numpy()[w].max()
        hs = np.hypot(es["east"], es["north"]).to_numpy()[w].max()
        print(f"outage {a:.0f}-{b:.0f} s: max horizontal error forward {hf:.2f} m, smoothed {hs:.3f} m")
        assert hf > 1.0, hf  # a real coast
        assert hf >= 5 * hs, (a, hf, hs)


def test_engine_smoother_equals_rts_on_its_stored_quantities():
    """The engine's backward pass (modified Bryson-Frazier form) and the RTS form on the stored
    P(k|k), P(k|k-1), Phi and feedback give the same smoothed covariances and states, through a
    GNSS outage: the store holds everything the RTS form (and an EM tuner) needs."""
    from insgnss.earth import radii

    truth = car_truth(120.0, 50.0)
    rng = np.random.default_rng(5)
    model = grade("tactical")
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng)
    gnss = gnss[(gnss.index < 50.0) | (gnss.index > 80.0)]
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    cfg = FilterConfig(imu_model=model, initial_att_std=(0.005, 0.005, 0.02))
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    xs_plus, _, Ps = rts_error_state(res.P_filtered, res.P_predicted, res.Phi, res.feedback)
    scale = np.sqrt(np.einsum("kii->ki", Ps))
    d = np.abs(res.P_smoothed - Ps) / (scale[:, :, None] * scale[:, None, :])
    print(f"largest correlation-scaled difference of the smoothed covariances: {d.max():.2e}")
    assert d.max() < 1e-7
    rows = res.smoothed.index.get_indexer(res.epoch_times)
    f, s = res.forward.iloc[rows], res.smoothed.iloc[rows]
    M, _ = radii(f["lat"].to_numpy())
    lat_rts = f["lat"].to_numpy() - xs_plus[:, 1] / (M + f["height"].to_numpy())
    north = (s["lat"].to_numpy() - lat_rts) * (M + f["height"].to_numpy())
    vel = s[["vel_e", "vel_n", "vel_u"]].to_numpy() - (f[["vel_e", "vel_n", "vel_u"]].to_numpy()
                                                       - xs_plus[:, 3:6])
    print(f"largest smoothed-state difference: north {np.abs(north).max():.2e} m, "
          f"velocity {np.abs(vel).max():.2e} m/s")
    assert np.abs(north).max() < 1e-6 and np.abs(vel).max() < 1e-8
