"""Allan deviation and noise-coefficient extraction."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.analysis.allan import (
    FLICKER_FACTOR,
    allan_analysis,
    allan_deviation_series,
    coefficients_table,
    extract_coefficients,
    tau_grid,
)
from insgnss.imu import DEG_PER_HOUR, GRADES, increments_table
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS
from insgnss.simulate.sensors import simulate_imu
from insgnss.simulate.trajectory import generate


def test_oadev_matches_the_definition():
    """allantools' overlapping estimator equals NIST SP 1065 eq. 11 computed directly."""
    rng = np.random.default_rng(0)
    rate = 10.0
    y = rng.normal(size=5000) + np.cumsum(rng.normal(size=5000)) * 0.01
    taus = np.array([0.1, 0.5, 2.0, 17.3, 100.0])
    t_used, ad = allan_deviation_series(y, rate, taus)
    x = np.concatenate([[0.0], np.cumsum(y - y.mean()) / rate])
    for tau, a in zip(t_used, ad, strict=True):
        m = int(round(tau * rate))
        d = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
        assert abs(np.sqrt(np.mean(d**2) / (2 * tau**2)) / a - 1) < 1e-12


def test_extraction_on_analytic_curve():
    """sigma^2 = N^2/tau + (0.664 B)^2 + K^2 tau / 3: N, B and K come back exactly enough."""
    N, B, K = 1e-4, 2e-5, 3e-7
    # regions: white dominates below ~6 s, the floor from 57 s to 5900 s, RRW above ~5e4 s
    taus = np.logspace(-2, 5, 141)
    s = np.sqrt(N**2 / taus + (FLICKER_FACTOR * B) ** 2 + K**2 * taus / 3.0)
    c = extract_coefficients(taus, s, 1e7, min_clusters=8.0)
    assert abs(c["white"] / N - 1) < 0.02
    assert abs(c["bias_instability"] / B - 1) < 0.03
    assert abs(c["rrw"] / K - 1) < 0.05  # slope fit: the floor adds ~4 % at the +1/2 edge
    # minimum reading is biased high by the white and rate-random-walk terms
    assert c["bias_instability_min"] > B
    # white noise only: no floor, no RRW
    c = extract_coefficients(taus, N / np.sqrt(taus), 1e7)
    assert abs(c["white"] / N - 1) < 1e-9 and np.isnan(c["rrw"])
    assert tau_grid(1000, 10.0, 10, 0.25)[-1] == 25.0


@pytest.fixture(scope="module")
def tactical_6h():
    """6 h static at 20 Hz through the full pipeline (truth -> inverse mechanization -> errors).

    Tactical-grade preset with the bias instability generated as IEEE flicker noise (bank of
    Gauss-Markov processes, see insgnss.simulate.sensors), whose Allan floor 0.664 B is what the
    analysis recovers. The gyro bias instability is 5 deg/h (tactical MEMS, e.g. ADIS16488 class;
    Groves' tactical range for gyro bias is 1-100 deg/h) rather than the preset's 0.5 deg/h: with
    ARW 0.125 deg/sqrt(h) the floor then dominates from tau ~ (N / 0.664 B)^2 = 5 s, and 6 h
    give a per-axis scatter of ~2 % for B. With 0.5 deg/h it would dominate only beyond ~500 s,
    where 6 h hold too few clusters for a 10 % estimate per axis (~15 % scatter).
    """
    m = GRADES["tactical"].scaled(gyro_bias_instability=5.0 * DEG_PER_HOUR)
    tr = generate(rate=20.0, lat=np.radians(48.0), lon=np.radians(11.0), height=500.0,
                  heading=np.radians(20.0), segments=[{"type": "static", "duration": 6 * 3600.0}])
    ideal = inverse_mechanize(tr.truth[NAV_COLS])
    sim = simulate_imu(ideal, m, 2024, bias_instability="flicker")
    return m, sim


def test_allan_recovers_tactical_parameters_within_10_percent(tactical_6h):
    m, sim = tactical_6h
    res = allan_analysis(sim.imu)
    c = res.coefficients
    assert abs(res.duration - 6 * 3600) < 1e-6 and abs(res.rate - 20.0) < 1e-9
    white = c["white"].to_numpy() / np.array([m.gyro_arw] * 3 + [m.accel_vrw] * 3)
    bi = c["bias_instability"].to_numpy() / np.array(
        [m.gyro_bias_instability] * 3 + [m.accel_bias_instability] * 3)
    assert np.all(np.abs(white - 1) < 0.10), white
    assert np.all(np.abs(bi - 1) < 0.10), bi
    # much tighter in fact (documented expectations, not luck): ARW/VRW within 3 %, B within 7 %
    assert np.all(np.abs(white - 1) < 0.03) and np.all(np.abs(bi - 1) < 0.07)
    # no rate random walk was simulated; nothing with a clear +1/2 slope should be reported
    # large enough to matter (K at 3 s far below the floor)
    k = c["rrw"].to_numpy()
    floor = FLICKER_FACTOR * np.array([m.gyro_bias_instability] * 3 + [m.accel_bias_instability] * 3)
    assert np.all(np.isnan(k) | (k < floor))
    tab = coefficients_table(res)
    assert abs(tab.loc["gyro_x", "arw_vrw"] / 0.125 - 1) < 0.03
    assert tab.loc["gyro_x", "arw_vrw_unit"] == "deg/sqrt(h)"
    assert abs(tab.loc["accel_y", "bias_instability"] / 50.0 - 1) < 0.07
    assert tab.loc["accel_y", "bias_instability_unit"] == "ug"


def test_rate_random_walk_recovered():
    """White noise + rate random walk (2 h at 10 Hz): K at tau = 3 s within 15 %."""
    rng = np.random.default_rng(9)
    rate, n = 10.0, 72_000
    N, K = 1e-4, 1e-4
    dt = 1 / rate
    w = rng.normal(size=(n, 6)) * N / np.sqrt(dt) + np.cumsum(rng.normal(size=(n, 6)), 0) * K * np.sqrt(dt)
    t = np.arange(n) * dt
    imu = increments_table(t, w[:, :3] * dt, w[:, 3:] * dt)
    c = allan_analysis(imu).coefficients
    assert np.all(np.abs(c["white"] / N - 1) < 0.05)
    assert np.all(np.abs(c["rrw"] / K - 1) < 0.15)


def test_allan_rejects_irregular_sampling():
    t = np.cumsum(np.r_[0.0, np.full(100, 0.01), 0.05, np.full(100, 0.01)])
    imu = increments_table(t, np.zeros((t.size, 3)), np.zeros((t.size, 3)))
    with pytest.raises(ValueError, match="uniform"):
        allan_analysis(imu)


def test_allan_cli(tmp_path, capsys):
    from insgnss.cli import main
    from insgnss.io.native import write_table

    rng = np.random.default_rng(1)
    n, dt = 36_000, 0.01
    t = np.arange(n) * dt
    arw = 0.2 * np.pi / 180 / 60
    imu = increments_table(t, rng.normal(size=(n, 3)) * arw * np.sqrt(dt),
                           rng.normal(size=(n, 3)) * 0.05 / 60 * np.sqrt(dt))
    src = tmp_path / "static_imu.csv"
    write_table(imu, src)
    out = tmp_path / "allan"
    assert main(["allan", str(src), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "gyro_x" in text and "deg/sqrt(h)" in text
    assert (out / "static_imu_allan.png").stat().st_size > 10_000
    coef = pd.read_csv(out / "static_imu_allan_coefficients.csv", index_col=0)
    assert np.all(np.abs(coef.loc[["gyro_x", "gyro_y", "gyro_z"], "arw_vrw"] / 0.2 - 1) < 0.05)
    adev = pd.read_csv(out / "static_imu_allan.csv", index_col=0)
    assert list(adev.columns) == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    # a non-IMU table is a clear error, not a traceback
    bad = tmp_path / "bad.csv"
    write_table(pd.DataFrame({"speed": np.ones(5)}, index=pd.Index(np.arange(5.0), name="time")),
                bad)
    assert main(["allan", str(bad)]) == 2
    assert "gyro_x" in capsys.readouterr().err
