"""The engine's compiled high-rate path: same results as the Python update path, its smoother
equals the RTS smoother over every IMU sample, gating/recovery/health on the compiled path,
and what it refuses."""

from __future__ import annotations

import numpy as np
import pytest
from filter_sim import car_truth, corrupt_imu, gnss_from_truth, nav_errors, perturbed_initial

from insgnss.errors import ConfigError
from insgnss.filter import BodyVelocity, FilterConfig, GnssPosition, Zaru, Zupt, run_filter
from insgnss.filter.smoother import rts_error_state
from insgnss.filter.store import dense_rows
from insgnss.imu import grade


@pytest.fixture(scope="module")
def car():
    """A car with two 15 s stops, tactical IMU, 1 Hz GNSS position."""
    truth = car_truth(150.0, 100.0, stops_after=(0, 1), stop_duration=15.0)
    rng = np.random.default_rng(11)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(truth, rng)
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    t = imu.index.to_numpy()
    still = truth["stationary"].to_numpy(bool)
    return truth, imu, gnss, init, t, still


def _config(**kw):
    return FilterConfig(imu_model="tactical", initial_att_std=(0.005, 0.005, 0.02),
                        propagation_interval=0.01, **kw)


def _meas(gnss, t, still, high_rate):
    ts = t[still][1:]
    moving = t[~still & (t > t[0])][::5]
    return [GnssPosition(gnss), Zupt(ts, std=0.01, high_rate=high_rate),
            Zaru(ts, std=1e-4, average=False, high_rate=high_rate),
            BodyVelocity(moving, 0.0, axes=(0, 2), std=0.05, name="nhc",
                         misalignment_state="mis", high_rate=high_rate)]


def test_compiled_path_agrees_with_python_path(car):
    """ZUPT and ZARU at every still IMU sample and NHC (with an IMU-to-vehicle misalignment
    state) at 20 Hz, on the compiled path and on the Python path (a filterpy epoch each), give
    the same trajectory, innovations and misalignment estimate."""
    truth, imu, gnss, init, t, still = car
    py = run_filter(imu, init, _meas(gnss, t, still, False), _config())
    hr = run_filter(imu, init, _meas(gnss, t, still, True), _config())
    assert py.complete and hr.complete and hr.high_rate is not None
    assert hr.high_rate["t"].size > 0.5 * t.size  # most segments ran sample by sample
    for name in ("zupt", "zaru", "nhc"):
        a = py.innovations[py.innovations.type == name]
        b = hr.innovations[hr.innovations.type == name]
        assert len(a) == len(b) > 100
        np.testing.assert_allclose(a["time"].to_numpy(), b["time"].to_numpy(), atol=1e-9)
        # the covariance propagation differs (second order over 10 ms vs first order per
        # sample): innovations agree to a small fraction of their sigma
        d = np.abs(a["innov_0"].to_numpy() - b["innov_0"].to_numpy()) / a["innov_std_0"].to_numpy()
        print(f"{name}: largest innovation difference {d.max():.3f} sigma")
        assert d.max() < 0.1
    ea, eb = nav_errors(py.forward, truth), nav_errors(hr.forward, truth)
    for c in ("east", "north", "up", "vel_e", "vel_n"):
        scale = np.sqrt(np.mean(ea[c].to_numpy() ** 2))
        assert np.sqrt(np.mean((ea[c] - eb[c]).to_numpy() ** 2)) < 0.05 * scale, c
    np.testing.assert_allclose(hr.forward[["mis_x", "mis_y", "mis_z"]].iloc[-1],
                               py.forward[["mis_x", "mis_y", "mis_z"]].iloc[-1], atol=2e-4)
    hs, ps = nav_errors(hr.smoothed, truth), nav_errors(py.smoothed, truth)
    for c in ("east", "north"):
        assert np.sqrt(np.mean(hs[c] ** 2)) < 1.2 * np.sqrt(np.mean(ps[c] ** 2)) + 0.01


def _rebuild(res):
    """The per-sample node sequence of a run with high-rate segments (the general nodes and
    every high-rate sample, with P(k|k-1), P(k|k) recomputed from the stored F, Qd and updates)
    and the forward-table row of each high-rate sample."""
    hrd, up = res.high_rate, res.updates
    f_ptr, f_col, f_act, q_row, q_col = hrd["pattern"]
    n = res.layout.n
    Pf, Pp, Phi, fb, rows = [], [], [], [], []
    P = None
    for k in range(res.epoch_times.size):
        for h in range(hrd["seg0"][k], hrd["seg1"][k]):
            F = np.zeros((n, n))
            for a, i in enumerate(f_act):
                F[i, f_col[f_ptr[a]:f_ptr[a + 1]]] = hrd["F"][h, f_ptr[a]:f_ptr[a + 1]]
            Q = np.zeros((n, n))
            Q[q_row, q_col] = hrd["Q"][h]
            Ph = np.eye(n) + F
            P = Ph @ P @ Ph.T + Q
            if hrd["Pp_index"][h] >= 0:
                P = hrd["Pp"][hrd["Pp_index"][h]]
            Pp.append(P)
            r = slice(hrd["r0"][h], hrd["r1"][h])
            H = dense_rows(up["H_ptr"], up["H_col"], up["H_val"], r.start, r.stop, n)
            K = up["K"][r].T
            P = (np.eye(n) - K @ H) @ P
            P = 0.5 * (P + P.T)
            Pf.append(P)
            Phi.append(Ph)
            fb.append(hrd["feedback"][h])
            rows.append(hrd["row"][h])
        P = res.P_filtered[k]
        Pf.append(P)
        Pp.append(res.P_predicted[k])
        Phi.append(res.Phi[k])
        fb.append(res.feedback[k])
        rows.append(-1)
    return np.array(Pf), np.array(Pp), np.array(Phi), np.array(fb), np.array(rows)


@pytest.mark.parametrize("covariance", [True, False])
def test_high_rate_smoother_equals_rts_over_every_sample(car, covariance):
    """The engine's backward pass through high-rate segments (adjoint backwards, smoothed
    errors rebuilt forwards without stored covariances) equals the RTS smoother run on every
    IMU sample of them as a node: with the stacked updates (smoothed covariances) and with the
    row-by-row updates the compiled path applies without them (the stored K, S^-1 z are the
    stacked update's)."""
    truth, imu, gnss, init, t, still = car
    res = run_filter(imu, init, _meas(gnss, t, still, True),
                     _config(smoother_covariance=covariance))
    Pf, Pp, Phi, fb, rows = _rebuild(res)
    # high-rate samples (an IMU row at a filter epoch shows the epoch's node instead)
    sel = (rows >= 0) & ~np.isin(t[np.maximum(rows, 0)], res.epoch_times)
    print(f"{sel.sum()} high-rate samples between {res.epoch_times.size} nodes")
    # the rebuilt covariances reproduce the forward table's stds
    np.testing.assert_allclose(np.sqrt(Pf[sel][:, 3, 3]),
                               res.forward["vel_e_std"].to_numpy()[rows[sel]], rtol=1e-6)
    xs_plus, _, _ = rts_error_state(Pf, Pp, Phi, fb)
    fwd, smo = res.forward.to_numpy(), res.smoothed.to_numpy()
    j = rows[sel]
    dv = (fwd[j, 3:6] - xs_plus[sel, 3:6]) - smo[j, 3:6]
    scale = np.abs(xs_plus[sel, 3:6]).max()
    print(f"largest smoothed-velocity difference {np.abs(dv).max():.2e} m/s "
          f"(corrections up to {scale:.2e} m/s)")
    assert np.abs(dv).max() < 1e-6 * max(scale, 1e-3)
    dpar = (fwd[j, 18:24] - xs_plus[sel, 9:15]) - smo[j, 18:24]
    assert np.abs(dpar).max() < 1e-9


def test_recovery_runaway_and_refusals_on_the_compiled_path(car):
    truth, imu, gnss, init, t, still = car
    ts = t[still][1:]
    # an odometer that reports 0.2 m/s during the second stop (a slipping wheel encoder): at
    # every still sample, rejected by the 99.9 % gate; a constraint is never forced in by the
    # gate recovery (issue 22) ...
    second = ts > ts[0] + 30.0
    speed = np.where(second, 0.2, 0.0)
    odo = BodyVelocity(ts, speed, axes=(1,), std=0.005, name="odo", high_rate=True)
    cfg = _config(gate_recovery=2.0, gate_probability=0.999, nis_window=None)
    res = run_filter(imu, init, [GnssPosition(gnss), odo], cfg)
    inn = res.innovations[res.innovations.type == "odo"]
    assert res.complete and int((~inn.accepted).sum()) >= 3 and not inn.recovered.any()
    assert not inn.loc[inn.time > ts[second][0] + 1.0, "accepted"].any()
    # ... but one declared recoverable is force-applied after 2 s; the smoother then sees the
    # inflated P(k|k-1)
    odo = type("RecoverableOdo", (BodyVelocity,), {"recoverable": True})(
        ts, speed, axes=(1,), std=0.005, name="odo", high_rate=True)
    res = run_filter(imu, init, [GnssPosition(gnss), odo], cfg)
    inn = res.innovations[res.innovations.type == "odo"]
    n_rej, n_rec = int((~inn.accepted).sum()), int(inn.recovered.sum())
    print(f"odometer: {n_rej} rejected, {n_rec} recoveries")
    assert res.complete and n_rej >= 3 and n_rec >= 1
    assert inn.loc[inn.recovered, "time"].min() > ts[second][0] + 2.0
    assert np.isfinite(res.smoothed[["lat", "lon", "vel_n"]].to_numpy()).all()
    Pf, Pp, Phi, fb, rows = _rebuild(res)  # the smoother through the recoveries is still RTS
    sel = (rows >= 0) & ~np.isin(t[np.maximum(rows, 0)], res.epoch_times)
    xs_plus, _, _ = rts_error_state(Pf, Pp, Phi, fb)
    j = rows[sel]
    dv = (res.forward.to_numpy()[j, 3:6] - xs_plus[sel, 3:6]) - res.smoothed.to_numpy()[j, 3:6]
    assert np.abs(dv).max() < 1e-6
    # runaway NIS on the compiled path stops the run and keeps what was computed
    flip = 0.5 * (-1.0) ** np.arange(ts.size)  # +-0.5 m/s from sample to sample, sigma 1 mm/s
    # (a constraint is watched only without absolute measurements: health.py)
    liar = BodyVelocity(ts, flip, axes=(1,), std=0.001, name="odo", high_rate=True)
    rb = run_filter(imu, init, [liar],
                    _config(gate_probability=None, nis_window=5.0, nis_min_count=10))
    assert not rb.complete and "runaway NIS" in str(rb.error)
    assert ts[0] < rb.forward.index[-1] < ts[0] + 10.0
    liar = type("RecoverableOdo", (BodyVelocity,), {"recoverable": True})(
        ts, flip, axes=(1,), std=0.001, name="odo", high_rate=True)
    rb = run_filter(imu, init, [GnssPosition(gnss), liar],
                    _config(gate_probability=None, nis_window=5.0, nis_min_count=10))
    assert not rb.complete and "runaway NIS" in str(rb.error)
    # a subclass with its own (Python) evaluate cannot run compiled
    gated = type("Gated", (Zupt,), {"evaluate": lambda self, i, nav: None})(ts, high_rate=True)
    with pytest.raises(ConfigError, match="compiled"):
        run_filter(imu, init, [gated], _config())


def test_coupled_clock_nominal_follows_its_dynamics(car):
    """The nominal of a coupled augmenting block follows its dynamics between updates on both
    paths: a receiver clock's bias grows by drift x dt (and its error covariance with it)."""
    from insgnss.filter import ExtraState, Measurement

    truth, imu, gnss, init, t, still = car

    class ClockOnly(Measurement):
        name = "clock_only"

        def extra_states(self):
            return [ExtraState("clock", 2, (10.0, 0.1), labels=("clock_bias", "clock_drift"),
                               initial_value=(1000.0, 2.5), dynamics=((0.0, 1.0), (0.0, 0.0)),
                               noise=((0.1, 0.0), (0.0, 0.001)))]

        def evaluate(self, i, nav):
            return None

    ts = t[still][1:]
    for hr in (False, True):
        res = run_filter(imu, init, [ClockOnly([5.0]), Zupt(ts, high_rate=hr)],
                         _config(smoother=False))
        f = res.forward
        span = f.index[-1] - f.index[0]
        assert f["clock_drift"].iloc[-1] == pytest.approx(2.5, abs=1e-12)
        assert f["clock_bias"].iloc[-1] == pytest.approx(1000.0 + 2.5 * span, rel=1e-9)
        assert f["clock_bias_std"].iloc[-1] > 0.1 * span  # the drift sigma integrates


def test_sequential_rows_give_the_stacked_update():
    """With uncorrelated rows (diagonal R) the row-by-row update of the compiled path gives the
    stacked update's P(k|k), correction and the smoother's K and S^-1 z."""
    from insgnss.filter.highrate import _kalman_update, _sequential_update
    from insgnss.filter.linalg import _innovation_cov

    rng = np.random.default_rng(5)
    n, m = 15, 6
    A = rng.standard_normal((n, n))
    P0 = A @ A.T * 1e-3 + np.diag(rng.uniform(1e-4, 1e-2, n))
    H = np.zeros((m, n))
    for a in range(3):  # a ZUPT (unit rows) and a ZARU (gyro bias and small attitude terms)
        H[a, 3 + a] = 1.0
        H[3 + a, 9 + a] = -1.0
        H[3 + a, 6:9] = 1e-3 * rng.standard_normal(3)
    rd = np.array([1e-4, 2e-4, 3e-4, 1e-6, 2e-6, 3e-6])
    z = rng.standard_normal(m) * 0.01
    S = H @ P0 @ H.T + np.diag(rd)
    K = P0 @ H.T @ np.linalg.inv(S)
    P_ref = P0 - K @ S @ K.T

    def scratch():
        return (np.zeros(n), np.empty((m, n)), np.empty((m, n)), np.empty(m))

    P = P0.copy()
    x, Kt, _, s = scratch()
    assert _sequential_update(P, H, z, rd, m, x, Kt, s, np.empty(n), np.empty(n),
                              np.empty(n, np.int64), np.empty(n), n)
    P2 = P0.copy()
    x2, Kt2, G2, s2 = scratch()
    HP, S2 = np.empty((m, n)), np.empty((m, m))
    _innovation_cov(H, P2, np.diag(rd), m, HP, S2, n)
    assert _kalman_update(P2, H, z, m, HP, S2, x2, Kt2, G2, s2, np.empty((m, m)),
                          np.empty((m, n)), np.empty((m, n)), True, n)
    np.testing.assert_allclose(P, P_ref, rtol=0, atol=1e-12 * np.abs(P0).max())
    np.testing.assert_array_equal(P, P.T)
    for got, stacked, ref in ((x, x2, K @ z), (Kt, Kt2, K.T), (s, s2, np.linalg.solve(S, z))):
        tol = 1e-9 * np.abs(ref).max()
        np.testing.assert_allclose(got, ref, rtol=0, atol=tol)
        np.testing.assert_allclose(stacked, ref, rtol=0, atol=tol)
    # a row whose innovation variance is not positive refuses the update
    P = P0.copy()
    P[3, 3] = -1.0
    assert not _sequential_update(P, H, z, rd, m, x, Kt, s, np.empty(n), np.empty(n),
                                  np.empty(n, np.int64), np.empty(n), n)


def test_row_pattern_gives_the_dense_innovation_blocks():
    """H P and the diagonal blocks of S formed from the non-zeros of the rows (the row pattern
    the compiled path finds once per sample) are the dense sums bit for bit, and the pattern
    holds exactly the non-zero columns of each row."""
    from insgnss.filter.highrate import _innovation_cov_blocks, row_pattern

    rng = np.random.default_rng(11)
    n, m = 15, 6
    A = rng.standard_normal((n, n))
    P = A @ A.T * 1e-3 + np.eye(n) * 1e-4
    H = np.zeros((m, n))
    for a in range(3):
        H[a, 3 + a] = 1.0
        H[3 + a, 9 + a] = -1.0
        H[3 + a, 6:9] = 1e-3 * rng.standard_normal(3)
    R = np.diag(rng.uniform(1e-6, 1e-4, m))
    off = np.array([0, 3, 6])
    nzn, nzc, nzv = np.empty(m, np.int64), np.empty((m, n), np.int64), np.empty((m, n))
    row_pattern(H, m, n, nzn, nzc, nzv)
    assert nzn.tolist() == [1, 1, 1, 4, 4, 4]
    for p in range(m):
        np.testing.assert_array_equal(nzc[p, :nzn[p]], np.flatnonzero(H[p]))
        np.testing.assert_array_equal(nzv[p, :nzn[p]], H[p, np.flatnonzero(H[p])])
    HP1, S1 = np.zeros((m, n)), np.zeros((m, m))
    HP2, S2 = np.zeros((m, n)), np.zeros((m, m))
    _innovation_cov_blocks(H, P, R, off, 2, HP1, S1, n)
    _innovation_cov_blocks(H, P, R, off, 2, HP2, S2, n, nzn, nzc, nzv)
    np.testing.assert_array_equal(HP1, HP2)
    np.testing.assert_array_equal(S1, S2)
    S_ref = H @ P @ H.T + R
    for o0, o1 in ((0, 3), (3, 6)):
        np.testing.assert_allclose(S2[o0:o1, o0:o1], S_ref[o0:o1, o0:o1], rtol=1e-12)


def test_nis3_is_the_general_nis():
    """The written-out 3 x 3 NIS of the compiled path gives the general Cholesky NIS bit for
    bit, and NaN for a block that is not positive definite."""
    from insgnss.filter.gating import nis3, nis_into

    rng = np.random.default_rng(3)
    for _ in range(50):
        A = rng.standard_normal((3, 3))
        S = np.zeros((5, 5))
        S[1:4, 1:4] = A @ A.T + np.diag(rng.uniform(1e-6, 1e-2, 3))
        y = np.zeros(5)
        y[1:4] = rng.standard_normal(3) * 0.1
        ref = nis_into(S[1:4, 1:4], y[1:4], np.empty((3, 3)), np.empty(3))
        assert nis3(S, 1, y) == ref
        assert abs(ref - y[1:4] @ np.linalg.solve(S[1:4, 1:4], y[1:4])) < 1e-9 * ref
    S[2, 2] = -1.0
    assert np.isnan(nis3(S, 1, y))
