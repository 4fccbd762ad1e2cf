"""The processing window ``[job] start`` / ``end`` (insgnss.job.span): a time in the job's
time base, "+SECONDS" after the first IMU sample, or a GPS time; every input is cut to it and
the outage windows stay where the whole recording puts them."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest
from example_data import T0, generate_for
from robustness_helpers import small_job

from insgnss.config import load_job_dict
from insgnss.errors import ConfigError
from insgnss.pipeline import run_job

RTK = {"job": {"time_base": "gps"},
       "inputs": {"imu": {"format": "native", "path": "imu.csv"},
                  "gnss": {"format": "rtklib_pos", "path": "gnss.pos"}},
       "initialization": {"method": "static", "static_duration": 20.0},
       "outages": {"windows": [[40.0, 50.0]]},
       "outputs": {"report": False, "progress": False}}


def _run(job):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_job(job, progress=False)


def test_relative_window_on_a_simulated_job():
    full = _run(small_job())
    job = small_job(job='start = "+2"\nend = "+60"')
    res = _run(job)
    t = res.filter.forward.index.to_numpy(float)
    assert t[0] >= 2.0 and t[-1] <= 60.0 and t[-1] > 59.9
    assert res.summary["preprocessing"]["processing_window"] == [2.0, 60.0]
    assert res.inputs.gnss.index.min() >= 2.0 and res.inputs.gnss.index.max() <= 60.0
    assert res.inputs.reference.index.max() <= 60.0
    assert res.summary["imu_samples"] < 0.7 * full.summary["imu_samples"]
    # the same solution over the window as the whole run up to 60 s, to the filter's accuracy
    f = full.filter.forward.loc[20.0:60.0]
    w = res.filter.forward.loc[20.0:60.0]
    dn = (w["lat"].to_numpy() - f["lat"].reindex(w.index).to_numpy()) * 6.37e6
    assert np.nanmax(np.abs(dn)) < 1.0


def test_gps_time_number_and_relative_agree(tmp_path):
    job, truth = generate_for(RTK, tmp_path)
    runs = {}
    for name, (a, b) in {"number": (T0 + 1.0, T0 + 120.0),
                         "relative": ("+1", "+120"),
                         "gps time": ("2025-07-08 19:34:01", "2025-07-08 19:36:00")}.items():
        j = copy.deepcopy(job)
        j["job"].update(start=a, end=b)
        runs[name] = _run(load_job_dict(j, tmp_path / "job.toml"))
    for name, res in runs.items():
        assert res.summary["preprocessing"]["processing_window"] == [T0 + 1.0, T0 + 120.0], name
        assert res.summary["complete"]
        # the outage stays 40-50 s after the first GNSS epoch of the file, not of the window
        assert res.summary["outages"] == [[T0 + 40.0, T0 + 50.0]], name
    a, b = runs["number"].filter.forward, runs["gps time"].filter.forward
    np.testing.assert_array_equal(a.index, b.index)
    np.testing.assert_allclose(a["lat"], b["lat"], rtol=0, atol=1e-12)


def test_window_errors_name_the_key(tmp_path):
    job, _ = generate_for(RTK, tmp_path)
    cases = [({"start": "+50", "end": "+20"}, "job.end", "ends before it starts"),
             ({"start": T0 + 1e5}, "job.start", "holds no IMU data"),
             ({"start": "yesterday"}, "job.start", "not a time"),
             ({"start": "+-3"}, "job.start", "not a number of seconds")]
    for keys, column, text in cases:
        j = copy.deepcopy(job)
        j["job"].update(keys)
        with pytest.raises(ConfigError, match=text) as e:
            _run(load_job_dict(j, tmp_path / "job.toml"))
        assert e.value.column == column
    j = copy.deepcopy(job)
    j["job"].update(time_base="unspecified", start="2025-07-08 19:34:01")
    j["inputs"]["gnss"] = {"format": "native", "path": "gnss.csv"}
    with pytest.raises(ConfigError, match="knows the date") as e:
        from insgnss.job.span import processing_window

        processing_window(load_job_dict(j, tmp_path / "job.toml"), _imu_table(tmp_path))
    assert e.value.column == "job.start"


def _imu_table(folder):
    from insgnss.io.native import read_table

    return read_table(folder / "imu.csv")
