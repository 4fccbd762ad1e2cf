"""In-motion heading alignment (insgnss.align.heading_in_motion, initialization.heading_alignment)
and the GNSS-moving intervals that end the ZUPT of a smooth pull-away."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pandas as pd
import pytest
from example_data import generate_for

from insgnss.align import free_inertial_drift_std, heading_in_motion
from insgnss.config import load_job_dict
from insgnss.imu import ImuErrorModel
from insgnss.job.initialization import gnss_moving_intervals, initialize
from insgnss.job.inputs import imu_model, load_inputs


def _path(n: int = 40):
    """An accelerating, turning horizontal path (east, north) from the origin."""
    t = np.arange(1, n + 1, dtype=float)
    az = np.radians(10.0) + 0.02 * t
    v = 0.1 * t
    e = np.cumsum(v * np.sin(az))
    nn = np.cumsum(v * np.cos(az))
    return t, np.column_stack([e, nn])


def _rotate(xy, psi):
    """Turn east/north displacements by the azimuth ``psi`` (clockwise seen from above)."""
    z = (xy[:, 1] + 1j * xy[:, 0]) * np.exp(1j * psi)
    return np.column_stack([z.imag, z.real])


def test_recovers_the_rotation_of_the_path_and_its_sigma_covers_it():
    rng = np.random.default_rng(1)
    t, y = _path()
    psi = np.radians(-140.0)
    x = _rotate(y, -psi)  # the free-inertial path computed with heading 0
    drift = 0.002 * t ** 2
    x_noisy = x + rng.normal(size=x.shape) * drift[:, None]
    out = heading_in_motion(t, x_noisy, y, drift, 0.02)
    assert out is not None
    err = np.angle(np.exp(1j * (out.offset - psi)))
    assert abs(err) < 3 * out.std
    assert 1e-4 < out.std < np.radians(3.0)
    # the fit stops where the drift outgrows the distance, not at the last epoch
    assert out.end < t[-1] and out.n >= 3


def test_no_motion_gives_none_and_inconsistent_data_inflates_the_sigma():
    t = np.arange(1.0, 11.0)
    assert heading_in_motion(t, np.zeros((10, 2)) + 1e-3, np.zeros((10, 2)), 0.01 * t,
                             0.02) is None
    _, y = _path(10)
    good = heading_in_motion(t, y, y, 0.01 * t, 0.02)
    bad = heading_in_motion(t, _rotate(y, np.radians(5.0) * np.sin(t)), y, 0.01 * t, 0.02)
    assert good is not None and bad is not None
    assert abs(good.offset) < 1e-9
    assert bad.std > 1.5 * good.std


def test_drift_model_grows_with_time_and_with_the_body_rotation():
    m = ImuErrorModel(accel_bias=0.2, accel_vrw=0.002, gyro_arw=np.radians(0.5) / 60,
                      gyro_bias=np.radians(360.0) / 3600)
    t = np.linspace(0.0, 20.0, 201)
    still = free_inertial_drift_std(t, np.zeros_like(t), m, 30.0)
    turned = free_inertial_drift_std(t, np.radians(30.0) * t / 20.0, m, 30.0)
    assert np.all(np.diff(still) >= 0) and still[-1] > 0
    # 0.2 m/s^2 bias turned by up to 30 deg: ~0.1 m/s^2 * t^2 / 6 at the end, ~6.9 m
    assert turned[-1] > 5.0 > still[-1]


def test_moving_intervals_from_rtk_displacements():
    t = np.arange(0.0, 10.0)
    lat0, lon0 = np.radians(40.0), np.radians(-105.0)
    north = np.where(t < 5, 0.0, 0.5 * 0.17 * (t - 5) ** 2)  # a 0.17 m/s^2 pull-away at 5 s
    g = pd.DataFrame({"lat": lat0 + north / 6.37e6, "lon": lon0, "height": 1600.0,
                      "vel_e": 0.0, "vel_n": np.gradient(north), "east_std": 0.02,
                      "north_std": 0.02}, index=pd.Index(t, name="time"))
    speed_only = gnss_moving_intervals(g, [])
    both = gnss_moving_intervals(g, [], displacement_sigmas=3.0)
    first = lambda iv: min(a for a, _ in iv)  # noqa: E731
    # speed > 0.3 m/s from about 7 s; the 2 cm displacements show the motion from 6 s
    assert first(speed_only) > 6.4
    assert 5.9 < first(both) < 6.1
    assert all(b <= 5.0 or a >= 5.0 for a, b in both)  # nothing before the motion


@pytest.mark.parametrize("alignment", ["in_motion", "course"])
def test_hand_held_start_heading(alignment, tmp_path):
    from test_docs_examples import EXAMPLES

    job = copy.deepcopy(next(j for t, j in EXAMPLES if t.startswith("Hand-held")))
    job.setdefault("initialization", {})["heading_alignment"] = alignment
    job, truth = generate_for(job, tmp_path)
    j = load_job_dict(job, tmp_path / "job.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ini = initialize(j, load_inputs(j), imu_model(j, None))
    C = ini.state.C
    hdg = np.arctan2(C[0, 1], C[1, 1])
    true = float(truth["heading"].iloc[0])
    err = abs(np.angle(np.exp(1j * (hdg - true))))
    if alignment == "in_motion":
        assert ini.heading_source == "in_motion"
        assert np.radians(0.5) <= ini.att_std[2] < np.radians(5.0)
        assert err < 3 * ini.att_std[2] and err < np.radians(1.0)
    else:
        assert ini.heading_source == "gnss_course"
        assert ini.att_std[2] == pytest.approx(np.radians(30.0))
