"""Filter health end to end (issue 8): a filter that goes non-finite or whose NIS runs away stops
with a clear message; the pipeline writes what was computed, marked INCOMPLETE; the CLI exits 3."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest
from robustness_helpers import small_job, small_job_text

from insgnss.errors import FilterHealthError
from insgnss.filter.engine import FilterConfig
from insgnss.io.native import read_table
from insgnss.pipeline import load_inputs, run_job, write_outputs

R_EARTH = 6.37e6


def _offset_gnss(inputs, after: float, metres: float):
    """GNSS epochs from ``after`` s past the first one moved ``metres`` north (a step)."""
    g = inputs.gnss.copy()
    t_bad = float(g.index[0]) + after
    g.loc[g.index >= t_bad, "lat"] += metres / R_EARTH
    inputs.gnss = g
    return t_bad


@pytest.fixture(scope="module")
def quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def test_runaway_nis_stops_the_filter_and_keeps_the_result(quiet):
    """GNSS stepping 50 m with gate recovery off: every epoch is rejected and the window median
    of NIS/dof passes 25 once half of the 30 s window is bad, i.e. about 15 s after the step."""
    job = small_job(filter="gate_recovery = 0")
    inputs = load_inputs(job)
    t_bad = _offset_gnss(inputs, 60.0, 50.0)
    res = run_job(job, inputs=inputs, progress=False)
    assert not res.filter.complete and not res.summary["complete"]
    assert isinstance(res.filter.error, FilterHealthError)
    assert "runaway NIS" in res.summary["error"] and "gnss_pos" in res.summary["error"]
    stop = res.summary["stopped_at"]
    assert t_bad + 10.0 <= stop <= t_bad + 20.0
    # what was computed up to the stop is kept, forward and smoothed
    fwd, smo = res.filter.forward, res.filter.smoothed
    assert fwd.index[-1] == pytest.approx(stop, abs=1.0) and smo.index[-1] == fwd.index[-1]
    assert np.isfinite(fwd[["lat", "lon", "height"]].to_numpy()).all()
    # the rejected steps are listed (gnss_pos rows after the step)
    rej = res.filter.rejected
    assert (rej.loc[rej["type"] == "gnss_pos", "time"] >= t_bad - 1e-6).sum() >= 10


def test_runaway_check_can_be_disabled_from_the_job(quiet):
    job = small_job(filter="gate_recovery = 0\nnis_window = 0")
    inputs = load_inputs(job)
    t_bad = _offset_gnss(inputs, 60.0, 50.0)
    res = run_job(job, inputs=inputs, progress=False)
    assert res.summary["complete"]
    rej = res.filter.rejected
    n_after = int((inputs.gnss.index >= t_bad).sum())
    assert (rej.loc[rej["type"] == "gnss_pos", "time"] >= t_bad - 1e-6).sum() == n_after


def test_gate_recovery_follows_a_step_instead_of_running_away(quiet):
    """With the default 5 s gate recovery a lasting step is accepted after ~5 s: no runaway."""
    job = small_job()
    inputs = load_inputs(job)
    _offset_gnss(inputs, 60.0, 50.0)
    res = run_job(job, inputs=inputs, progress=False)
    assert res.summary["complete"]
    assert res.filter.innovations["recovered"].sum() >= 1
    c = res.summary["measurements"]["gnss_pos"]
    assert 3 <= c["rejected"] <= 8 and c["recovered"] >= 1
    assert c["applied"] + c["rejected"] == c["offered"]


def test_nis_config_is_validated():
    with pytest.raises(Exception, match="NIS window"):
        FilterConfig(nis_window=-1.0).validate()
    with pytest.raises(Exception, match="NIS bound"):
        FilterConfig(nis_bound=0.0).validate()


def test_nan_in_the_imu_stops_and_writes_a_marked_partial_set(quiet, tmp_path):
    """NaN injected in memory after reading (the readers reject NaN in files)."""
    job = small_job(outputs='rate_hz = "imu"')  # every sample: the rows up to the stop
    inputs = load_inputs(job)
    imu = inputs.imu.copy()
    k = int(np.searchsorted(imu.index, imu.index[0] + 50.0))
    imu.iloc[k, 0] = np.nan
    inputs.imu = imu
    t_nan = float(imu.index[k])
    res = run_job(job, inputs=inputs, progress=False)
    assert not res.summary["complete"]
    assert "non-finite" in res.summary["error"]
    # the last good epoch is the one before the NaN sample (1 s epoch grid)
    assert t_nan - 1.0 - 1e-6 <= res.summary["stopped_at"] < t_nan
    out = tmp_path / "out"
    paths = write_outputs(res, out)
    marker = (out / "INCOMPLETE").read_text()
    assert "INCOMPLETE" in marker and "non-finite" in marker and "forward.csv" in marker
    assert "INCOMPLETE" in paths
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is False and "non-finite" in summary["error"]
    assert "INCOMPLETE" in summary["files"]
    fwd = read_table(out / "forward.csv")
    smo = read_table(out / "smoothed.csv")
    assert fwd.index[-1] == pytest.approx(res.summary["stopped_at"])
    assert smo.index[-1] == fwd.index[-1] and len(fwd) > 4000
    assert np.isfinite(fwd[["lat", "lon", "height"]].to_numpy()).all()
    # nothing but the outputs (no staging folder or temporary files) is left
    assert sorted(p.name for p in out.iterdir()) == sorted(paths)


def test_a_complete_rerun_clears_the_incomplete_marker(quiet, tmp_path):
    job = small_job(outputs='rate_hz = "imu"')
    inputs = load_inputs(job)
    good = run_job(job, inputs=load_inputs(job), progress=False)
    imu = inputs.imu.copy()
    imu.iloc[3000, 2] = np.inf
    inputs.imu = imu
    bad = run_job(job, inputs=inputs, progress=False)
    bad.filter.smoothed = None  # e.g. a stop before the smoother had two epochs
    write_outputs(bad, tmp_path)
    assert (tmp_path / "INCOMPLETE").exists() and not (tmp_path / "smoothed.csv").exists()
    write_outputs(good, tmp_path)
    assert not (tmp_path / "INCOMPLETE").exists()
    assert json.loads((tmp_path / "summary.json").read_text())["complete"] is True
    assert len(read_table(tmp_path / "forward.csv")) == len(good.filter.forward)
    # and an incomplete run after a complete one removes the stale smoothed trajectory
    write_outputs(bad, tmp_path)
    assert not (tmp_path / "smoothed.csv").exists()
    assert (tmp_path / "INCOMPLETE").exists()


def test_cli_exits_3_with_a_clear_message(tmp_path):
    """A job whose GNSS sigma is 500 times too small: runaway NIS, partial outputs, status 3."""
    job = tmp_path / "job.toml"
    job.write_text(small_job_text(aiding="gnss_position_std = 0.001\ngnss_min_std = 0.0001"))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "process", str(job), "-o", str(out),
                        "--no-progress"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 3, r.stderr
    assert "INCOMPLETE" in r.stderr and "runaway NIS" in r.stderr and "Traceback" not in r.stderr
    assert (out / "INCOMPLETE").exists()
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["stopped_at"] is not None
    fwd = pd.read_csv(out / "forward.csv")
    assert fwd["time"].iloc[-1] == pytest.approx(s["stopped_at"])


def test_runaway_window_median_equals_numpy():
    """The runaway-NIS window median (an insertion sort of at most 64 values) is the value
    ``np.median`` gives, odd and even counts, ties and infinite NIS included."""
    from insgnss.filter.health import _small_median

    rng = np.random.default_rng(5)
    for n in range(1, 65):
        for _ in range(5):
            v = rng.chisquare(3, n) / 3
            if n > 3:
                v[rng.integers(0, n, 2)] = np.inf  # a non-finite NIS is pushed as inf
                v[rng.integers(0, n)] = v[0]  # a tie
            got = _small_median(v.copy(), n)
            assert got == np.median(v), (n, got, np.median(v))
    buf = np.array([3.0, 1.0, 2.0, 9.0, 7.0])
    assert _small_median(buf, 4) == 2.5 and list(buf[:4]) == [1.0, 2.0, 3.0, 9.0]
