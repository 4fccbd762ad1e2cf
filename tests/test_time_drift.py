"""IMU-GNSS time offset with a linear drift (insgnss.preprocess.estimate_time_correction): a
simulated car whose IMU time base runs 300 ppm slow, one without a drift, and the real drive."""

from __future__ import annotations

import numpy as np
import pytest
from filter_sim import car_truth, corrupt_imu

from insgnss.imu import grade
from insgnss.preprocess import TimeCorrection, estimate_time_correction, shift_time
from insgnss.simulate.aiding import simulate_gnss


@pytest.fixture(scope="module")
def car():
    """A 600 s manoeuvring car: consumer IMU at 100 Hz (true time), RTK-like GNSS at 4 Hz."""
    rng = np.random.default_rng(7)
    truth = car_truth(duration=600.0, rate=100.0)
    imu, _ = corrupt_imu(truth, grade("consumer"), rng)
    gnss = simulate_gnss(truth, rng, rate=4.0, horizontal_std=0.02, vertical_std=0.04)
    return imu, gnss


def _recorded(imu, offset, drift, t_ref=300.0):
    """The IMU table as a logger with a time error stamps it: a sample taken at true time t
    is stamped ``t - offset - drift (t - t_ref)``."""
    t = imu.index.to_numpy(float)
    out = imu.set_axis(t - offset - drift * (t - t_ref), axis=0)
    out.attrs = dict(imu.attrs)
    return out


def test_a_drifting_imu_clock_is_recovered_and_undone(car):
    imu, gnss = car
    rec = _recorded(imu, 0.05, -300e-6)  # slow by 300 ppm: 0.18 s over the 600 s log
    corr, info = estimate_time_correction(rec, gnss)
    assert info["drift_applied"] and info["drift_t"] > 5
    assert corr.drift == pytest.approx(-300e-6, abs=30e-6)
    # the corrected stamps are the true times within a few milliseconds over the whole log
    t_true = imu.index.to_numpy(float)
    err = corr(rec.index.to_numpy(float)) - t_true
    assert np.max(np.abs(err)) < 0.006
    fixed = shift_time(rec, corr)
    assert np.all(np.diff(fixed.index.to_numpy(float)) > 0)
    # the constant-offset model alone leaves up to +-0.09 s at the ends
    c0, _ = estimate_time_correction(rec, gnss, drift=False)
    assert c0.drift == 0.0 and np.max(np.abs(c0(rec.index.to_numpy(float)) - t_true)) > 0.06


def test_no_drift_is_not_invented(car):
    imu, gnss = car
    rec = _recorded(imu, -0.08, 0.0)
    corr, info = estimate_time_correction(rec, gnss)
    assert not info["drift_applied"] and corr.drift == 0.0
    assert corr.offset == pytest.approx(-0.08, abs=0.01)  # the course-rate fit: ~ -7 ms bias at 100 Hz
    assert len(info["drift_windows"]) >= 4  # it looked, and found nothing to apply


def test_time_correction_maps_times():
    c = TimeCorrection(0.1, 1e-3, 100.0)
    assert c(100.0) == pytest.approx(100.1) and c(200.0) == pytest.approx(200.2)
    assert not TimeCorrection() and c


def test_drive_imu_clock_drift():
    """The rtklibexplorer drive: its IMU stamps (the IMU counter scaled onto the time-tag
    span) drift against GPS time by about -0.3 ms/s (docs/generalization.md)."""
    from conftest import shared_data

    from insgnss.config import load_job
    from insgnss.job.inputs import load_inputs
    from insgnss.pipeline import outage_windows

    shared_data("gnss-imu-rtklibexplorer", "drive_0708")
    from pathlib import Path

    job = load_job(Path(__file__).resolve().parents[1] / "scenarios" / "drive_0708.toml")
    inputs = load_inputs(job)
    corr, info = estimate_time_correction(inputs.imu, inputs.gnss,
                                          outage_windows(job, inputs.gnss))
    assert info["drift_applied"] and info["drift_t"] > 5
    assert -400e-6 < corr.drift < -250e-6
    assert info["drift_residual_rms_s"] < 0.015
