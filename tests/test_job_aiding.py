"""No silent garbage (issue 12 item 2): a job that asks for an aiding source and can apply none
of it stops with exit status 2 and a message naming the filter step that removed everything -
before the filter runs when the inputs show it, after it (outputs written, marked incomplete)
when the innovation gate rejected everything; a source mostly not applied warns and is
flagged; the summary counts applied updates, with offered and rejected beside them.

Inputs: the small seeded simulation of ``robustness_helpers`` (1 Hz GNSS with Q = 5 epochs,
92 s) written to files where the command line is exercised."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
import warnings

import numpy as np
import pytest
from robustness_helpers import small_job, small_job_text

from insgnss.config import load_job_dict
from insgnss.errors import InsgnssWarning, NoUsableAidingError
from insgnss.io.native import write_table
from insgnss.io.outputset import MARKER
from insgnss.pipeline import load_inputs, run_job, write_outputs

#: the simulated GNSS has Q = 5 on every epoch; this q_scale admits only fixed and float
ONLY_FIX_AND_FLOAT = "q_scale = { 1 = 1.0, 2 = 3.0 }"


def _job(**replace) -> object:
    text = small_job_text()
    for old, new in replace.items():
        text = text.replace(old, new)
    return load_job_dict(tomllib.loads(text))


def _quiet_run(job, inputs=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_job(job, inputs=inputs, progress=False)


def test_every_epoch_removed_by_q_scale_stops_naming_the_q_column():
    job = _job(**{"q_scale = { 5 = 1.0 }": ONLY_FIX_AND_FLOAT})
    with pytest.raises(NoUsableAidingError) as e:
        _quiet_run(job)
    err = e.value
    assert err.column == "q"
    msg = str(err)
    assert "aiding.q_scale" in msg and "Q = 5" in msg and "Q = 1, 2" in msg
    # the trail of filter steps ends at the one that removed the last epoch
    assert "92 outside the outage windows, 0 with a Q admitted by aiding.q_scale" in msg


def test_q_scale_stop_from_the_command_line_exits_2(tmp_path):
    d = tmp_path
    inputs = load_inputs(small_job())
    write_table(inputs.imu, d / "imu.csv")
    write_table(inputs.gnss, d / "gnss.csv")
    text = small_job_text().split("[initialization]")[1].replace("q_scale = { 5 = 1.0 }",
                                                                 ONLY_FIX_AND_FLOAT)
    (d / "job.toml").write_text(
        '[inputs.imu]\nformat = "native"\npath = "imu.csv"\n\n[inputs.gnss]\nformat = "native"\n'
        'path = "gnss.csv"\n\n[initialization]' + text.replace("[outputs]\n",
                                                                 '[outputs]\ndir = "out"\n'))
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "process", str(d / "job.toml"),
                        "--no-progress"], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    assert "aiding.q_scale" in r.stderr and "gnss.csv" in r.stderr and "'q'" in r.stderr
    assert not (d / "out" / "summary.json").exists()  # found before any computation


@pytest.mark.parametrize("case", ["outages", "day_late", "day_late_gnss_velocity", "empty",
                                  "nan_sigma"])
def test_variants_give_a_clean_message_naming_the_cause(case):
    """Variants that crashed during the initialization (IndexError, ValueError) or ran
    unaided to the end now stop cleanly, naming the step that removed the GNSS."""
    if case == "outages":
        job = _job(**{"[outputs]": "[outages]\nwindows = [[-10.0, 1000.0]]\n\n[outputs]"})
    elif case == "day_late_gnss_velocity":
        job = _job(**{'method = "static"\nstatic_duration = 15.0':
                      'method = "gnss_velocity"'})  # (a static window is not read then)
    else:
        job = _job()
    inputs = load_inputs(job)
    g = inputs.gnss
    if case.startswith("day_late"):
        inputs.gnss = g.set_axis(g.index + 86400.0, axis=0)
    elif case == "empty":
        inputs.gnss = g.iloc[:0]
    elif case == "nan_sigma":
        inputs.gnss = g.assign(east_std=np.nan)
    with pytest.raises(NoUsableAidingError) as e:
        _quiet_run(job, inputs)
    msg = str(e.value)
    assert "aiding.gnss_position = true asks for GNSS positions" in msg
    expect = {"outages": ("outage window", "outages"),
              "day_late": ("outside the IMU time span 0.000 .. 92.660 s", "time"),
              "day_late_gnss_velocity": ("GNSS 86400.000 .. 86492.000 s", "time"),
              "empty": ("holds no epoch", "time"),
              "nan_sigma": ("non-finite position or sigma", "east_std")}[case]
    assert expect[0] in msg and e.value.column == expect[1]


def test_gate_rejecting_everything_stops_after_the_run_with_outputs_marked(tmp_path):
    """The inputs are fine but the innovation gate (here absurdly tight, recovery off) rejects
    every GNSS epoch: the run goes to its end, the outputs are written for inspection and
    marked INCOMPLETE, and the result carries the error (exit status 2 from the CLI)."""
    job = _job(**{"[outputs]": "[filter]\ngate_probability = 1e-9\ngate_recovery = 0.0\n\n"
                               "[outputs]"})
    res = _quiet_run(job)
    s = res.summary
    assert isinstance(res.failure, NoUsableAidingError)
    assert res.failure.column == "filter.gate_probability"
    assert not s["complete"] and s["stopped_at"] is None
    assert "rejected all 92 evaluated epochs" in s["error"]
    assert s["measurements"]["gnss_pos"] == {"offered": 92, "applied": 0, "rejected": 92,
                                             "recovered": 0, "unusable": 0}
    write_outputs(res, tmp_path)
    marker = (tmp_path / MARKER).read_text()
    assert "not usable" in marker and "filter.gate_probability" in marker and "None" not in marker
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["complete"] is False and MARKER in on_disk["files"]


def test_gate_stop_from_the_command_line_writes_then_exits_2(tmp_path):
    path = tmp_path / "job.toml"
    text = small_job_text(filter="gate_probability = 1e-9\ngate_recovery = 0.0")
    path.write_text(text.replace("[outputs]\n", '[outputs]\ndir = "out"\n'))
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "process", str(path),
                        "--no-progress"], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "filter.gate_probability" in r.stderr
    assert (tmp_path / "out" / MARKER).exists() and (tmp_path / "out" / "forward.csv").exists()


def test_most_of_a_source_unusable_warns_and_is_flagged():
    job = small_job()
    inputs = load_inputs(job)
    g = inputs.gnss.copy()
    q = g["q"].to_numpy().copy()
    q[::5] = 2.0  # 80 % keep Q = 5 (admitted), 20 % become Q = 2 (not admitted): no warning
    g["q"] = q
    inputs.gnss = g
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        res = run_job(job, inputs=inputs, progress=False)
    assert not [w for w in rec if "not applied" in str(w.message)]
    assert res.summary["aiding_warnings"] == []
    inputs = load_inputs(job)
    g = inputs.gnss.copy()
    q = g["q"].to_numpy().copy()
    q[q.size // 3:] = 2.0  # two thirds not admitted by q_scale = {5: 1}
    g["q"] = q
    inputs.gnss = g
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        res = run_job(job, inputs=inputs, progress=False)
    texts = [str(w.message) for w in rec if issubclass(w.category, InsgnssWarning)]
    c = res.summary["measurements"]["gnss_pos"]
    assert res.summary["complete"] and c["unusable"] == 62 and c["applied"] == 30
    flagged = [t for t in texts if "gnss_pos: 62 of 92 offered epochs not applied" in t]
    assert flagged and "Q not admitted by aiding.q_scale" in flagged[0]
    assert any("gnss_pos: 62 of 92" in n for n in res.summary["aiding_warnings"])


def test_summary_counts_are_applied_updates_from_the_innovation_log():
    res = _quiet_run(small_job())
    inn = res.filter.innovations
    for kind, c in res.summary["measurements"].items():
        log = inn[inn["type"] == kind]
        assert c["applied"] == int(log["accepted"].sum()), kind
        assert c["rejected"] == int((~log["accepted"]).sum()), kind
        assert c["recovered"] == int(log["recovered"].sum()), kind
        assert c["applied"] + c["rejected"] + c["unusable"] <= c["offered"], kind
    assert res.summary["measurements"]["gnss_pos"]["offered"] == 92
    assert "rejected" not in res.summary  # one fact in one place: the counts per type


def test_zupt_without_a_stop_warns_but_runs():
    """ZUPT/ZARU depend on the vehicle stopping: a run without stillness is not garbage, it
    warns (GNSS is required; a stop is not)."""
    job = _job(**{"[aiding]\n": "[aiding]\nzupt = true\nstatic_intervals = [[500.0, 510.0]]\n"})
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        res = run_job(job, progress=False)
    assert res.summary["complete"]
    assert any("zupt: none applied" in str(w.message) for w in rec)
    assert any(n.startswith("zupt: none applied") for n in res.summary["aiding_warnings"])


def test_constraint_times_share_the_epochs_the_filter_has():
    """The NHC grid moves onto the GNSS epochs closer than half its interval: with GNSS at its
    rate every constraint is a row of a GNSS epoch; with 1 Hz GNSS one in four; none in an
    outage; at most one constraint per epoch and the spacing stays about the interval."""
    from insgnss.job.aiding import constraint_times

    t0, t1, dt = 100.0, 160.0, 0.25
    gnss = np.round(np.arange(100.149, 160.0, 0.25), 6)  # 4 Hz, another phase
    gnss = gnss[(gnss < 120.0) | (gnss > 135.0)]         # a 15 s outage
    tn = constraint_times(t0, t1, dt, gnss)
    grid = t0 + np.arange(1, int((t1 - t0) / dt)) * dt
    assert tn.size == grid.size
    on = np.isin(tn, gnss)
    assert on.sum() == gnss[gnss < t1 - 0.2].size
    inside = (tn > 120.0) & (tn < 135.0)
    np.testing.assert_allclose(tn[inside], grid[(grid > 120.0) & (grid < 135.0)])
    assert np.all(np.abs(tn - grid) < 0.5 * dt)
    # 1 Hz GNSS: a quarter of the constraints on its epochs, no epoch taken twice
    g1 = np.arange(100.9, 160.0, 1.0)
    tn1 = constraint_times(t0, t1, dt, g1)
    assert tn1.size == grid.size and np.isin(tn1, g1).sum() == np.sum(g1 < grid[-1] + 0.5 * dt)
    # GNSS denser than the grid (10 Hz): every constraint on an epoch, each a different one
    g10 = np.round(np.arange(100.03, 160.0, 0.1), 6)
    tn10 = constraint_times(t0, t1, dt, g10)
    assert np.isin(tn10, g10).all() and np.unique(tn10).size == tn10.size == grid.size
    # an epoch half an interval from two grid times moves neither (a tie); closer, the nearest
    np.testing.assert_array_equal(constraint_times(0.0, 2.0, 0.5, [0.75]), [0.5, 1.0, 1.5])
    np.testing.assert_array_equal(constraint_times(0.0, 2.0, 0.5, [0.76]), [0.5, 0.76, 1.5])
    # no epochs: the plain grid
    np.testing.assert_array_equal(constraint_times(t0, t1, dt, []), grid)
