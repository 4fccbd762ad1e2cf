"""`insgnss mechanize` and `insgnss allan` read IMU files as a job file's [inputs.imu] does
(options or --job), mechanize takes an initial velocity and writes errors against a
reference."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from example_data import WRITERS, scenario_for

from insgnss.cli import main
from insgnss.io.native import read_table, write_table
from insgnss.simulate.scenario import simulate_scenario

COLUMNS = {"time": "t_ms", "gyro_x": "gx", "gyro_y": "gy", "gyro_z": "gz", "accel_x": "ax",
           "accel_y": "ay", "accel_z": "az"}
IMU = {"format": "csv", "path": "imu.csv", "gyro_unit": "deg/s", "accel_unit": "g",
       "time_unit": "ms", "axis_map": "y,x,-z", "columns": COLUMNS}
JOB_TOML = """
[inputs.imu]
format = "csv"
path = "imu.csv"
gyro_unit = "deg/s"
accel_unit = "g"
time_unit = "ms"
axis_map = "y,x,-z"

[inputs.imu.columns]
time = "t_ms"
gyro_x = "gx"
gyro_y = "gy"
gyro_z = "gz"
accel_x = "ax"
accel_y = "ay"
accel_z = "az"
"""


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A tactical-grade drive (25 s still, then moving) written as a CSV in deg/s, g, ms and
    FRD axes with custom column names, the job file that describes it, the truth."""
    d = tmp_path_factory.mktemp("cli_inputs")
    job = {"inputs": {"imu": dict(IMU)}, "initialization": {"static_duration": 20.0}}
    sim = simulate_scenario(scenario_for(job, seed=3))
    WRITERS[("imu", "csv")](sim.imu, sim.imu.index.to_numpy(float), IMU, d / "imu.csv")
    (d / "job.toml").write_text(JOB_TOML)
    write_table(sim.truth, d / "truth.csv")
    return d, sim


def _bias_h(sim) -> float:
    """Horizontal accelerometer bias [m/s^2] the simulation drew (level body)."""
    e = sim.sensor_errors().iloc[0]
    return float(np.hypot(e["accel_bias_x"], e["accel_bias_y"]))


def _start(sim, t):
    r = sim.truth.iloc[sim.truth.index.get_indexer([t], method="nearest")[0]]
    return r, ["--lat", f"{np.degrees(r.lat):.10f}", "--lon", f"{np.degrees(r.lon):.10f}",
               "--height", f"{r.height:.4f}"]


def test_mechanize_with_the_job_or_the_same_options(drive, capsys):
    d, sim = drive
    r, pos = _start(sim, 0.0)
    att = f"{np.degrees(r.roll):.6f},{np.degrees(r.pitch):.6f},{np.degrees(r.heading):.6f}"
    a = ["mechanize", "--job", str(d / "job.toml"), *pos, f"--attitude={att}",
         "-o", str(d / "a.csv"), "--reference", str(d / "truth.csv")]
    assert main(a) == 0
    text = capsys.readouterr().out
    assert "errors against truth.csv" in text
    cols = ",".join(f"{k}={v}" for k, v in COLUMNS.items())
    b = ["mechanize", str(d / "imu.csv"), "--format", "csv", "--columns", cols,
         "--gyro-unit", "deg/s", "--accel-unit", "g", "--time-unit", "ms",
         "--axis-map", "y,x,-z", *pos, f"--attitude={att}", "-o", str(d / "b.csv")]
    assert main(b) == 0
    ta, tb = read_table(d / "a.csv"), read_table(d / "b.csv")
    pd.testing.assert_frame_equal(ta, tb)  # the same reading of the file
    err = read_table(d / "a_errors.csv")
    assert {"east", "north", "up", "horizontal", "vel_e", "roll", "heading"} <= set(err.columns)
    # still for 25 s from the true state: the drift is that of the simulated accelerometer
    # bias, 0.5 |b_h| t^2 (gyro bias through tilt adds ~g b_g t^3 / 6, centimetres)
    assert err["horizontal"].loc[20.0] == pytest.approx(0.5 * _bias_h(sim) * 20.0 ** 2,
                                                        rel=0.25)
    assert np.abs(err["heading"].loc[:20.0]).max() < np.radians(0.01)


def test_mechanize_initial_velocity(drive, tmp_path):
    """Starting a mechanization while the vehicle moves: with the true velocity the error
    after 10 s stays below a metre; at rest (no --velocity) it is the distance travelled."""
    d, sim = drive
    t1 = 40.0  # moving at 10 m/s
    part = sim.imu.loc[t1:]
    WRITERS[("imu", "csv")](part, part.index.to_numpy(float), IMU, tmp_path / "moving.csv")
    r, pos = _start(sim, float(part.index[0]))
    att = f"{np.degrees(r.roll):.6f},{np.degrees(r.pitch):.6f},{np.degrees(r.heading):.6f}"
    base = ["mechanize", str(tmp_path / "moving.csv"), "--job", str(d / "job.toml"), *pos,
            f"--attitude={att}", "--reference", str(d / "truth.csv")]
    assert main([*base, f"--velocity={r.vel_e:.6f},{r.vel_n:.6f},{r.vel_u:.6f}",
                 "-o", str(tmp_path / "v.csv")]) == 0
    assert main([*base, "-o", str(tmp_path / "rest.csv")]) == 0
    ev = read_table(tmp_path / "v_errors.csv").loc[:t1 + 10.0]
    er = read_table(tmp_path / "rest_errors.csv").loc[:t1 + 10.0]
    speed = float(np.hypot(r.vel_e, r.vel_n))
    assert speed > 5.0
    assert ev["horizontal"].iloc[-1] < 1.5 * 0.5 * _bias_h(sim) * 10.0 ** 2 + 0.1
    assert er["horizontal"].iloc[-1] == pytest.approx(10.0 * speed, rel=0.2)
    assert main(["mechanize", str(tmp_path / "moving.csv"), *pos, "--align", "5",
                 "--velocity", "1,2,3", "-o", str(tmp_path / "x.csv")]) == 2


def test_allan_reads_like_a_job(drive, tmp_path, capsys):
    """The same static data as a native table and as the deg/s/g/ms/FRD CSV (via --job):
    the same noise coefficients."""
    d, sim = drive
    still = sim.imu.loc[:24.0]
    write_table(still, tmp_path / "native.csv")
    WRITERS[("imu", "csv")](still, still.index.to_numpy(float), IMU, tmp_path / "imu.csv")
    (tmp_path / "job.toml").write_text(JOB_TOML)
    assert main(["allan", str(tmp_path / "native.csv"), "-o", str(tmp_path / "n")]) == 0
    assert main(["allan", "--job", str(tmp_path / "job.toml"), "-o", str(tmp_path / "c")]) == 0
    n = pd.read_csv(tmp_path / "n" / "native_allan_coefficients.csv", index_col=0)
    c = pd.read_csv(tmp_path / "c" / "imu_allan_coefficients.csv", index_col=0)
    # gyro ARW / accel VRW in datasheet units agree (the CSV holds mean rates of the same
    # increments, written to 10 significant digits)
    np.testing.assert_allclose(c["arw_vrw"].to_numpy(float), n["arw_vrw"].to_numpy(float),
                               rtol=0.02)
    assert json.dumps(list(c.index)) == json.dumps(list(n.index))
