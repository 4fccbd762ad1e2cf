"""Every job value at its documented extreme completes or refuses cleanly (issue 12): the
short form of bench/bench_extremes.py (45 s simulated instead of 5 minutes, no report), each
run an ``insgnss process`` subprocess under a 4 GiB address-space limit."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("bench_extremes",
                                               REPO / "bench" / "bench_extremes.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_the_extremes_are_the_documented_ends_of_the_ranges():
    data = bench.job_data("low", duration=45.0)
    assert data["filter"]["epoch_interval"] == 0.01  # one IMU interval at 100 Hz
    assert data["outages"]["periodic"]["length"] == data["outages"]["periodic"]["gap"] == 0.01
    assert data["filter"]["gate_probability"] == 0.0 and data["aiding"]["gnss_min_std"] == 0.0
    assert data["aiding"]["nhc_std"] == [bench.OPEN_STEP] * 2
    assert data["initialization"]["heading_deg"] == -360.0
    high = bench.job_data("high", duration=45.0)
    assert high["filter"]["gate_probability"] < 1.0 < high["filter"]["gate_probability"] + 1e-6
    assert high["aiding"]["zupt_std"] == bench.BIG and high["outages"]["windows"] == \
        [[-bench.BIG, bench.BIG]]
    assert "nis_bound" not in data["filter"]  # nis_window = 0 switches it off
    import tomllib

    assert tomllib.loads(bench.to_toml(high)) == high


@pytest.mark.parametrize("process_model,side", [("strapdown", "low"), ("strapdown", "high"),
                                                ("strapdown", "work"), ("riss", "work")])
def test_extreme_job_completes_or_refuses_cleanly(tmp_path, process_model, side):
    data = bench.job_data(side, process_model=process_model, duration=45.0)
    data["outputs"]["report"] = False  # the plots of 4,500 outage windows take minutes
    r = bench.run_one(data, tmp_path, bench._limit("4G"), timeout=900)
    assert r["clean"], r["stderr"][-4000:]
    if side == "work":  # the memory and work extremes run through
        assert r["exit"] in (0, 3), r["stderr"][-2000:]
        assert (tmp_path / "out" / "summary.json").exists()


def test_a_filter_stopped_at_its_first_epoch_still_gives_a_clean_result(tmp_path):
    """A singular initial covariance (a zero sigma of an estimated state, set in memory past
    the loader) stops the filter at t0; with ZUPT at the first sample the forward solution is
    empty, and its evaluation raised an IndexError (found by bench_extremes)."""
    import json
    import warnings

    from robustness_helpers import small_job

    from insgnss.pipeline import evaluate_solution, run_job, write_outputs

    job = small_job(filter="scale_factors = true", aiding="zupt = true")
    job.settings["filter"]["imu_model"]["gyro_scale_ppm"] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(job, progress=False)
        write_outputs(res, tmp_path)
    assert not res.filter.complete and "positive definite" in res.summary["error"]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["complete"] is False
    empty = res.filter.forward.iloc[:0]
    assert evaluate_solution(empty, res.inputs, res.windows, job) == {}
