"""Foot-mounted ZUPT/ZARU INS: compiled filter pieces, simulated walks, PyShoe Vicon trials."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from insgnss.attitude import euler_to_dcm, skew, wrap_pi
from insgnss.detect import Stillness
from insgnss.earth import geodetic_to_enu
from insgnss.errors import AlignmentError, ConfigError
from insgnss.foot import (
    FootConfig,
    _adjoint_back,
    _propagate_cov,
    _update_block,
    euler_to_dcm_into,
    level,
    run_foot_ins,
)
from insgnss.imu import grade
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.simulate.sensors import simulate_imu
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0
LAT, LON, H = 45.0 * D, 7.0 * D, 200.0
REPO = Path(__file__).resolve().parents[1]


# --- compiled pieces against dense linear algebra ---------------------------------------------
def _dense_phi(f, C, dt):
    F = np.zeros((15, 15))
    F[0:3, 3:6] = np.eye(3)
    F[3:6, 6:9] = -skew(f)
    F[3:6, 12:15] = -C
    F[6:9, 9:12] = -C
    return np.eye(15) + F * dt


def test_covariance_propagation_and_adjoint_match_dense():
    rng = np.random.default_rng(0)
    L = rng.normal(size=(15, 15))
    P = L @ L.T
    f, C, dt = rng.normal(size=3) * 5, euler_to_dcm(0.3, -0.2, 1.0), 0.01
    q = np.array([1.0, 2.0, 3.0, 4.0])
    Phi = _dense_phi(f, C, dt)
    Q = np.diag(np.r_[np.zeros(3), np.repeat(q, 3)]) * dt
    P2 = P.copy()
    _propagate_cov(P2, np.empty((15, 15)), f, C, dt, *q)
    np.testing.assert_allclose(P2, Phi @ P @ Phi.T + Q, rtol=0, atol=1e-12)
    lam = rng.normal(size=15)
    lam2 = lam.copy()
    _adjoint_back(lam2, f, C, dt)
    np.testing.assert_allclose(lam2, Phi.T @ lam, atol=1e-14)


@pytest.mark.parametrize("block,sign", [(3, 1.0), (9, -1.0)])
def test_block_update_matches_dense_kalman(block, sign):
    rng = np.random.default_rng(1)
    L = rng.normal(size=(15, 15))
    P = L @ L.T
    H = np.zeros((3, 15))
    H[:, block:block + 3] = sign * np.eye(3)
    z, r = rng.normal(size=3), 0.1
    S = H @ P @ H.T + r * np.eye(3)
    K = P @ H.T @ np.linalg.inv(S)
    P2, Kt, dx = P.copy(), np.empty((15, 3)), np.empty(15)
    ok = _update_block(P2, block, sign, z, r, Kt, np.empty((3, 3)), dx, np.empty((3, 3)),
                       np.empty((3, 15)), np.inf)
    assert ok
    np.testing.assert_allclose(Kt, K, atol=1e-12)
    np.testing.assert_allclose(dx, K @ z, atol=1e-12)
    np.testing.assert_allclose(P2, P - K @ H @ P, atol=1e-10)
    # a gate below the normalised innovation rejects the update and leaves P alone
    nis = float(z @ np.linalg.solve(S, z))
    P3 = P.copy()
    assert not _update_block(P3, block, sign, z, r, Kt, np.empty((3, 3)), dx, np.empty((3, 3)),
                             np.empty((3, 15)), 0.5 * nis)
    np.testing.assert_array_equal(P3, P)


def test_levelling_recovers_roll_and_pitch():
    g = 9.81
    for roll, pitch in [(0.0, 0.0), (10 * D, -20 * D), (-35 * D, 15 * D), (120 * D, 30 * D)]:
        C = euler_to_dcm(roll, pitch, 1.234)
        f_b = C.T @ np.array([0.0, 0.0, g])
        r, p = level(f_b)
        assert r == pytest.approx(roll, abs=1e-12)
        assert p == pytest.approx(pitch, abs=1e-12)
        C2 = np.empty((3, 3))
        euler_to_dcm_into(roll, pitch, 1.234, C2)
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
    """The compiled pedestrian filter and the general engine (filterpy, one Python epoch per
    update) with its ``Zupt`` and ``Zaru`` measurement models, on the same stance samples and
    matched noise models, give the same walk and the same gyro-bias estimate."""
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
    cfg = FootConfig.from_dict({"sigma_zupt": 0.02, "detector": {"method": "are",
                                                                 "threshold": 0.3}})
    assert cfg.detector.method == "are" and cfg.to_dict()["detector"]["threshold"] == 0.3
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
