"""Drift comparison: helpers, a simulated car with stops, the foot-mounted comparison, the CLI."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from insgnss.align import coarse_align
from insgnss.cli import main as cli_main
from insgnss.compare import (
    CompareSettings,
    align_yaw,
    compare_foot_runs,
    compare_runs,
    control_points_at_stops,
    cupt_times_from_positions,
    growth_exponent,
    plot_drift,
    plot_errors,
    still_intervals,
    still_update_times,
)
from insgnss.detect import DetectorConfig, detect_stillness
from insgnss.filter.engine import FilterConfig
from insgnss.imu import grade
from insgnss.io.native import write_table
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NavState
from insgnss.simulate.sensors import simulate_imu
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0
LAT, LON, H = 45.0 * D, 7.0 * D, 250.0


# --- helpers -----------------------------------------------------------------------------------
@pytest.mark.parametrize("p", [1.0, 2.0, 2.7, 3.0])
def test_growth_exponent_of_power_laws(p):
    t = np.linspace(0.01, 400.0, 4000)
    b, a = growth_exponent(t, 0.02 * t**p, (10.0, 300.0))
    assert b == pytest.approx(p, abs=1e-4)  # linear interpolation between samples
    assert a == pytest.approx(np.log10(0.02), abs=1e-3)
    assert np.isnan(growth_exponent(t[:5], t[:5], (10, 300))[0])


def test_align_yaw_undoes_shift_and_rotation():
    rng = np.random.default_rng(2)
    g = np.cumsum(rng.normal(0, 0.3, (200, 2)), axis=0) + [5.0, -3.0]
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    est = (g - g[0]) @ R.T + [100.0, 20.0]
    np.testing.assert_allclose(align_yaw(est, g), g - g[0], atol=1e-10)


def test_still_helpers():
    t = np.arange(0.0, 3.0, 0.01)
    still = (t < 1.0) | ((t >= 2.0) & (t < 2.5))
    assert still_intervals(t, still) == [(0, 100), (200, 250)]
    ts = still_update_times(t, still, 0.1)
    assert ts.size == 15 and ts[0] == 0.0 and np.all(np.diff(ts[:10]) == pytest.approx(0.1))


# --- a simulated car with stops ------------------------------------------------------------------
def _car(imu_grade="tactical", seed=3):
    segs = [{"type": "static", "duration": 30.0}]
    for k in range(4):
        segs += [{"type": "accelerate", "speed": 12.0, "acceleration": 1.5},
                 {"type": "hold", "duration": 25.0},
                 {"type": "turn", "angle": (90 if k % 2 == 0 else -60) * D, "rate": 10 * D},
                 {"type": "hold", "duration": 15.0},
                 {"type": "decelerate", "speed": 0.0, "acceleration": 2.0},
                 {"type": "static", "duration": 20.0}]
    tr = generate(rate=100.0, lat=LAT, lon=LON, height=H, heading=20 * D, segments=segs)
    truth = tr.truth
    imu = simulate_imu(inverse_mechanize(truth), grade(imu_grade), rng=seed).imu.copy()
    # road vibration while moving (a simulated IMU has none; a stop detector relies on it)
    rng = np.random.default_rng(seed + 100)
    moving = ~tr.stationary
    dt = 0.01
    for c, s in [("dv_x", 0.1), ("dv_y", 0.1), ("dv_z", 0.2), ("dtheta_x", 0.2 * D),
                 ("dtheta_y", 0.2 * D), ("dtheta_z", 0.1 * D)]:
        imu.loc[moving, c] += rng.normal(0, s * dt, moving.sum())
    model = grade(imu_grade).scaled(accel_vrw=0.012, gyro_arw=3e-4)  # vibration in the model
    al = coarse_align(imu.loc[:29.0], LAT, H, model=grade(imu_grade), heading=20 * D,
                      heading_source="given")
    # start at the end of the static alignment window, just before the car moves
    imu = imu.loc[29.0:]
    r = truth.loc[imu.index[0]]
    init = NavState(r.lat, r.lon, r.height, np.zeros(3), al.C, float(imu.index[0]))
    return truth.loc[imu.index[0]:], imu, init, model


@pytest.fixture(scope="module")
def car():
    truth, imu, init, model = _car()
    still = detect_stillness(imu, DetectorConfig(method="amv", window=0.5, threshold=0.05,
                                                 min_stance=1.0, margin=0.3))
    cp = control_points_at_stops(truth)
    res = compare_runs(imu, init, truth, still=still, control_points=cp,
                       config=FilterConfig(imu_model=model, smoother=False))
    return truth, imu, init, model, still, cp, res


def test_car_detector_finds_the_stops(car):
    truth, imu, init, model, still, cp, res = car
    st_true = truth["stationary"].to_numpy() > 0.5
    assert np.mean(still.still.to_numpy() == st_true) > 0.98
    assert not np.any(still.still.to_numpy() & ~st_true)  # never still while moving
    assert len(cp) == 4  # one surveyed point per stop


def test_car_drift_comparison(car):
    truth, imu, init, model, still, cp, res = car
    tab = res.table
    assert list(tab.index) == ["free", "zupt", "zupt_zaru", "zupt_cupt"]
    for col in ("final_h_err_m", "rms_h_err_m"):
        assert tab.loc["free", col] > tab.loc["zupt", col] > tab.loc["zupt_cupt", col], col
    assert tab.loc["free", "final_h_err_m"] > 10 * tab.loc["zupt", "final_h_err_m"]
    assert tab.loc["zupt_cupt", "final_h_err_m"] < 0.2  # last update is a CUPT (2 cm points)
    # velocity error while stopped (after the first updates of each stop)
    for run in ("zupt", "zupt_zaru", "zupt_cupt"):
        assert tab.loc[run, "max_stop_vel_err_m_s"] < 0.01, run
    assert tab.loc["free", "max_stop_vel_err_m_s"] > 1.0
    # free-inertial error growth: between t^2 (accelerometer bias, tilt) and t^3 (gyro bias)
    assert 2.0 <= tab.loc["free", "growth_exponent"] <= 3.5
    assert res.cupt_times.size == 4
    # every run of the comparison starts from the same state
    for sol in res.solutions.values():
        assert sol.index[0] == init.time


def test_position_triggered_cupt_matches_time_triggered(car):
    truth, imu, init, model, still, cp, res = car
    st = still.still.to_numpy()
    found = cupt_times_from_positions(res.solutions["zupt"], st, cp.reset_index(drop=True),
                                      radius=100.0)
    assert len(found) == len(cp)
    # the update lands inside the same stop as the surveyed point's time
    for t_found, t_cp in zip(found.index, cp.index, strict=True):
        assert abs(t_found - t_cp) < 10.0
    far = cupt_times_from_positions(res.solutions["zupt"], st, cp.reset_index(drop=True),
                                    radius=1e-3)
    assert len(far) == 0


def test_figures_are_written(car, tmp_path):
    res = car[-1]
    p1 = plot_drift(res, tmp_path / "d.png", title="car")
    p2 = plot_errors(res, tmp_path / "e.png")
    assert p1.stat().st_size > 10_000 and p2.stat().st_size > 10_000


# --- foot-mounted -------------------------------------------------------------------------------
def _walk_folder(tmp_path):
    segs = [{"type": "stand", "duration": 2.0}, {"type": "walk", "steps": 25, "turn": 120 * D},
            {"type": "stand", "duration": 1.0}]
    tr = generate(rate=200.0, lat=LAT, lon=LON, height=H, vehicle="pedestrian", segments=segs)
    imu = simulate_imu(inverse_mechanize(tr.truth), grade("consumer"), rng=4).imu
    d = tmp_path / "walk"
    write_table(imu, d / "imu.csv")
    write_table(tr.truth, d / "truth.csv")
    return d, imu, tr.truth


def test_foot_comparison_on_a_simulated_walk(tmp_path):
    d, imu, truth = _walk_folder(tmp_path)
    res = compare_foot_runs(imu, truth, lat=LAT, lon=LON, height=H)
    tab = res.table
    assert tab.loc["free", "final_h_err_m"] > 20 * tab.loc["zupt", "final_h_err_m"]
    assert tab.loc["zupt_zaru", "final_h_err_m"] < 1.0
    assert tab.loc["zupt_zaru", "max_stop_vel_err_m_s"] < 0.05
    assert res.still.mean() > 0.4


def test_cli_compare_foot_folder(tmp_path, capsys):
    d, _, _ = _walk_folder(tmp_path)
    out = tmp_path / "out"
    assert cli_main(["compare", str(d), "-o", str(out), "--only", "free,zupt_zaru"]) == 0
    table = pd.read_csv(out / "compare_table.csv", index_col=0)
    assert list(table.index) == ["free", "zupt_zaru"]
    assert list(table["rejected"]) == [0, 0]  # the foot INS has no gate
    # the old spelling still works, with a deprecation warning (montecarlo --runs is a count)
    with pytest.warns(FutureWarning, match="--only"):
        assert cli_main(["compare", str(d), "-o", str(tmp_path / "old"), "--runs", "free",
                         "--no-figures"]) == 0
    assert list(pd.read_csv(tmp_path / "old" / "compare_table.csv", index_col=0).index) == [
        "free"]
    summary = json.loads((out / "compare_summary.json").read_text())
    assert summary["runs"] == ["free", "zupt_zaru"]
    assert (out / "drift_loglog.png").exists() and (out / "errors_vs_time.png").exists()
    assert "free" in capsys.readouterr().out


def test_cli_compare_simulated_job(tmp_path):
    job = tmp_path / "car.toml"
    job.write_text("""
[scenario]
name = "short_car"
seed = 5
imu_rate = 50.0

[trajectory]
vehicle = "land"
lat = 45.0
lon = 7.0
height = 200.0
heading = 10.0
segments = [
  { type = "static", duration = 30.0 },
  { type = "accelerate", speed = 8.0, acceleration = 1.5 },
  { type = "hold", duration = 10.0 },
  { type = "decelerate", speed = 0.0, acceleration = 1.5 },
  { type = "static", duration = 15.0 },
]

[imu]
grade = "tactical"

[initialization]
method = "static"
static_duration = 25.0
heading_deg = 10.0
""")
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(job), "-o", str(out), "--no-figures"]) == 0
    table = pd.read_csv(out / "compare_table.csv", index_col=0)
    assert {"free", "zupt", "zupt_zaru", "zupt_cupt"} <= set(table.index)
    assert table.loc["zupt_cupt", "final_h_err_m"] < table.loc["free", "final_h_err_m"]


def test_settings_validation():
    from insgnss.errors import ConfigError

    with pytest.raises(ConfigError):
        CompareSettings(solution="best")
    with pytest.raises(ConfigError):
        CompareSettings(fit_window=(10.0, 5.0))


def test_cupt_is_not_gated_and_rejections_are_counted():
    """A consumer IMU reaches each surveyed point with a NIS of 60-80 (free-inertial drift
    between stops against a covariance that misses the unmodelled errors): with the filter's
    gate every control point was rejected and the "ZUPT+CUPT" row was ZUPT only. CUPT is not
    gated in the comparison (like ZUPT/ZARU), and the table shows the rejections per run."""
    truth, imu, init, model = _car("consumer")
    still = detect_stillness(imu, DetectorConfig(method="amv", window=0.5, threshold=0.05,
                                                 min_stance=1.0, margin=0.3))
    cp = control_points_at_stops(truth)
    cfg = FilterConfig(imu_model=model, smoother=False)
    res = compare_runs(imu, init, truth, still=still, control_points=cp,
                       runs=["zupt", "zupt_cupt"], config=cfg)
    inn = res.filter_results["zupt_cupt"].innovations
    cupt = inn[inn["type"] == "cupt"]
    assert len(cupt) == 4 and cupt["accepted"].all()
    from scipy.stats import chi2

    assert cupt["nis"].iloc[0] > chi2.ppf(0.9999, 3)  # the filter's gate would reject it
    tab = res.table
    assert list(tab["rejected"]) == [0, 0]
    # on the 2 cm points after the last update; ZUPT alone drifts tens of metres
    assert tab.loc["zupt_cupt", "final_h_err_m"] < 0.5
    assert tab.loc["zupt", "final_h_err_m"] > 20 * tab.loc["zupt_cupt", "final_h_err_m"]
    # gating them (gate_zupt) loses the points, and the table says so
    gated = compare_runs(imu, init, truth, still=still, control_points=cp,
                         runs=["zupt_cupt"], config=cfg, settings=CompareSettings(gate_zupt=True))
    row = gated.table.loc["zupt_cupt"]
    n_cupt = int(row["rejected_types"].split("cupt ")[1].split(",")[0])
    assert n_cupt >= 2 and row["rejected"] > n_cupt  # control points and stop updates
    assert row["rms_h_err_m"] > 1.5 * tab.loc["zupt_cupt", "rms_h_err_m"]
    from insgnss.compare import format_table

    text = format_table(gated.table)
    assert "rejected" in text.splitlines()[0] and "(cupt " in text
