"""Vibration of a standing vehicle as process noise (insgnss.preprocess.vibration_noise), the
GNSS evidence of standing (insgnss.job.initialization.standing_intervals) and the single-run
position NEES of the evaluation (insgnss.job.evaluation.position_nees)."""

import numpy as np
import pandas as pd
import pytest

from insgnss.imu import ImuErrorModel, rates_table
from insgnss.job.evaluation import CHI2_3DOF_3SIGMA, position_nees
from insgnss.job.initialization import STATIC_GNSS_SPEED, standing_intervals
from insgnss.preprocess import vibration_density, vibration_noise

RATE = 100.0


def _still(seconds, gyro_std, accel_std, seed=1, extra=None):
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    w = rng.standard_normal((n, 3)) * gyro_std + [1e-4, -2e-4, 5e-5]  # + a constant bias
    f = rng.standard_normal((n, 3)) * accel_std + [0.0, 0.0, 9.81]
    if extra is not None:
        w, f = extra(t, w, f)
    return rates_table(t, w, f)


def test_density_of_white_noise_is_its_psd():
    # white rate noise of std s per sample at dt: N^2 = s^2 dt (AVAR(tau) = N^2 / tau)
    s_g, s_a = np.radians(0.2), 0.15
    qg, qa, edf = vibration_density(_still(120.0, s_g, s_a))
    assert edf == pytest.approx(3 * (3 * 11999 / 200 - 2 * 11998 / 12000), rel=1e-3)  # SP 1065
    assert qg == pytest.approx(s_g ** 2 / RATE, rel=0.12)
    assert qa == pytest.approx(s_a ** 2 / RATE, rel=0.12)


def test_density_of_a_bounded_oscillation_is_small():
    # a 30 Hz vibration of the same sample std integrates to a bounded angle: it drives no
    # random walk at the filter's time scale (the sample std would claim s^2 dt)
    s = np.radians(0.2) * np.sqrt(2.0)

    def shake(t, w, f):
        w = w.copy()
        w[:, 0] += s * np.sin(2 * np.pi * 30.0 * t)
        return w, f

    qg, _, _ = vibration_density(_still(120.0, 1e-6, 1e-4, extra=shake))
    assert qg < 0.01 * (np.radians(0.2) ** 2 / RATE) / 3.0


def test_rows_add_the_excess_over_the_model():
    s_g, s_a = np.radians(0.2), 0.15
    imu = _still(60.0, s_g, s_a)
    model = ImuErrorModel(gyro_arw=np.radians(0.1) / 60.0, accel_vrw=0.03 / 60.0)
    xn = vibration_noise(imu, [(10.0, 30.0)], model)
    qg, qa, _ = vibration_density(imu.loc[10.0:30.0])
    assert xn.index[0] > 10.0 and xn.index[-1] == pytest.approx(30.0)
    assert np.all(np.diff(xn.index) > 0)
    # the variances over the window sum to (N^2 - ARW^2) T
    assert np.sum(xn.att_std ** 2) == pytest.approx((qg - model.gyro_arw ** 2) * 20.0, rel=1e-9)
    assert np.sum(xn.vel_std ** 2) == pytest.approx((qa - model.accel_vrw ** 2) * 20.0, rel=1e-9)
    assert np.all(xn.pos_std == 0.0)
    # a window shorter than the minimum, or no excess over the model: nothing
    assert vibration_noise(imu, [(10.0, 12.0)], model) is None
    loud = ImuErrorModel(gyro_arw=10 * s_g / np.sqrt(RATE), accel_vrw=10 * s_a / np.sqrt(RATE))
    assert vibration_noise(imu, [(10.0, 30.0)], loud) is None


def test_an_imu_that_matches_its_model_adds_nothing():
    # the window's Allan estimate scatters about the model's density; only an excess the window
    # can show (chi-square at 99 %) counts as vibration: 20 s windows of white noise at exactly
    # the model's level add nothing on (nearly) every seed, 1.5x the level (in std) always adds
    s_g, s_a = np.radians(0.2), 0.15
    model = ImuErrorModel(gyro_arw=s_g / np.sqrt(RATE), accel_vrw=s_a / np.sqrt(RATE))
    added = [vibration_noise(_still(40.0, s_g, s_a, seed=k), [(10.0, 30.0)], model) is not None
             for k in range(40)]
    assert sum(added) <= 3
    assert all(vibration_noise(_still(40.0, 1.5 * s_g, 1.5 * s_a, seed=k), [(10.0, 30.0)],
                               model) is not None for k in range(10))


def test_standing_intervals_need_two_slow_epochs_outside_outages():
    t = np.arange(0.0, 20.0, 1.0)
    speed = np.where((t >= 5) & (t <= 12), 0.05, 10.0)
    speed[8] = 2 * STATIC_GNSS_SPEED  # one noisy epoch splits the stop
    g = pd.DataFrame({"vel_e": speed, "vel_n": 0.0 * t}, index=pd.Index(t, name="time"))
    assert standing_intervals(g, []) == [(5.0, 7.0), (9.0, 12.0)]
    # the epochs of an outage are not evidence (10 and 11 withheld: 9 and 12 are 3 s apart)
    assert standing_intervals(g, [(10.0, 12.0)]) == [(5.0, 7.0)]
    assert standing_intervals(g.drop(columns="vel_e"), []) == []


def test_position_nees_of_consistent_errors_is_three():
    rng = np.random.default_rng(7)
    n = 4000
    t = np.arange(n) * 0.25
    sd = np.column_stack([np.full(n, 2.0), np.linspace(0.5, 3.0, n), np.full(n, 4.0)])
    e = rng.standard_normal((n, 3)) * sd
    err = pd.DataFrame(np.column_stack([e, sd]), index=pd.Index(t, name="time"),
                       columns=["east", "north", "up", "east_std", "north_std", "up_std"])
    out = position_nees(err, [(100.0, 400.0)])
    assert out["nees_pos_n"] == n
    assert out["nees_pos_mean"] == pytest.approx(3.0, rel=0.06)
    assert out["nees_pos_outage_n"] == 1200
    assert out["nees_pos_outage_mean"] == pytest.approx(3.0, rel=0.1)
    assert out["nees_pos_within_3sigma_fraction"] == pytest.approx(0.9973, abs=0.004)
    # twice the error: four times the NEES
    big = position_nees(err.assign(east=2 * err.east, north=2 * err.north, up=2 * err.up), [])
    assert big["nees_pos_mean"] == pytest.approx(4 * out["nees_pos_mean"], rel=1e-9)
    assert big["nees_pos_within_3sigma_fraction"] < 0.9
    assert CHI2_3DOF_3SIGMA == pytest.approx(14.156, abs=1e-3)
    # a solution without stds: nothing
    assert position_nees(err[["east", "north", "up"]], []) == {}


def test_simulated_idle_vibration_is_measured_at_the_stops():
    # the tactical-MEMS car: 0.2 deg/s and 0.15 m/s^2 of white idle vibration per 100 Hz sample
    # at the start and the two stops with GNSS -> N = 0.02 deg/sqrt(s) and 0.015 m/s/sqrt(s),
    # far above the preset's 0.1 deg/sqrt(h) and 0.03 m/s/sqrt(h): per 1 s step, that std
    import tomllib
    import warnings
    from pathlib import Path

    from insgnss.config import load_job_dict
    from insgnss.pipeline import run_job

    path = Path(__file__).resolve().parents[1] / "scenarios" / "mc_car_tactical_mems.toml"
    data = tomllib.loads(path.read_text())
    data["filter"]["smoother"] = False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(load_job_dict(data, path), progress=False, seed=5)
    vib = res.summary["preprocessing"]["vibration_noise"]
    # (a GNSS speed epoch above 0.3 m/s, 1 % of them with 0.1 m/s noise, splits a stop)
    assert 3 <= vib["quiet_windows"] <= 6
    assert vib["max_att_std_deg_per_step"] == pytest.approx(0.02, rel=0.2)
    assert vib["max_vel_std_m_s_per_step"] == pytest.approx(0.015, rel=0.2)
    ev = res.summary["evaluation"]["forward"]
    assert ev["nees_pos_outage_n"] > 0 and ev["nees_pos_n"] > ev["nees_pos_outage_n"]
    assert 0.5 < ev["nees_pos_outage_mean"] < 10.0
