"""Issue 22 item 5: noise and stillness thresholds measured in a static window ignore the
samples that end a bridged gap, and the default vehicle ZUPT detector follows the still noise
of a parked car with its engine running."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from mech_helpers import static_increments

from insgnss.detect import DetectorConfig, detect_stillness, regular_samples
from insgnss.job.aiding import VEHICLE_DETECTOR, still_threshold
from insgnss.preprocess import static_noise

RATE = 100.0
VRW = 0.042 / 60.0  # m/s/sqrt(s) (0.042 m/s/sqrt(h))
DV = ["dv_x", "dv_y", "dv_z"]


def _static(duration=25.0, vrw=VRW, seed=0) -> pd.DataFrame:
    imu, _ = static_increments(duration, RATE)
    rng = np.random.default_rng(seed)
    imu[DV] = imu[DV].to_numpy() + rng.normal(0, vrw * np.sqrt(1 / RATE), (len(imu), 3))
    return imu.iloc[1:]


def _bridged(imu: pd.DataFrame, k: int = 1200) -> pd.DataFrame:
    """Sample k lost; the next row keeps its own (one-interval) increment, as a logger that
    does not accumulate writes it: divided by the two intervals it looks like g / 2."""
    return imu.drop(imu.index[k])


def test_regular_samples_flag_the_sample_after_a_gap():
    t = np.r_[np.arange(10) * 0.01, 0.11, 0.12]
    ok = regular_samples(t)
    assert list(np.flatnonzero(~ok)) == [10]


def test_static_noise_ignores_the_bridged_sample():
    imu = _static()
    vrw = static_noise(imu)[1]
    assert vrw == pytest.approx(VRW, rel=0.1)
    vrw_b = static_noise(_bridged(imu))[1]
    assert vrw_b == pytest.approx(VRW, rel=0.1)
    # what the bridged sample did before (issue 22: 0.042 -> 0.54 m/s/sqrt(h))
    from insgnss.detect import imu_rates

    t, _, f = imu_rates(_bridged(imu))
    naive = float(np.max(np.std(f, axis=0))) * np.sqrt(1 / RATE)
    assert naive > 10 * VRW


@pytest.mark.parametrize("idle", [0.1, 0.15])
def test_default_detector_follows_the_idling_engine(idle):
    """Engine vibration of `idle` m/s^2 per axis (AMV statistic ~sqrt(3) idle = 0.17-0.26):
    the fixed 0.1 never detects the parked car; the threshold from the static window does,
    and it stays below the static start's stillness limit (0.5) and above the still level."""
    imu = _static(60.0, vrw=idle / np.sqrt(RATE))
    static = _bridged(imu.loc[:25.0], 1200)
    thr = still_threshold(static, 0.5)
    assert 0.1 < thr <= 0.5
    assert thr > np.sqrt(3) * idle
    fixed = detect_stillness(imu, DetectorConfig(**VEHICLE_DETECTOR)).still.to_numpy()
    spec = dict(VEHICLE_DETECTOR, threshold=thr)
    measured = detect_stillness(imu, DetectorConfig(**spec)).still.to_numpy()
    assert fixed.mean() < 0.05 and measured.mean() > 0.9
    # a quiet IMU keeps the default
    assert still_threshold(_static(25.0), 0.5) == pytest.approx(0.1)
    # capped at the limit the static start accepted
    assert still_threshold(_static(25.0, vrw=1.0 / np.sqrt(RATE)), 0.5) == pytest.approx(0.5)
