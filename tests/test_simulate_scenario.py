"""Scenario files: loading, validation, reproducibility, writing and reading back."""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from insgnss.cli import main
from insgnss.errors import ConfigError
from insgnss.imu import GRADES
from insgnss.io.native import read_table
from insgnss.mechanization.strapdown import NAV_COLS, NavState, mechanize
from insgnss.simulate.scenario import datasheet_keys, simulate_scenario


def _is_simulation(path: Path) -> bool:
    """scenarios/ also holds processing jobs of real data; simulations have these tables."""
    cfg = tomllib.loads(path.read_text())
    return "scenario" in cfg and "trajectory" in cfg


SCENARIOS = sorted(p for p in (Path(__file__).resolve().parents[1] / "scenarios").glob("*.toml")
                   if _is_simulation(p))
NAMES = [p.stem for p in SCENARIOS]

SMALL = {
    "scenario": {"name": "small", "seed": 5, "imu_rate": 50.0},
    "trajectory": {"lat": 45.0, "lon": 7.0, "height": 100.0, "heading": 30.0,
                   "segments": [{"type": "static", "duration": 10.0},
                                {"type": "accelerate", "speed": 10.0, "acceleration": 2.0},
                                {"type": "turn", "angle": 90.0, "rate": 10.0},
                                {"type": "hold", "duration": 20.0}]},
    "imu": {"grade": "tactical", "gyro_arw_deg_sqrt_h": 0.2},
    "gnss": {"rate": 1.0, "velocity": True, "lever_arm": [0.0, 1.0, 1.0]},
    "odometer": {"rate": 10.0, "scale_factor_std": 0.01},
    "magnetometer": {"rate": 5.0, "noise_std": 2.0, "declination_error": 1.0},
    "process": {"anything": "belongs to the processing job"},
    "evaluation": {"whatever": [1, 2, 3]},
}


def test_the_five_scenarios_exist():
    for name in ("car_town_mems", "car_highway_tactical_outages", "static_navigation_1h",
                 "foot_walk", "land_vehicle_odometer"):
        assert name in NAMES


@pytest.mark.parametrize("path", SCENARIOS, ids=NAMES)
def test_scenario_simulates_in_full(path):
    cfg = tomllib.loads(path.read_text())
    r = simulate_scenario(path)
    T = r.truth
    assert list(T.columns[:9]) == NAV_COLS and np.all(np.isfinite(T.to_numpy()))
    assert len(r.imu) == len(T) == len(r.imu_ideal)
    assert abs(1.0 / np.median(np.diff(T.index)) - cfg["scenario"]["imu_rate"]) < 1e-6
    assert r.metadata["seed"] == cfg["scenario"]["seed"]
    for table in ("gnss", "odometer", "magnetometer"):
        assert (getattr(r, table) is None) == (table not in cfg)
    if r.gnss is not None:
        assert len(r.gnss) > 10
    # the heading of the file (degrees) is the heading of the truth (radians)
    assert abs(np.degrees(T["heading"].iloc[0]) - cfg["trajectory"]["heading"] % 360) < 1e-9
    if "static" in path.stem:
        assert np.all(T[["vel_e", "vel_n", "vel_u"]].to_numpy() == 0)
    if "foot" in path.stem:
        st = T["stationary"].to_numpy() > 0.5
        assert np.all(T[["vel_e", "vel_n", "vel_u"]].to_numpy()[st] == 0) and 0.5 < st.mean() < 0.9


@pytest.mark.parametrize("path", SCENARIOS, ids=NAMES)
def test_cli_writes_tables_that_read_back(path, tmp_path, capsys):
    out = tmp_path / path.stem
    assert main(["simulate", str(path), "-o", str(out), "--duration", "40"]) == 0
    assert "simulated in" in capsys.readouterr().out
    ref = simulate_scenario(path, duration=40.0)
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["seed"] == ref.seed and meta["scenario"]["name"] == path.stem
    assert meta["frames"]["body"] == "right-forward-up"
    for name, df in ref.tables().items():
        back = read_table(out / name)
        assert list(back.columns) == list(df.columns), name
        assert np.allclose(back.index.to_numpy(), df.index.to_numpy(), rtol=0, atol=1e-9)
        a, b = back.to_numpy(), df.to_numpy()
        assert np.allclose(a, b, rtol=1e-11, atol=1e-15), name
        assert name in meta["files"]
    # the IMU read back from disk mechanizes along the truth: the file keeps full precision
    if meta["imu"]["grade"] != "ideal":
        ideal = ref.imu_ideal
        truth = read_table(out / "truth.csv")
        r0 = truth.iloc[0]
        init = NavState.from_euler(r0.lat, r0.lon, r0.height, [r0.vel_e, r0.vel_n, r0.vel_u],
                                   r0.roll, r0.pitch, r0.heading)
        nav = mechanize(ideal, init)
        assert np.abs(nav["vel_n"].to_numpy() - truth["vel_n"].to_numpy()).max() < 1e-6


def test_reproducible_and_seed_override():
    a = simulate_scenario(SMALL)
    b = simulate_scenario(copy.deepcopy(SMALL))
    c = simulate_scenario(SMALL, seed=6)
    for name in ("imu", "gnss", "odometer", "magnetometer"):
        assert getattr(a, name).equals(getattr(b, name))
        assert not getattr(a, name).equals(getattr(c, name))
    assert a.truth.equals(c.truth)  # the truth is deterministic
    assert c.metadata["seed"] == 6 and c.metadata["config"]["scenario"]["seed"] == 6
    # no seed anywhere: one is drawn and recorded, and it reproduces the run
    cfg = copy.deepcopy(SMALL)
    del cfg["scenario"]["seed"]
    d = simulate_scenario(cfg)
    e = simulate_scenario(cfg, seed=d.seed)
    assert d.imu.equals(e.imu)
    # changing the GNSS settings does not change the IMU errors
    cfg = copy.deepcopy(SMALL)
    cfg["gnss"]["horizontal_std"] = 5.0
    f = simulate_scenario(cfg)
    assert f.imu.equals(a.imu) and not f.gnss.equals(a.gnss)


def test_metadata_records_drawn_parameters():
    r = simulate_scenario(SMALL)
    m = r.metadata
    assert m["imu"]["grade"] == "tactical"
    # the datasheet override is converted once, in ImuErrorModel.from_datasheet
    assert abs(m["imu"]["model_si"]["gyro_arw"] - 0.2 * np.pi / 180 / 60) < 1e-15
    assert r.imu_model.gyro_arw == m["imu"]["model_si"]["gyro_arw"]
    assert m["imu"]["model_si"]["accel_vrw"] == GRADES["tactical"].accel_vrw
    drawn = np.array(m["imu"]["drawn"]["gyro_bias_turn_on"])
    assert np.allclose(r.imu_bias[["gyro_bias_x", "gyro_bias_y", "gyro_bias_z"]].iloc[0], drawn,
                       atol=5 * GRADES["tactical"].gyro_bias_instability)
    sf = m["odometer"]["drawn"]["scale_factor"]
    assert sf != 0.0 and abs(sf) < 0.05
    assert m["magnetometer"]["declination_error"] == pytest.approx(1.0)
    assert m["initial_state"]["heading_deg"] == pytest.approx(30.0)
    json.dumps(m)  # JSON-ready (numpy converted at write time)


def test_datasheet_keys_cover_from_datasheet():
    keys = datasheet_keys()
    assert keys["gyro_arw_deg_sqrt_h"][0] == "gyro_arw"
    assert keys["accel_bias_mg"] == ("accel_bias", pytest.approx(9.80665e-3))
    assert "gyro_quantization_urad" in keys and "bias_correlation_time_s" in keys


@pytest.mark.parametrize("table,key", [("gnss", "horizontal_sd"), ("imu", "gyro_arw"),
                                       ("odometer", "scale"), ("magnetometer", "bias"),
                                       ("scenario", "rate"), ("trajectory", "altitude")])
def test_unknown_keys_are_config_errors(table, key):
    cfg = copy.deepcopy(SMALL)
    cfg[table][key] = 1.0
    with pytest.raises(ConfigError, match=f"{table}.{key}"):
        simulate_scenario(cfg)


def test_bad_values_name_the_key(tmp_path):
    cfg = copy.deepcopy(SMALL)
    cfg["gnss"]["rate"] = "fast"
    with pytest.raises(ConfigError, match="gnss.rate"):
        simulate_scenario(cfg)
    cfg = copy.deepcopy(SMALL)
    cfg["trajectory"]["segments"][2]["angel"] = 3.0
    with pytest.raises(ConfigError, match=r"segments\[2\]\.angel"):
        simulate_scenario(cfg)
    cfg = copy.deepcopy(SMALL)
    cfg["imu"]["grade"] = "military"
    with pytest.raises(ConfigError, match="imu.grade"):
        simulate_scenario(cfg)
    cfg = copy.deepcopy(SMALL)
    cfg["gnss"]["periodic_outages"] = {"start": 10.0, "length": 5.0}
    with pytest.raises(ConfigError, match="periodic_outages.gap"):
        simulate_scenario(cfg)
    cfg = copy.deepcopy(SMALL)
    del cfg["scenario"]["imu_rate"]
    with pytest.raises(ConfigError, match="imu_rate"):
        simulate_scenario(cfg)
    # errors from a file name the file
    bad = tmp_path / "bad.toml"
    bad.write_text('[scenario]\nimu_rate = 100\n[trajectory]\nlat = 1\nlon = 2\n'
                   'segments = [{type = "static", duration = 1, speed = 3}]\n')
    with pytest.raises(ConfigError, match="bad.toml") as exc:
        simulate_scenario(bad)
    assert "speed" in str(exc.value)
    assert main(["simulate", str(bad), "-o", str(tmp_path / "x")]) == 2
    broken = tmp_path / "broken.toml"
    broken.write_text("[scenario\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        simulate_scenario(broken)


def test_ideal_imu_without_imu_table():
    cfg = copy.deepcopy(SMALL)
    del cfg["imu"]
    r = simulate_scenario(cfg)
    assert r.imu.equals(r.imu_ideal) and r.imu_bias is None and r.imu_model is None
    assert r.metadata["imu"]["grade"] == "ideal"
