"""IMU error synthesis: deterministic relations, noise statistics, processes, reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from insgnss.imu import DTHETA_COLS, DV_COLS, GRADES, ImuErrorModel, compensate
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS
from insgnss.simulate.sensors import flicker_bank, gauss_markov, quantize, random_walk, simulate_imu
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0


@pytest.fixture(scope="module")
def ideal():
    segs = [{"type": "static", "duration": 5.0},
            {"type": "accelerate", "speed": 12.0, "acceleration": 2.0},
            {"type": "turn", "angle": 180 * D, "rate": 20 * D},
            {"type": "hold", "duration": 20.0}]
    tr = generate(rate=100.0, lat=0.8, lon=0.1, height=50.0, segments=segs, roll_gain=0.5 * D)
    return inverse_mechanize(tr.truth[NAV_COLS])


def arrays(tab):
    return tab[DTHETA_COLS].to_numpy(), tab[DV_COLS].to_numpy()


def test_zero_model_is_ideal(ideal):
    out = simulate_imu(ideal, ImuErrorModel(), 1)
    assert np.array_equal(out.imu.to_numpy(), ideal.to_numpy())
    assert np.all(out.bias.to_numpy() == 0.0)


def test_deterministic_errors_are_inverted_by_compensation(ideal):
    """Without noise, compensate((x - b dt)) recovers the ideal increments exactly."""
    m = GRADES["consumer"].scaled(gyro_arw=0.0, accel_vrw=0.0, gyro_bias_instability=0.0,
                                  accel_bias_instability=0.0)
    out = simulate_imu(ideal, m, 5)
    p = out.params
    dt = 0.01
    th, dv = arrays(out.imu)
    th0, dv0 = arrays(ideal)
    b = out.bias.to_numpy()
    assert np.allclose(b[:, :3], p["gyro_bias_turn_on"]) and np.allclose(b[:, 3:], p["accel_bias_turn_on"])
    rec_th = compensate(th - b[:, :3] * dt, 0.0, p["gyro_scale"], p["gyro_nonorth"])
    rec_dv = compensate(dv - b[:, 3:] * dt, 0.0, p["accel_scale"], p["accel_nonorth"])
    assert np.abs(rec_th - th0).max() < 1e-15 and np.abs(rec_dv - dv0).max() < 1e-13
    # drawn magnitudes are of the declared order and the non-orthogonality has a zero diagonal
    assert np.all(np.diag(p["gyro_nonorth"]) == 0) and np.any(p["gyro_nonorth"] != 0)
    assert np.all(np.abs(p["gyro_scale"]) < 5 * m.gyro_scale)
    assert np.all(np.abs(p["gyro_bias_turn_on"]) < 5 * m.gyro_bias)


def test_white_noise_density(ideal):
    """ARW / VRW: increment noise std = density * sqrt(dt)."""
    m = ImuErrorModel(gyro_arw=0.3 * D / 60, accel_vrw=0.1 / 60)
    out = simulate_imu(ideal, m, 2)
    e = out.imu.to_numpy() - ideal.to_numpy()
    n = e.shape[0]
    sd = e.std(axis=0)
    rel = 3.0 / np.sqrt(2 * n)  # 3-sigma of a sample std
    assert np.all(np.abs(sd[:3] / (m.gyro_arw * 0.1) - 1) < rel)
    assert np.all(np.abs(sd[3:] / (m.accel_vrw * 0.1) - 1) < rel)
    # white: lag-1 correlation ~ 0
    r1 = [np.corrcoef(e[1:, j], e[:-1, j])[0, 1] for j in range(6)]
    assert np.max(np.abs(r1)) < 4 / np.sqrt(n)


def test_gauss_markov_statistics():
    rng = np.random.default_rng(3)
    n, dt, sigma, tau = 400_000, 0.1, 2.0, 5.0
    x = gauss_markov(rng, n, dt, sigma, tau, size=2)
    assert np.all(np.abs(x.std(axis=0) / sigma - 1) < 0.03)
    phi = np.exp(-dt / tau)
    r1 = np.array([np.corrcoef(x[1:, j], x[:-1, j])[0, 1] for j in range(2)])
    assert np.all(np.abs(r1 - phi) < 2e-3)
    lag = int(tau / dt)  # autocorrelation exp(-1) at one correlation time
    rl = np.array([np.corrcoef(x[lag:, j], x[:-lag, j])[0, 1] for j in range(2)])
    assert np.all(np.abs(rl - np.exp(-1)) < 0.03)


def test_random_walk_growth():
    rng = np.random.default_rng(4)
    K, dt = 0.5, 0.01
    x = random_walk(rng, 1001, dt, K, size=2000)
    assert np.all(x[0] == 0)
    # var(x(T)) = K^2 T
    assert abs(x[-1].var() / (K**2 * 10.0) - 1) < 0.1


def test_flicker_bank_variance_per_process():
    """Each Gauss-Markov process of the bank has variance B^2 ln10 / (pi per_decade)."""
    rng = np.random.default_rng(5)
    x = flicker_bank(rng, 2_000, 0.01, 1.0, (0.02, 0.2), per_decade=3, size=1000)
    n_tau = 4  # ceil(3 * 1) + 1
    expected = n_tau * np.log(10) / (np.pi * 3)
    assert abs(x[-1].var() / expected - 1) < 0.15


def test_quantization_carries_residual():
    rng = np.random.default_rng(6)
    x = rng.normal(1e-4, 3e-5, size=(10_000, 3))
    q = 2e-5
    y = quantize(x, q)
    assert np.allclose(np.round(y / q), y / q, atol=1e-6)  # multiples of q
    # the accumulated sum never drifts by more than half a quantum
    assert np.abs(np.cumsum(y, 0) - np.cumsum(x, 0)).max() <= 0.5 * q + 1e-15
    assert np.abs(y - x).max() > 0.3 * q  # each sample is really quantized


def test_saturation_and_quantization_in_simulation(ideal):
    m = ImuErrorModel.from_datasheet(gyro_range_deg_s=10.0, accel_range_g=0.2,
                                     gyro_quantization_urad=5.0, accel_quantization_mm_s=0.5)
    out = simulate_imu(ideal, m, 1)
    th, dv = arrays(out.imu)
    assert np.abs(th).max() <= 10 * D * 0.01 + 5e-6
    assert np.abs(dv[:, :2]).max() <= 0.2 * 9.80665 * 0.01 + 5e-4
    th0, _ = arrays(ideal)
    assert np.abs(th0).max() > 10 * D * 0.01  # the turn really saturates the gyro
    assert np.allclose(th / 5e-6, np.round(th / 5e-6), atol=1e-6)


def test_g_sensitivity(ideal):
    m = ImuErrorModel.from_datasheet(gyro_g_sensitivity_deg_h_g=100.0)
    out = simulate_imu(ideal, m, 8)
    G = out.params["gyro_g_sensitivity"]
    th, _ = arrays(out.imu)
    th0, dv0 = arrays(ideal)
    assert np.allclose(th - th0, dv0 @ G.T, atol=1e-17)
    assert np.abs(G).max() > 1e-6


def test_reproducible_and_components_independent(ideal):
    m = GRADES["tactical"]
    a = simulate_imu(ideal, m, 42)
    b = simulate_imu(ideal, m, 42)
    c = simulate_imu(ideal, m, 43)
    assert np.array_equal(a.imu.to_numpy(), b.imu.to_numpy())
    assert not np.array_equal(a.imu.to_numpy(), c.imu.to_numpy())
    # adding rate random walk does not change the other components' draws
    d = simulate_imu(ideal, m.scaled(gyro_rrw=1e-7), 42)
    diff = d.imu.to_numpy() - a.imu.to_numpy()
    rrw_part = d.bias.to_numpy() - a.bias.to_numpy()
    assert np.allclose(diff[:, :3], rrw_part[:, :3] * 0.01, atol=1e-18)
    assert np.all(a.params["gyro_bias_turn_on"] == d.params["gyro_bias_turn_on"])


def test_rates_output(ideal):
    out = simulate_imu(ideal, GRADES["tactical"], 1, output="rates")
    inc = simulate_imu(ideal, GRADES["tactical"], 1)
    assert list(out.imu.columns[:3]) == ["gyro_x", "gyro_y", "gyro_z"]
    assert np.allclose(out.imu.to_numpy()[1:] * 0.01, inc.imu.to_numpy()[1:], rtol=1e-12,
                       atol=1e-18)
    with pytest.raises(ValueError):
        simulate_imu(ideal, GRADES["tactical"], 1, output="counts")
