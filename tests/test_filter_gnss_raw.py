"""Tightly coupled measurement models (insgnss.filter.gnss_raw): Jacobians against finite
differences of the predicted pseudorange / range rate, the receiver-clock process model, and a
simulated EKF with known satellite geometry and truth (clock, position errors inside 3 sigma,
NEES consistent)."""

from __future__ import annotations

import numpy as np
import pytest
from gnss_helpers import ALPHA, BETA, CFG, ION, T0, pr_noise, simulate_observations, synthetic_constellation
from scipy.linalg import expm

from insgnss.earth import (
    ecef_to_enu_matrix,
    ecef_to_geodetic,
    enu_displacement_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
    radii,
)
from insgnss.filter.gnss_raw import Doppler, Pseudorange, ReceiverClock
from insgnss.filter.measurements import NominalState
from insgnss.filter.models import StateLayout
from insgnss.gnss import SppConfig, prepare_observations, spp
from insgnss.gnss.observations import range_rate_variance

LAT0, LON0, H0 = np.radians(40.1), np.radians(-105.15), 1600.0
R0 = np.array(geodetic_to_ecef(LAT0, LON0, H0))



def make_nav(layout, lat, lon, h, vel, C, omega, params) -> NominalState:
    nav = NominalState()
    nav.time, nav.lat, nav.lon, nav.height = 0.0, lat, lon, h
    nav.vel, nav.C = np.asarray(vel, float), np.asarray(C, float)
    nav.omega_ib = nav.omega_ib_mean = np.asarray(omega, float)
    nav.f_ib = nav.f_ib_mean = np.array([0.0, 0.0, 9.8])
    nav.segment_duration = 0.1
    nav.params = np.asarray(params, float)
    nav.layout = layout
    nav.M, nav.N = radii(lat)
    nav.gyro_psd = np.full(3, 1e-8)
    return nav


@pytest.fixture(scope="module")
def one_epoch():
    eph = synthetic_constellation(T0)
    obs, truth = simulate_observations(eph, [T0 + 5.0], lambda t: R0 + np.array([1.0, -2.0, 0.5])
                                       * (t - T0), lambda t: -4.6e5 - 70.0 * (t - T0),
                                       isb={"E": 12.5}, iono=(ALPHA, BETA))
    return eph, obs, prepare_observations(obs, eph, CFG)


def test_jacobians_match_finite_differences(one_epoch):
    eph, obs, prep = one_epoch
    lever = np.array([0.3, 0.6, 0.9])
    pr = Pseudorange(prep, ION, lever_arm=lever, config=CFG,
                     clock=ReceiverClock(initial_bias=-4.6e5, initial_drift=-70.0))
    dp = Doppler(prep, ION, lever_arm=lever, config=CFG, clock=pr.clock)
    layout = StateLayout(extras=pr.extra_states())
    assert layout.n == 18 and "isb_E" in layout and layout["clock"] == slice(15, 17)
    C = expm(np.array([[0, -0.7, 0.1], [0.7, 0, -0.2], [-0.1, 0.2, 0]]))
    vel, omega = np.array([1.2, -0.8, 0.1]), np.array([0.05, -0.3, 0.4])
    params = np.zeros(layout.n - 9)
    params[layout["clock"].start - 9:layout["clock"].stop - 9] = [-4.6e5 + 3.0, -70.0 + 0.2]
    params[layout["isb_E"].start - 9] = 11.0

    def nav_of(dpos=None, dvel=None, datt=None, dbg=None, dpar=None):
        z3 = np.zeros(3)
        dpos, dvel = (z3 if dpos is None else dpos), (z3 if dvel is None else dvel)
        datt, dbg = (z3 if datt is None else datt), (z3 if dbg is None else dbg)
        dlat, dlon, dh = enu_displacement_to_geodetic(LAT0, H0, *dpos)
        p = params.copy() if dpar is None else params + dpar
        Cp = expm(np.array([[0, -datt[2], datt[1]], [datt[2], 0, -datt[0]],
                            [-datt[1], datt[0], 0]])) @ C
        return make_nav(layout, LAT0 + dlat, LON0 + dlon, H0 + dh, vel + dvel, Cp,
                        omega - dbg, p)

    checked = 0
    for m in (pr, dp):
        for i in range(len(m)):
            res = m.evaluate(i, nav_of())
            if res is None:
                continue
            z0, H, R = res
            assert z0.shape == (1,) and H.shape == (1, layout.n) and R.shape == (1, 1)
            assert R[0, 0] > 0
            num = np.zeros(layout.n)
            for k, eps in [(0, 1.0), (1, 1.0), (2, 1.0), (3, 1e-2), (4, 1e-2), (5, 1e-2),
                           (6, 1e-3), (7, 1e-3), (8, 1e-3), (9, 1e-4), (10, 1e-4), (11, 1e-4)]:
                e = np.zeros(3)
                e[k % 3] = eps
                kw = {0: "dpos", 1: "dvel", 2: "datt", 3: "dbg"}[k // 3]
                zp = m.evaluate(i, nav_of(**{kw: e}))[0][0]
                zm = m.evaluate(i, nav_of(**{kw: -e}))[0][0]
                num[k] = (zp - zm) / (2 * eps)
            for k in range(15, layout.n):
                e = np.zeros(layout.n - 9)
                e[k - 9] = 1.0
                num[k] = (m.evaluate(i, nav_of(dpar=e))[0][0]
                          - m.evaluate(i, nav_of(dpar=-e))[0][0]) / 2.0
            # H includes the change of the tropospheric delay with the antenna height; only
            # the ionospheric pierce point's motion (~1e-7 per metre) is left out
            atol = np.full(layout.n, 1e-6)
            bad = ~np.isclose(H[0], num, atol=atol, rtol=1e-4)
            assert not bad.any(), (m.name, i, np.nonzero(bad), H[0][bad], num[bad])
            checked += 1
    assert checked > 15
    # per-row labels and gating objects: one evaluation per satellite
    assert pr.row_label(0) == prep["sat"].iloc[0]
    assert len(pr) == len(prep) == len(dp)


def test_models_reproduce_measurements_at_the_truth(one_epoch):
    eph, obs, prep = one_epoch
    b_true = -4.6e5 - 70.0 * 5.0
    pr = Pseudorange(prep, ION, config=CFG)
    dp = Doppler(prep, ION, config=pr.config)
    layout = StateLayout(extras=pr.extra_states())
    params = np.zeros(layout.n - 9)
    params[layout["clock"].start - 9:layout["clock"].stop - 9] = [b_true, -70.0]
    params[layout["isb_E"].start - 9] = 12.5
    r = R0 + np.array([1.0, -2.0, 0.5]) * 5.0
    lat, lon, h = ecef_to_geodetic(*r)
    v = ecef_to_enu_matrix(lat, lon) @ np.array([1.0, -2.0, 0.5])
    nav = make_nav(layout, lat, lon, h, v, np.eye(3), np.zeros(3), params)
    zr = np.array([z[0][0] for z in (pr.evaluate(i, nav) for i in range(len(pr))) if z])
    zd = np.array([z[0][0] for z in (dp.evaluate(i, nav) for i in range(len(dp))) if z])
    assert zr.size > 8 and zd.size == zr.size
    assert np.abs(zr).max() < 5e-3  # noise-free simulation: residual of the light-time model
    assert np.abs(zd).max() < 5e-3


def test_clock_process_noise_is_the_integrated_two_state_model():
    clk = ReceiverClock(h0=2e-19, h_m2=2e-20)
    dt = 2.0
    sf, sg = clk.psd
    # van Loan: Qd = int_0^dt Phi(s) G Q G^T Phi(s)^T ds for x' = [[0,1],[0,0]] x + w
    F = np.array([[0.0, 1.0], [0.0, 0.0]])
    Qc = np.diag([sf, sg])
    M = expm(np.block([[-F, Qc], [np.zeros((2, 2)), F.T]]) * dt)
    Qd = M[2:, 2:].T @ M[:2, 2:]
    assert np.allclose(clk.process_noise(dt), Qd, rtol=1e-12)
    assert np.allclose(clk.transition(dt), expm(F * dt))
    # Allan variance of the model at tau: h0 / (2 tau) + (2 pi^2 / 3) h_-2 tau
    assert sf == pytest.approx(299792458.0**2 * 1e-19)
    ex = clk.extra_state()
    assert ex.size == 2 and ex.element_labels() == ["clock_bias", "clock_drift"]


class _ClockEkf:
    """Minimal EKF for the tests: constant-velocity receiver + clock (bias, drift) + ISBs,
    with the engine's conventions (error state nominal - true, ENU position/velocity errors,
    closed-loop feedback, sequential per-satellite updates with chi-square gating)."""

    def __init__(self, models, layout, lat, lon, h, vel, P0_diag, params, q_vel=1e-6):
        self.models, self.layout = models, layout
        self.lat, self.lon, self.h = lat, lon, h
        self.vel = np.asarray(vel, float)
        self.params = np.asarray(params, float)
        self.P = np.diag(P0_diag)
        self.q_vel = q_vel
        self.clock = models[0].clock
        self.rejected = 0

    def predict(self, dt):
        n, c = self.layout.n, self.layout["clock"]
        Phi = np.eye(n)
        Phi[0:3, 3:6] = np.eye(3) * dt
        Phi[c, c] = self.clock.transition(dt)
        Q = np.zeros((n, n))
        Q[0:3, 0:3] = np.eye(3) * self.q_vel * dt**3 / 3
        Q[0:3, 3:6] = Q[3:6, 0:3] = np.eye(3) * self.q_vel * dt**2 / 2
        Q[3:6, 3:6] = np.eye(3) * self.q_vel * dt
        Q[c, c] = self.clock.process_noise(dt)
        for ex in self.layout.extras[1:]:
            s = self.layout[ex.name]
            Q[s, s] = ex.psd * dt
        self.P = Phi @ self.P @ Phi.T + Q
        dlat, dlon, dh = enu_displacement_to_geodetic(self.lat, self.h, *(self.vel * dt))
        self.lat, self.lon, self.h = self.lat + dlat, self.lon + dlon, self.h + dh
        i = c.start - 9
        self.params[i] += self.params[i + 1] * dt

    def update(self, rows):
        from scipy.stats import chi2

        thr = chi2.ppf(0.9999, 1)
        for m in self.models:
            for i in rows:
                nav = make_nav(self.layout, self.lat, self.lon, self.h, self.vel, np.eye(3),
                               np.zeros(3), self.params)
                res = m.evaluate(i, nav)
                if res is None:
                    continue
                z, H, R = res
                S = H @ self.P @ H.T + R
                if z @ np.linalg.solve(S, z) > thr:
                    self.rejected += 1
                    continue
                K = self.P @ H.T @ np.linalg.inv(S)
                x = K @ z
                IKH = np.eye(self.layout.n) - K @ H
                self.P = IKH @ self.P @ IKH.T + K @ R @ K.T
                dlat, dlon, dh = enu_displacement_to_geodetic(self.lat, self.h, *x[0:3])
                self.lat, self.lon, self.h = self.lat - dlat, self.lon - dlon, self.h - dh
                self.vel = self.vel - x[3:6]
                self.params[6:] -= x[15:]


def test_simulated_tight_filter_is_consistent():
    rng = np.random.default_rng(7)
    eph = synthetic_constellation(T0)
    clock = ReceiverClock(h0=2e-21, h_m2=2e-22)  # an OCXO-like clock: smooth over 0.1 s
    # truth: clock sample path on a fine grid, constant velocity
    dt_fine, n_fine = 0.05, 2600
    Phi, Qd = clock.transition(dt_fine), clock.process_noise(dt_fine)
    Lq = np.linalg.cholesky(Qd)
    xs = np.zeros((n_fine, 2))
    xs[0] = [-4.6e5, -70.0]
    for k in range(1, n_fine):
        xs[k] = Phi @ xs[k - 1] + Lq @ rng.standard_normal(2)
    tg = T0 + dt_fine * np.arange(n_fine)

    def clock_fn(t):
        return float(np.interp(t, tg, xs[:, 0]))

    v_ecef = np.array([1.5, -1.0, 0.3])
    times = T0 + 1.0 + np.arange(100) * 1.0
    obs, truth = simulate_observations(
        eph, times, lambda t: R0 + v_ecef * (t - T0), clock_fn,
        isb={"E": 12.5}, iono=(ALPHA, BETA), noise=pr_noise, rng=rng,
        doppler_noise=lambda el, cn0: np.sqrt(range_rate_variance(el, cn0, CFG)))
    prep = prepare_observations(obs, eph, CFG)
    s0 = spp(obs[obs.index == obs.index[0]], eph, ION, SppConfig(model=CFG)).solution.iloc[0]
    clk0 = ReceiverClock(h0=clock.h0, h_m2=clock.h_m2, initial_bias=s0.clock_bias_G,
                         initial_drift=s0.clock_drift, bias_std=3 * s0.up_std, drift_std=0.2)
    pr = Pseudorange(prep, ION, config=CFG, clock=clk0,
                     isb_initial={"E": s0.clock_bias_E - s0.clock_bias_G}, isb_std=5.0)
    dp = Doppler(prep, ION, config=CFG, clock=clk0)
    layout = StateLayout(extras=pr.extra_states())
    p0 = np.full(layout.n, 1e-14)
    p0[0:3] = [s0.east_std**2, s0.north_std**2, s0.up_std**2]
    p0[3:6] = 0.2**2
    p0[15:] = [clk0.bias_std**2, 0.2**2, 25.0]
    params = np.zeros(layout.n - 9)
    params[6:] = [clk0.initial_bias, clk0.initial_drift, pr.isb_initial["E"]]
    vel0 = [s0.vel_e, s0.vel_n, s0.vel_u]
    f = _ClockEkf([pr, dp], layout, s0.lat, s0.lon, s0.height, vel0, p0, params)
    starts = np.r_[0, np.nonzero(np.diff(prep.index.to_numpy()))[0] + 1, len(prep)]
    t_prev = prep.index[0]
    nees, inside = [], []
    idx = np.r_[0:6, 15:layout.n]
    for k in range(starts.size - 1):
        t = prep.index[starts[k]]
        if t > t_prev:
            f.predict(t - t_prev)
        t_prev = t
        f.update(range(starts[k], starts[k + 1]))
        tr = truth[k]
        lat, lon, h = ecef_to_geodetic(*tr["r"])
        e, n, u = geodetic_to_enu(f.lat, f.lon, f.h, lat, lon, h)
        v_true = ecef_to_enu_matrix(lat, lon) @ v_ecef
        d_true = (clock_fn(tr["t"] + 0.05) - clock_fn(tr["t"] - 0.05)) / 0.1
        err = np.r_[e, n, u, f.vel - v_true,
                    f.params[6] - tr["b"], f.params[7] - d_true, f.params[8] - 12.5]
        P = f.P[np.ix_(idx, idx)]
        if k >= 5:
            nees.append(err @ np.linalg.solve(P, err))
            inside.append(np.abs(err) < 3 * np.sqrt(np.diag(P)))
    nees, inside = np.array(nees), np.array(inside)
    print(f"NEES mean {nees.mean():.2f} (dof {idx.size}), inside 3 sigma {inside.mean(axis=0).round(3)}")
    dof = idx.size
    assert inside.mean(axis=0).min() > 0.9
    # correlated NEES samples: the mean must be near the state dimension
    assert 0.6 * dof < nees.mean() < 1.5 * dof, nees.mean()
    # after 100 s the clock and position are well inside their error budget
    assert abs(err[6]) < 3 * np.sqrt(P[6, 6]) and np.hypot(err[0], err[1]) < 3.0
    assert f.rejected < 0.01 * 2 * len(prep)


# --- the models inside the filter engine ------------------------------------------------------
@pytest.fixture(scope="module")
def engine_run():
    """A simulated car (tactical IMU, 100 Hz, 90 s) with pseudoranges and Dopplers of the
    synthetic constellation at 1 Hz, a random-walk receiver clock and a Galileo ISB; satellite
    G07 gets an 80 m pseudorange fault for 20 s. Run through :func:`run_filter`."""
    from filter_sim import car_truth, corrupt_imu, initial_with_error

    from insgnss.filter import FilterConfig, run_filter
    from insgnss.imu import grade

    rng = np.random.default_rng(11)
    truth = car_truth(duration=90.0, rate=100.0)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    # GPS time of the constellation (after the IMU simulation, which needs exact steps)
    truth.index, imu.index = truth.index + T0, imu.index + T0
    clock = ReceiverClock(h0=2e-21, h_m2=2e-22)
    tt = truth.index.to_numpy(float)
    Phi, Qd = clock.transition(0.01), clock.process_noise(0.01)
    Lq = np.linalg.cholesky(Qd)
    xs = np.zeros((tt.size, 2))
    xs[0] = [-4.6e5, -70.0]
    for k in range(1, tt.size):
        xs[k] = Phi @ xs[k - 1] + Lq @ rng.standard_normal(2)
    ecef = np.column_stack(geodetic_to_ecef(truth["lat"].to_numpy(), truth["lon"].to_numpy(),
                                            truth["height"].to_numpy()))

    def r_fn(t):
        return np.array([np.interp(t, tt, ecef[:, j]) for j in range(3)])

    def clock_fn(t):
        return float(np.interp(t, tt, xs[:, 0]))

    eph = synthetic_constellation(T0)
    times = T0 + 1.0 + np.arange(88) * 1.0
    obs, sim = simulate_observations(
        eph, times, r_fn, clock_fn, isb={"E": 12.5}, iono=(ALPHA, BETA), noise=pr_noise,
        rng=rng, doppler_noise=lambda el, cn0: np.sqrt(range_rate_variance(el, cn0, CFG)))
    fault = (obs["sat"] == "G07") & (obs.index >= T0 + 40.0) & (obs.index < T0 + 60.0)
    obs.loc[fault, "pr"] += 80.0
    prep = prepare_observations(obs, eph, CFG)
    s0 = spp(obs[obs.index == obs.index[0]], eph, ION, SppConfig(model=CFG)).solution.iloc[0]
    s0 = s0.to_frame().T.set_axis([float(obs.index[0])])
    clk0 = ReceiverClock.from_spp(s0, float(imu.index[0]), h0=clock.h0, h_m2=clock.h_m2,
                                  bias_std=10.0, drift_std=0.5)
    s0 = s0.iloc[0]
    models = [Pseudorange(prep, ION, config=CFG, clock=clk0, isb_std=10.0,
                          isb_initial={"E": s0.clock_bias_E - s0.clock_bias_G}),
              Doppler(prep, ION, config=CFG, clock=clk0)]
    initial = initial_with_error(truth, np.r_[1.0, -1.0, 2.0, 0.05, -0.05, 0.02,
                                              np.radians([0.1, -0.1, 0.5])])
    cfg = FilterConfig(imu_model="tactical", initial_pos_std=3.0, initial_vel_std=0.2,
                       smoother=False)
    res = run_filter(imu, initial, models, cfg)
    return truth, res, sim, xs, fault.sum()


def test_tight_filter_in_the_engine_is_consistent(engine_run):
    """Clock bias, ISB and position from the engine inside 3 sigma; NEES of the position and
    clock bias near its dimension at the update epochs."""
    from filter_sim import nav_errors

    truth, res, sim, xs, _ = engine_run
    assert res.complete
    fw = res.forward
    assert "clock_bias" in fw.columns and "isb_E_std" in fw.columns
    t_upd = np.array([s["t_tag"] for s in sim])[10:]
    rows = fw.index.to_numpy(float)
    k = np.searchsorted(rows, t_upd)
    k = np.clip(k, 0, rows.size - 1)
    at = fw.iloc[k]
    err = nav_errors(fw, truth).reindex(at.index)
    b_true = np.array([s["b"] for s in sim])[10:]
    e_clk = at["clock_bias"].to_numpy() - b_true
    e_isb = at["isb_E"].to_numpy() - 12.5
    s_pos = at[["east_std", "north_std", "up_std"]].to_numpy()
    e_pos = err[["east", "north", "up"]].to_numpy()
    z = np.column_stack([e_pos / s_pos, e_clk / at["clock_bias_std"].to_numpy(),
                         e_isb / at["isb_E_std"].to_numpy()])
    assert np.isfinite(z).all()
    inside = (np.abs(z) < 3.0).mean(axis=0)
    print("inside 3 sigma", inside.round(3), "mean z^2", (z**2).mean(axis=0).round(2))
    assert inside.min() > 0.9
    # position, clock bias and ISB are correlated (a common-mode error): check each's z^2
    assert np.all((z**2).mean(axis=0) < 3.0) and np.all((z**2).mean(axis=0) > 0.1)
    assert np.hypot(e_pos[:, 0], e_pos[:, 1]).max() < 3.0
    # the estimated clock drift follows the truth's (finite difference of the sample path)
    d_true = np.gradient(xs[:, 0], truth.index.to_numpy(float))
    d_err = at["clock_drift"].to_numpy() - np.interp(t_upd, truth.index.to_numpy(float), d_true)
    assert np.sqrt(np.mean(d_err**2)) < 0.1


def test_engine_logs_and_gates_each_satellite(engine_run):
    """Every pseudorange/Doppler row is logged with its satellite; the faulty satellite is
    rejected on its own (never forced through by the gate recovery, since the other
    satellites were accepted) and the others keep being applied."""
    _, res, _, _, n_fault = engine_run
    inn = res.innovations
    pr = inn[inn["type"] == "pseudorange"]
    assert set(pr["label"]) >= {"G07", "E08"} and (pr["label"] != "").all()
    assert (inn.loc[inn["type"] == "doppler", "label"] != "").all()
    bad = pr[(pr["label"] == "G07") & (pr["time"] >= T0 + 40.0) & (pr["time"] < T0 + 60.0)]
    assert len(bad) == n_fault and n_fault > 15
    assert not bad["accepted"].any() and not bad["recovered"].any()
    others = pr[(pr["label"] != "G07") & (pr["time"] >= T0 + 40.0) & (pr["time"] < T0 + 60.0)]
    assert others["accepted"].mean() > 0.98
    assert set(res.rejected["label"]) >= {"G07"}
