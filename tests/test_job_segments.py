"""Split runs (issue 12 item 6, ``inputs.imu.gap_policy = "split"``): a later segment does not
initialize from GNSS withheld by an outage window, each segment is filtered and smoothed only
within itself, the merged output has no jump with a tiny sigma at a segment start, and every
message names real times.

Simulated: the small seeded job of ``robustness_helpers`` with a 2 s logger gap at 50 s. Real:
the rtklibexplorer drive (job ``scenarios/drive_0708.toml``, 11 outages of 15 s) with a 10 s
IMU gap that ends inside the second outage.
"""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import numpy as np
import pytest
from robustness_helpers import small_job

from insgnss.config import load_job
from insgnss.io.outputset import MARKER
from insgnss.pipeline import load_inputs, run_job, write_outputs

REPO = Path(__file__).resolve().parents[1]
GAP = (50.0, 52.0)
R_EARTH = 6.37e6


def _split_job(**tables):
    return small_job(**{"inputs.imu": 'gap_policy = "split"', **tables})


def _gapped(job, gap=GAP):
    inputs = load_inputs(job)
    t = inputs.imu.index.to_numpy()
    inputs.imu = inputs.imu[(t <= gap[0]) | (t >= gap[1])]
    return inputs


def _run(job, inputs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_job(job, inputs=inputs, progress=False)


def test_later_segment_does_not_initialize_from_withheld_gnss():
    """Segment 1 starts at 52 s, inside an outage window [51, 60]: its initialization takes
    the first GNSS epoch after the window, as the aiding does (it used the epoch at 52 s)."""
    job = _split_job(outages="windows = [[51.0, 60.0]]\nrelative_to = \"absolute\"")
    res = _run(job, _gapped(job))
    assert res.summary["complete"]
    seg1 = res.summary["segments"][1]
    assert seg1["initialization"] == "gnss_velocity" and seg1["init_time"] >= 60.0
    for name in ("forward", "smoothed"):
        df = getattr(res.filter, name)
        assert df[df["segment"] == 1].index[0] >= 60.0, name
    # no GNSS epoch inside the window was applied either
    inn = res.filter.innovations
    t = inn.loc[inn["type"].str.startswith("gnss"), "time"].to_numpy()
    assert not ((t > 51.0) & (t < 60.0)).any()


def test_each_segment_is_filtered_and_smoothed_only_within_itself():
    """Changing the IMU data of segment 0 (a gyro bias added) leaves segment 1 bit for bit as
    it was, forward and smoothed; segment 0 itself changes."""
    job = _split_job()
    a = _run(job, _gapped(job))
    inputs = _gapped(job)
    imu = inputs.imu.copy()
    t = imu.index.to_numpy()
    col, scale = ("gyro_z", 1.0) if "gyro_z" in imu.columns else \
        ("dtheta_z", float(np.median(np.diff(t))))  # rates or increments
    imu.loc[t < GAP[0], col] += np.radians(0.5) * scale  # 0.5 deg/s: segment 0 drifts
    imu.attrs = dict(inputs.imu.attrs)
    inputs.imu = imu
    b = _run(job, inputs)
    for name in ("forward", "smoothed"):
        fa, fb = getattr(a.filter, name), getattr(b.filter, name)
        cols = ["lat", "lon", "height", "heading", "east_std"]
        s1a, s1b = fa[fa["segment"] == 1][cols], fb[fb["segment"] == 1][cols]
        assert len(s1a) > 3000
        np.testing.assert_array_equal(s1a.to_numpy(), s1b.to_numpy())
        s0a, s0b = fa[fa["segment"] == 0][cols], fb[fb["segment"] == 0][cols]
        assert np.abs(s0a["heading"].to_numpy() - s0b["heading"].to_numpy()).max() > 1e-3


def test_a_later_segment_that_stops_early_names_its_time(tmp_path):
    """Segment 0 completes; segment 1 gets GNSS shifted by 30 m with the gate off, so its NIS
    runs away and it stops: the run is incomplete, the summary, the INCOMPLETE marker and the
    command line name the real stop time (they said "t = None s")."""
    job = _split_job(filter="gate_probability = 0.0")
    inputs = _gapped(job)
    g = inputs.gnss.copy()
    g.loc[g.index >= 55.0, "lat"] += 30.0 / R_EARTH
    inputs.gnss = g
    res = _run(job, inputs)
    s = res.summary
    assert [x["complete"] for x in s["segments"]] == [True, False]
    assert not s["complete"] and s["error"].startswith("IMU segment 1: ")
    t_stop = s["stopped_at"]
    assert isinstance(t_stop, float) and 60.0 < t_stop < 93.0
    assert s["segments"][1]["stopped_at"] == t_stop and "runaway NIS" in s["error"]
    write_outputs(res, tmp_path)
    marker = (tmp_path / MARKER).read_text()
    assert f"t = {t_stop:.3f} s" in marker and "None" not in marker


@pytest.fixture(scope="module")
def drive_split():
    """The drive with the IMU samples of 80..90 s after the first fix removed: segment 1
    starts inside the outage window 85..100 s."""
    from conftest import shared_data

    shared_data("gnss-imu-rtklibexplorer", "drive_0708")
    job = load_job(REPO / "scenarios" / "drive_0708.toml")
    job.settings["inputs"]["imu"]["gap_policy"] = "split"
    job.settings["filter"]["autotune"] = False  # the segment mechanics, not the tuning
    inputs = load_inputs(job)
    tg0 = float(inputs.gnss.index[0])
    t = inputs.imu.index.to_numpy()
    inputs.imu = inputs.imu[(t < tg0 + 80.0) | (t > tg0 + 90.0)]
    single_job = load_job(REPO / "scenarios" / "drive_0708.toml")
    single_job.settings["filter"]["autotune"] = False
    single = _run(single_job, None)
    return _run(job, copy.copy(inputs)), single, tg0


def test_drive_split_respects_the_outage_and_has_no_jump(drive_split):
    res, single, tg0 = drive_split
    s = res.summary
    w = [(a - tg0, b - tg0) for a, b in res.windows]
    assert (85.0, 100.0) in [(round(a, 3), round(b, 3)) for a, b in w]
    seg1 = s["segments"][1]
    assert seg1["start"] - tg0 < 90.5
    # no GNSS of the window 85..100 s: segment 1 starts at the first fix after it
    assert seg1["init_time"] - tg0 >= 100.0
    # both segments run to their end (segment 1 used to diverge: runaway NIS, 14 m errors)
    assert s["complete"] and all(x["complete"] for x in s["segments"])
    for name in ("forward", "smoothed"):
        df = getattr(res.filter, name)
        s1 = df[df["segment"] == 1]
        err = res.evaluation[name]["errors"].loc[s1.index[0]: s1.index[0] + 10.0]
        # at the segment start the error is small and inside its own sigma
        assert err["horizontal"].max() < 0.3, name
        assert (err["east"].abs() <= 5 * err["east_std"] + 0.02).all(), name
    smo = res.evaluation["smoothed"]["summary"]
    assert smo["max_h_m"] < 1.0
    # the segments reach the accuracy of the unsplit run outside the removed seconds
    assert smo["non_outage_rms_h_m"] < 2 * single.evaluation["smoothed"]["summary"][
        "non_outage_rms_h_m"]
    # the IMU noise measured while parked (segment 0) holds in segment 1 too
    assert s["imu_model"] == single.summary["imu_model"]
