"""Foot-mounted ZUPT/ZARU INS: compiled filter pieces, simulated walks, PyShoe Vicon trials."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from insgnss.attitude import euler_to_dcm, euler_to_dcm_nb, wrap_pi
from insgnss.detect import Stillness
from insgnss.earth import geodetic_to_enu
from insgnss.errors import AlignmentError, ConfigError
from insgnss.filter import gating
from insgnss.filter.highrate import (
    _first_order_propagation,
    _innovation_cov,
    _kalman_update,
    _propagate_short15,
)
from insgnss.filter.models import StateLayout, accumulate_short_term_dynamics, error_dynamics
from insgnss.foot import FootConfig, level, run_foot_ins
from insgnss.imu import grade
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.simulate.sensors import simulate_imu
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0
LAT, LON, H = 45.0 * D, 7.0 * D, 200.0
REPO = Path(__file__).resolve().parents[1]


# --- compiled pieces of the engine's high-rate path against dense linear algebra -------------
def test_first_order_covariance_propagation_matches_dense():
    """P <- (I + F dt) P (I + F dt)^T + Qd with the strapdown F of a moving, turning IMU."""
    rng = np.random.default_rng(0)
    L = rng.normal(size=(15, 15))
    P = L @ L.T
    C, dt = euler_to_dcm(0.3, -0.2, 1.0), 0.005
    F = error_dynamics(0.8, 120.0, [3.0, -1.0, 0.2], C, rng.normal(size=3) * 5,
                       rng.normal(size=3), StateLayout()) * dt
    Qd = np.diag(rng.uniform(1e-8, 1e-6, 15))
    Qd[3:6, 3:6] += 1e-7 * np.ones((3, 3))
    P2 = P.copy()
    F[12, 12] = -dt / 300.0  # a decaying (Gauss-Markov) parameter row
    mask = F != 0.0
    act = np.flatnonzero(mask.any(axis=1))
    f_ptr = np.concatenate([[0], np.cumsum(mask[act].sum(axis=1))])
    f_col = np.concatenate([np.flatnonzero(mask[r]) for r in act])
    q_row, q_col = np.nonzero(Qd)
    _first_order_propagation(P2, F, Qd, f_ptr, f_col, act, q_row, q_col, np.empty((15, 15)),
                             np.empty((15, 15)))
    Phi = np.eye(15) + F
    np.testing.assert_allclose(P2, Phi @ P @ Phi.T + Qd, rtol=0, atol=1e-12)
    # the block form of the short-term (pedestrian) model
    Fs = np.zeros((15, 15))
    accumulate_short_term_dynamics(Fs, dt, C, rng.normal(size=3) * 1e-3,
                                   rng.normal(size=3) * 0.05, -1, -1)
    P3 = P.copy()
    _propagate_short15(P3, Fs, Qd, np.empty((15, 15)))
    Phi = np.eye(15) + Fs
    np.testing.assert_allclose(P3, Phi @ P @ Phi.T + Qd, rtol=0, atol=1e-12)


@pytest.mark.parametrize("blocks", [[(3, 1.0)], [(9, -1.0)], [(3, 1.0), (9, -1.0)]])
def test_compiled_update_matches_dense_kalman(blocks):
    """ZUPT-like (+I at velocity), ZARU-like (-I at the gyro bias) and the two stacked."""
    rng = np.random.default_rng(1)
    L = rng.normal(size=(15, 15))
    P = L @ L.T
    m = 3 * len(blocks)
    H = np.zeros((m, 15))
    for k, (b, sign) in enumerate(blocks):
        H[3 * k:3 * k + 3, b:b + 3] = sign * np.eye(3)
    H[:, 6:9] += 0.01 * rng.normal(size=(m, 3))  # small attitude terms (ZARU's -C^T [w_ie x])
    z, R = rng.normal(size=m), 0.1 * np.eye(m)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    P2, x = P.copy(), np.empty(15)
    Kt, G, s = np.empty((m, 15)), np.empty((m, 15)), np.empty(m)
    HP, S2 = np.empty((m, 15)), np.empty((m, m))
    _innovation_cov(H, P, R, m, HP, S2)
    np.testing.assert_allclose(S2, S, atol=1e-12)
    work = [np.empty((m, m)), np.empty((m, 15)), np.empty((m, 15))]
    assert _kalman_update(P2, H, z, m, HP, S2, x, Kt, G, s, *work, True)
    np.testing.assert_allclose(Kt.T, K, atol=1e-12)
    np.testing.assert_allclose(x, K @ z, atol=1e-12)
    I_KH = np.eye(15) - K @ H
    np.testing.assert_allclose(P2, I_KH @ P @ I_KH.T + K @ R @ K.T, atol=1e-10)  # Joseph
    np.testing.assert_allclose(G, np.linalg.solve(S, H), atol=1e-12)
    np.testing.assert_allclose(s, np.linalg.solve(S, z), atol=1e-12)
    # a gate below the normalised innovation squared rejects the measurement
    nis = float(z @ np.linalg.solve(S, z))
    assert gating.nis(S, z) == pytest.approx(nis, rel=1e-12)
    streak = np.zeros((1, 3))
    assert gating.gate_step(streak, 0, 1.0, nis, 2.0 * nis, -1.0) == gating.ACCEPT
    assert gating.gate_step(streak, 0, 1.0, nis, 0.5 * nis, -1.0) == gating.REJECT


def test_levelling_recovers_roll_and_pitch():
    g = 9.81
    for roll, pitch in [(0.0, 0.0), (10 * D, -20 * D), (-35 * D, 15 * D), (120 * D, 30 * D)]:
        C = euler_to_dcm(roll, pitch, 1.234)
        f_b = C.T @ np.array([0.0, 0.0, g])
        r, p = level(f_b)
        assert r == pytest.approx(roll, abs=1e-12)
        assert p == pytest.approx(pitch, abs=1e-12)
        C2 = np.empty((3, 3))
        euler_to_dcm_nb(roll, pitch, 1.234, C2)
        np.testing.assert_allclose(C2, C, atol=1e-15)


# --- simulated walks ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def walk():
    segs = [{"type": "stand", "duration": 2.0},
            {"type": "walk", "steps": 20, "turn": 90 * D},
            {"type": "stand", "duration": 1.0},
            {"type": "walk", "steps": 20, "turn": -180 * D},
            {"type": "stand", "duration": 1.0}]
    tr = generate(rate=200.0, lat=LAT, lon=LON, height=H, heading=30 * D, vehicle="pedestrian",
                  segments=segs)
    ideal = inverse_mechanize(tr.truth)
    e, n, u = geodetic_to_enu(tr.truth.lat, tr.truth.lon, tr.truth.height, LAT, LON, H)
    return tr, ideal, np.column_stack([e, n, u])


def _errors(res, tr, enu):
    h = np.hypot(res.east - enu[:, 0], res.north - enu[:, 1]).to_numpy()
    st = tr.stationary
    v = res[["vel_e", "vel_n", "vel_u"]].to_numpy()[st]
    return h, np.abs(v).max()


def test_perfect_imu_walk_is_reproduced(walk):
    tr, ideal, enu = walk
    for still in (tr.stationary, None):  # declared stance, then the preset detector
        r = run_foot_ins(ideal, FootConfig(heading=30 * D), still=still, lat=LAT, lon=LON,
                         height=H)
        h, v = _errors(r.trajectory, tr, enu)
        assert h.max() < 1e-6 and v < 1e-9
    assert np.mean(r.stillness.still.to_numpy() == tr.stationary) > 0.98


@pytest.mark.parametrize("imu_grade,max_err,gain", [("tactical", 0.15, 0.8), ("consumer", 0.8, 0.8)])
def test_noisy_imu_walk_drift_and_stance_velocity(walk, imu_grade, max_err, gain):
    tr, ideal, enu = walk
    imu = simulate_imu(ideal, grade(imu_grade), rng=7).imu
    r = run_foot_ins(imu, FootConfig(heading=30 * D), lat=LAT, lon=LON, height=H)
    distance = 56.0
    hs, vs = _errors(r.trajectory, tr, enu)
    hf, vf = _errors(r.forward, tr, enu)
    assert hs.max() < max_err, hs.max()  # 0.3 % (tactical) / 1.4 % (consumer) of 56 m
    assert hs[-1] < max_err * distance / 56.0
    assert vf < 0.05 and vs < 0.01  # velocity error while the foot is flat
    # the smoother (MBF backward pass) uses the ZUPT that ends each swing: swing velocity and
    # tilt improve (position and heading are not observed by ZUPT/ZARU, so their accumulated
    # drift is not undone by smoothing)
    sw = ~tr.stationary
    tv = tr.truth[["vel_e", "vel_n", "vel_u"]].to_numpy()[sw]

    def vrms(tab):
        dv = tab[["vel_e", "vel_n", "vel_u"]].to_numpy()[sw] - tv
        return np.sqrt(np.mean(np.sum(dv**2, 1)))

    assert vrms(r.trajectory) < vrms(r.forward)

    def tilt_rms(tab):
        d = wrap_pi(tab[["roll", "pitch"]].to_numpy() - tr.truth[["roll", "pitch"]].to_numpy())
        return np.sqrt(np.mean(d**2))

    assert tilt_rms(r.trajectory) < gain * tilt_rms(r.forward)
    assert np.allclose(r.trajectory.iloc[-1].to_numpy(), r.forward.iloc[-1].to_numpy())
    assert r.n_updates > 0 and np.isfinite(r.std.to_numpy()).all()


def test_heading_is_unobservable_and_defaults_to_zero(walk):
    tr, ideal, enu = walk
    imu = simulate_imu(ideal, grade("tactical"), rng=3).imu
    r30 = run_foot_ins(imu, FootConfig(heading=30 * D), lat=LAT, lon=LON, height=H)
    r0 = run_foot_ins(imu, lat=LAT, lon=LON, height=H)  # heading 0: documented default
    assert r0.initial.euler[2] == pytest.approx(0.0, abs=1e-12)
    # the heading-0 trajectory is the heading-30 one rotated by -30 deg about the start:
    # the ZUPT/ZARU measurements do not depend on heading
    a = -30 * D  # clockwise-from-north heading -> the rotation of (east, north)
    e, n = r30.trajectory.east.to_numpy(), r30.trajectory.north.to_numpy()
    rot_e = np.cos(a) * e + np.sin(a) * n
    rot_n = -np.sin(a) * e + np.cos(a) * n
    d = np.hypot(r0.trajectory.east - rot_e, r0.trajectory.north - rot_n)
    assert d.max() < 0.01


def test_compiled_filter_agrees_with_engine():
    """The foot-mounted INS (the engine's compiled high-rate path, a smoother node at every IMU
    sample) and the engine's Python update path (filterpy, one Python epoch per update) with
    the same ``Zupt`` and ``Zaru`` models, on the same stance samples and matched noise
    models, give the same walk and the same gyro-bias estimate."""
    from insgnss.filter.engine import FilterConfig, run_filter
    from insgnss.filter.measurements import Zaru, Zupt
    from insgnss.imu import ImuErrorModel

    segs = [{"type": "stand", "duration": 2.0}, {"type": "walk", "steps": 10, "turn": 60 * D},
            {"type": "stand", "duration": 1.0}]
    tr = generate(rate=200.0, lat=LAT, lon=LON, height=H, heading=30 * D, vehicle="pedestrian",
                  segments=segs)
    m = grade("consumer").scaled(gyro_scale=0.0, accel_scale=0.0, gyro_misalignment=0.0,
                                 accel_misalignment=0.0, gyro_bias_instability=0.0,
                                 accel_bias_instability=0.0)
    imu = simulate_imu(inverse_mechanize(tr.truth), m, rng=1).imu
    st = tr.stationary
    cfg = FootConfig(heading=30 * D, zaru_max_rate=np.inf, sigma_zaru=0.01,
                     zupt_noise_exponent=0.0, accel_dyn_noise=0.0, accel_psd=0.01,
                     gyro_psd=1e-3, gyro_bias_rw=1e-7, accel_bias_rw=1e-7,
                     init_gyro_bias_std=m.gyro_bias, init_accel_bias_std=m.accel_bias,
                     init_att_std=1 * D, init_heading_std=0.1 * D, init_vel_std=0.01,
                     init_pos_std=1e-3)
    r = run_foot_ins(imu, cfg, still=st, lat=LAT, lon=LON, height=H)
    bg0 = r.biases.iloc[0].to_numpy()[:3]  # levelling-window gyro bias, given to both
    em = ImuErrorModel(gyro_bias=m.gyro_bias, accel_bias=m.accel_bias, gyro_arw=1e-3,
                       accel_vrw=0.01, gyro_rrw=1e-7, accel_rrw=1e-7)
    fc = FilterConfig(imu_model=em, bias_model="random_walk", propagation_interval=0.005,
                      gate_probability=None, initial_pos_std=1e-3, initial_vel_std=0.01,
                      initial_att_std=(1 * D, 1 * D, 0.1 * D), gyro_bias=tuple(bg0))
    ts = imu.index.to_numpy()[st][1:]
    eng = run_filter(imu, r.initial, [Zupt(ts, std=0.01), Zaru(ts, std=0.01, average=False)], fc)
    e, n, _ = geodetic_to_enu(tr.truth.lat, tr.truth.lon, tr.truth.height, LAT, LON, H)
    for a, b, tol in ((r.forward, eng.forward, 0.002), (r.trajectory, eng.smoothed, 0.006)):
        ea, na, _ = geodetic_to_enu(a.lat, a.lon, a.height, LAT, LON, H)
        eb, nb, _ = geodetic_to_enu(b.lat, b.lon, b.height, LAT, LON, H)
        assert np.hypot(ea - e, na - n).max() < 0.01
        assert np.hypot(eb - e, nb - n).max() < 0.01
        assert np.hypot(ea - eb, na - nb).max() < tol
    cols = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z"]
    np.testing.assert_allclose(r.biases[cols].iloc[-1], eng.forward[cols].iloc[-1], atol=1e-5)


def test_stillness_object_drives_soft_zupt(walk):
    tr, ideal, enu = walk
    imu = simulate_imu(ideal, grade("consumer"), rng=5).imu
    base = run_foot_ins(imu, lat=LAT, lon=LON, height=H)
    st = base.stillness
    again = run_foot_ins(imu, still=Stillness(st.still, st.statistic, st.threshold, "x"),
                         lat=LAT, lon=LON, height=H)
    np.testing.assert_allclose(again.trajectory.east, base.trajectory.east, atol=1e-9)
    hard = run_foot_ins(imu, still=st.still, lat=LAT, lon=LON, height=H)  # no statistic
    assert not np.allclose(hard.trajectory.east, base.trajectory.east, atol=1e-6)


def test_config_errors():
    with pytest.raises(ConfigError, match="unknown foot-mounted settings"):
        FootConfig.from_dict({"sigma_zup": 0.1})
    cfg = FootConfig.from_dict({"sigma_zupt": 0.02, "threshold_selection": "none",
                                "detector": {"method": "are", "threshold": 0.3}})
    assert cfg.detector.method == "are" and cfg.to_dict()["detector"]["threshold"] == 0.3
    with pytest.raises(ConfigError, match="threshold_selection"):
        FootConfig.from_dict({"detector": {"method": "are", "threshold": 0.3}})
    with pytest.raises(ConfigError, match="unknown stance-threshold selection"):
        FootConfig(threshold_selection="oracle")
    with pytest.raises(ConfigError, match="candidate grid"):
        FootConfig(selection_fixed=(9.0, 5.0, 0.25))
    with pytest.raises(ConfigError, match="candidate grid"):
        FootConfig(selection_relative=(0.0, 1.0))
    assert FootConfig.from_dict({"selection_fixed": [6, 8, 0.5]}).selection_fixed == (6, 8, 0.5)
    with pytest.raises(ConfigError):
        FootConfig(level_floor_std=0.0)
    with pytest.raises(ConfigError):
        FootConfig(stride_height_noise=-0.01)
    with pytest.raises(ConfigError, match="true or false"):
        FootConfig(level_floor="yes")
    with pytest.raises(ConfigError, match="finite number"):
        FootConfig(level_floor_max_step="5 cm")
    with pytest.raises(ConfigError, match="below level_floor_max_step"):
        FootConfig(level_floor=True, level_floor_std=0.05)
    with pytest.raises(ConfigError, match="fraction"):
        FootConfig(stride_height_noise=1.5)
    with pytest.raises(ConfigError):
        FootConfig(update_every=0)


def test_levelling_needs_samples():
    from insgnss.imu import rates_table
    imu = rates_table([0.0], [[0.0, 0.0, 0.0]], [[0.0, 0.0, 9.8]])
    with pytest.raises(AlignmentError):
        run_foot_ins(imu, FootConfig(level_window=0.1))


# --- the real PyShoe Vicon trials ------------------------------------------------------------
def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, str(path))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_pyshoe_converter_round_trip(pyshoe_dir, tmp_path):
    sys.path.insert(0, str(REPO / "scenarios" / "pyshoe"))
    try:
        convert = _load(REPO / "scenarios" / "pyshoe" / "convert.py", "pyshoe_convert")
    finally:
        sys.path.pop(0)
    mat = pyshoe_dir / "2017-11-22-11-27-30.mat"
    raw = convert.load_mat(mat)
    imu, truth = convert.to_insgnss(raw)
    # at rest the body (RFU) specific force points up: z is the largest, positive component
    f0 = imu[["accel_x", "accel_y", "accel_z"]].iloc[:100].mean().to_numpy()
    assert f0[2] > 9.0 and np.linalg.norm(f0) == pytest.approx(9.82, abs=0.05)
    # the Vicon height is kept (z up: the foot rises in the swings)
    np.testing.assert_array_equal(truth["z"].to_numpy(), raw["gt"][:, 2])
    imu_csv, truth_csv = convert.write_trial(mat, tmp_path / "trial")
    back = convert.write_mat(imu_csv, truth_csv, tmp_path / "back.mat")
    b = convert.load_mat(back)
    np.testing.assert_allclose(b["ts"], raw["ts"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(b["imu"], raw["imu"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b["gt"], raw["gt"], rtol=1e-12, atol=1e-12)
    xyz = convert.solution_xyz(pd.DataFrame({"east": [1.0, 2.0], "north": [3.0, 5.0],
                                             "up": [0.0, 1.0]}))
    np.testing.assert_array_equal(xyz.to_numpy(), [[0, 0, 0], [1, 2, 1]])


#: walking (x2), running and a slow-motion trial; with the one fixed preset
PYSHOE_SUBSET = {"2017-11-22-11-22-03": 0.06, "2017-11-22-11-35-59": 0.06,
                 "2017-11-27-11-24-07": 0.15, "2018-02-09-11-19-39": 0.08}


def test_pyshoe_trials_armse(pyshoe_dir):
    scorer_path = pyshoe_dir.parent.parent / "eval" / "pyshoe_armse.py"
    if not scorer_path.exists():
        pytest.skip(f"shared scorer {scorer_path} not present")
    sys.path.insert(0, str(REPO / "scenarios" / "pyshoe"))
    try:
        run = _load(REPO / "scenarios" / "pyshoe" / "run_pyshoe.py", "run_pyshoe")
    finally:
        sys.path.pop(0)
    sc = _load(scorer_path, "pyshoe_armse")
    cfg = FootConfig()
    errs = {}
    for trial, limit in PYSHOE_SUBSET.items():
        mat = pyshoe_dir / f"{trial}.mat"
        sol, res, n = run.run_trial(mat, cfg)
        assert len(sol) == n and res.stillness.fraction > 0.1
        errs[trial] = sc.armse_2d(sol[["x", "y", "z"]].to_numpy(), sc.sio.loadmat(mat)["gt"])
        assert errs[trial] < limit, (trial, errs[trial])
    assert np.mean(list(errs.values())) < 0.07


def test_foot_mounted_scenario_is_the_profile():
    """scenarios/foot_mounted.toml writes the defaults out: it must stay equal to them."""
    import tomllib
    from pathlib import Path

    doc = tomllib.loads((Path(__file__).resolve().parents[1] / "scenarios" /
                         "foot_mounted.toml").read_text())
    assert FootConfig.from_dict(doc["foot"]).to_dict() == FootConfig().to_dict()
