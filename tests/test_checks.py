"""Sanity checks for the common set-up mistakes (insgnss.checks): each message names the likely
cause and the key that fixes it - an upside-down axis map, deg/s declared as rad/s, latitude
degrees in a radians column, a static window that reaches into motion."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pandas as pd
import pytest
from example_data import generate_for

from insgnss.checks import (
    GYRO_REST_MAX,
    check_gyro_at_rest,
    check_latitude_radians,
    check_upright,
    still_duration,
)
from insgnss.config import load_job_dict
from insgnss.earth import OMEGA_E
from insgnss.errors import AlignmentError, InvalidValueError, UnitError
from insgnss.imu import grade, rates_table
from insgnss.pipeline import run_job

#: a consumer IMU CSV (deg/s, g, FRD axes) with RTKLIB GNSS and a static start
JOB = {"inputs": {"imu": {"format": "csv", "path": "imu.csv", "gyro_unit": "deg/s",
                          "accel_unit": "g", "axis_map": "y,x,-z"},
                  "gnss": {"format": "rtklib_pos", "path": "gnss.pos",
                           "lever_arm": [0.0, 0.5, 1.0]}},
       "initialization": {"method": "static", "static_duration": 20.0},
       "filter": {"imu_grade": "consumer"},
       "outputs": {"report": False, "progress": False}}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The data of :data:`JOB` (still for 25 s, then a drive) and the job that reads it."""
    d = tmp_path_factory.mktemp("checks")
    job, _ = generate_for(JOB, d)
    return d, job


def _run(job, folder):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_job(load_job_dict(job, folder / "job.toml"), progress=False)


def test_the_correct_job_runs(files):
    d, job = files
    res = _run(job, d)
    assert res.summary["complete"]
    assert abs(res.summary["initialization"]["roll_deg"]) < 2.0


def test_frd_declared_as_rfu_names_the_axis_map(files):
    d, job = files
    bad = copy.deepcopy(job)
    del bad["inputs"]["imu"]["axis_map"]  # the forward-right-down sensor read as right-forward-up
    with pytest.raises(AlignmentError) as e:
        _run(bad, d)
    msg = str(e.value)
    assert "roll" in msg and "up axis points down" in msg and "axis_map" in msg
    roll = float(msg.split("gives roll ")[1].split(" deg")[0])
    assert abs(abs(roll) - 180.0) < 3.0


def test_deg_s_declared_as_rad_s(files):
    d, job = files
    bad = copy.deepcopy(job)
    bad["inputs"]["imu"]["gyro_unit"] = "rad/s"
    with pytest.raises(UnitError) as e:
        _run(bad, d)
    msg = str(e.value)
    assert e.value.column == "inputs.imu.gyro_unit"
    assert "deg/s declared as rad/s" in msg and "Earth rate" in msg
    # the white noise reads 57 times the consumer grade's as well (deg -> rad)
    ratio = float(msg.split("per sample, ")[1].split(" times")[0])
    assert 20 < ratio < 150


def test_static_window_into_motion_names_static_duration(files):
    d, job = files
    bad = copy.deepcopy(job)
    bad["initialization"]["static_duration"] = 40.0  # the data is still for 25 s
    with pytest.raises(AlignmentError) as e:
        _run(bad, d)
    assert e.value.column == "initialization.static_duration"
    msg = str(e.value)
    still = float(msg.split("still only for the first ")[1].split(" s")[0])
    assert 24.0 <= still <= 26.0
    assert "not static" in msg and "units" not in msg  # motion, not the units, is the cause


def test_latitude_degrees_in_a_radians_column(files, tmp_path):
    d, job = files
    base = {"inputs": {"imu": {"format": "native", "path": "imu.csv"},
                       "gnss": {"format": "native", "path": "gnss.csv"}},
            "outputs": {"report": False, "progress": False}}
    job2, _ = generate_for(base, tmp_path)
    g = tmp_path / "gnss.csv"
    g.write_text(g.read_text().replace("lat_deg,", "lat,", 1))  # degrees under 'lat'
    with pytest.raises(InvalidValueError) as e:
        _run(job2, tmp_path)
    assert e.value.column == "lat" and "lat_deg" in str(e.value) and e.value.row == 2
    assert str(g) in str(e.value)


def test_check_upright_thresholds():
    check_upright(np.radians(30.0), np.radians(-20.0), what="levelling")
    for r in (179.0, -95.0):
        with pytest.raises(AlignmentError, match="up axis points down"):
            check_upright(np.radians(r), 0.0, what="levelling")
    with pytest.raises(AlignmentError, match="nearly vertical"):
        check_upright(0.0, np.radians(85.0), what="levelling")


def _still(rate, noise, n=2000, dt=0.01, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    w = np.asarray(rate) + rng.normal(0.0, noise, (n, 3))
    f = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0.0, 0.01, (n, 3))
    return rates_table(t, w, f)


def test_check_gyro_at_rest_numbers():
    model = grade("consumer")
    white = model.gyro_arw / np.sqrt(0.01)
    # a real consumer gyro at rest: Earth rate + a 0.1 deg/s bias, its own white noise
    check_gyro_at_rest(_still([np.radians(0.1), OMEGA_E, 0.0], white), model)
    # the same data in deg/s read as rad/s: 57.3 times everything
    k = 180.0 / np.pi
    with pytest.raises(UnitError) as e:
        check_gyro_at_rest(_still(np.array([np.radians(0.1), OMEGA_E, 0.0]) * k, white * k),
                           model)
    msg = str(e.value)
    times_earth = float(msg.split(" times the Earth rate")[0].rsplit(", ", 1)[1])
    rate = np.linalg.norm([np.radians(0.1) * k, OMEGA_E * k])  # 0.1 "rad/s"
    assert times_earth == pytest.approx(rate / OMEGA_E, rel=0.05)
    assert float(msg.split("per sample, ")[1].split(" times")[0]) == pytest.approx(k, rel=0.1)
    # a model that declares a large bias (raw MEMS offset) lifts the limit
    big = model.scaled(gyro_bias=np.radians(5.0))
    check_gyro_at_rest(_still([np.radians(3.0), 0.0, 0.0], white), big)
    with pytest.raises(UnitError):
        check_gyro_at_rest(_still([1.2 * GYRO_REST_MAX, 0.0, 0.0], white), None)


def test_check_latitude_and_still_duration():
    t = pd.DataFrame({"lat": [0.7, 0.71], "lon": [0.1, 0.1]}, index=[0.0, 1.0])
    check_latitude_radians(t)
    t["lat"] = [45.0, 45.1]
    with pytest.raises(InvalidValueError, match="look like degrees"):
        check_latitude_radians(t)
    imu = _still([0.0, 0.0, 0.0], 1e-3, n=3000)
    assert still_duration(imu, 0.5, np.radians(5.0)) == pytest.approx(29.99)
    imu.iloc[1234:, 3] += np.sin(np.arange(3000 - 1234) * 0.3) * 3.0  # shaking from 12.34 s
    assert still_duration(imu, 0.5, np.radians(5.0)) == pytest.approx(12.0)
