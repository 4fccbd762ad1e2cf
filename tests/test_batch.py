"""Batch processing (issue 9): many recorded logs with the same settings, one summary table; a
broken job is reported and does not stop the others."""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pandas as pd
import pytest

from insgnss.batch import COLUMNS, expand_jobs, merge_settings, run_batch
from insgnss.cli import main as cli_main
from insgnss.errors import ConfigError
from insgnss.simulate.scenario import simulate_scenario

SCENARIO = """
[scenario]
name = "log"
imu_rate = 50.0

[trajectory]
vehicle = "land"
lat = 45.0
lon = 7.0
height = 300.0
heading = 30.0
segments = [
  { type = "static", duration = 20.0 },
  { type = "accelerate", speed = 15.0, acceleration = 2.0 },
  { type = "turn", angle = 90.0, rate = 15.0 },
  { type = "hold", duration = 30.0 },
]

[imu]
grade = "tactical"

[gnss]
rate = 1.0
horizontal_std = 1.0
vertical_std = 2.0
velocity = true
velocity_std = 0.05
q = 5
"""

#: the lab's shared settings (every job gets them)
BASE = """
[initialization]
method = "static"
static_duration = 15.0

[aiding]
gnss_position = true
gnss_velocity = true
q_scale = { 5 = 1.0 }

[outages]
windows = [[30.0, 40.0]]

[filter]
bias_model = "random_walk"

[outputs]
report = false
progress = false
formats = ["csv"]
"""

JOB = """
[job]
name = "{name}"

[inputs.imu]
format = "native"
path = "{folder}/imu.csv"

[inputs.gnss]
format = "native"
path = "{folder}/gnss.csv"

[inputs.reference]
format = "native"
path = "{folder}/truth.csv"
point = "imu"
"""


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """Two simulated logs written as files with a job file each, a shared settings file and a
    job whose IMU file is missing."""
    root = tmp_path_factory.mktemp("campaign")
    for k, seed in enumerate((11, 12)):
        sim = simulate_scenario(tomllib.loads(SCENARIO), seed=seed)
        sim.write(root / f"log{k}")
        (root / "jobs").mkdir(exist_ok=True)
        (root / "jobs" / f"log{k}.toml").write_text(JOB.format(name=f"drive{k}",
                                                               folder=f"../log{k}"))
    # a job whose IMU file is not a table (it fails), one whose data is not present and a
    # settings-only file (both skipped with a note)
    (root / "broken").mkdir()
    (root / "broken" / "imu.csv").write_text("time,gyro_x\nnot a number,1\n")
    (root / "broken" / "gnss.csv").write_text((root / "log0" / "gnss.csv").read_text())
    (root / "broken" / "truth.csv").write_text((root / "log0" / "truth.csv").read_text())
    (root / "jobs" / "broken.toml").write_text(JOB.format(name="broken", folder="../broken"))
    (root / "jobs" / "missing.toml").write_text(JOB.format(name="missing", folder="../nowhere"))
    (root / "jobs" / "settings_only.toml").write_text("[filter]\nsmoother = false\n")
    (root / "lab.toml").write_text(BASE)
    return root


def test_expand_and_merge(campaign):
    files, empty = expand_jobs([str(campaign / "jobs" / "*.toml"), str(campaign / "jobs" /
                                                                      "log0.toml"),
                                str(campaign / "none*" / "*.toml")])
    assert [f.name for f in files] == ["broken.toml", "log0.toml", "log1.toml",  # unique, sorted
                                       "missing.toml", "settings_only.toml"]
    assert empty == [str(campaign / "none*" / "*.toml")]
    m = merge_settings({"filter": {"bias_model": "random_walk", "smoother": True}, "a": 1},
                       {"filter": {"smoother": False}, "b": 2})
    assert m == {"filter": {"bias_model": "random_walk", "smoother": False}, "a": 1, "b": 2}
    with pytest.raises(ConfigError, match="no job file"):
        run_batch([str(campaign / "none*.toml")])


def test_batch_summary_table_and_failure(campaign, tmp_path):
    out = tmp_path / "out"
    res = run_batch([str(campaign / "jobs" / "*.toml")], settings=campaign / "lab.toml",
                    out_dir=out)
    t = res.table.set_index("job")
    assert list(res.table.columns) == COLUMNS
    assert list(t.index) == ["missing", "settings_only", "broken", "drive0", "drive1"]
    assert list(t["status"]) == ["skipped", "skipped", "failed", "ok", "ok"]
    # skipped with a one-line reason naming the missing file / what the file is for
    assert t.loc["missing", "error"].startswith("data not present: ")
    assert "nowhere" in t.loc["missing", "error"] and "imu.csv" in t.loc["missing", "error"]
    assert "settings only" in t.loc["settings_only", "error"]
    assert "--settings" in t.loc["settings_only", "error"]
    assert [k["file"].rsplit("/", 1)[1] for k in res.summary["skipped"]] == [
        "missing.toml", "settings_only.toml"]
    assert "imu.csv" in t.loc["broken", "error"]                 # names the bad file
    assert res.failures[0]["job"] == "broken" and res.failures[0]["traceback"]
    for name in ("drive0", "drive1"):
        r = t.loc[name]
        assert r["imu_samples"] > 3000 and r["duration_s"] > 60
        assert r["initialization"] == "static"
        assert json.loads(r["measurements"])["gnss_pos"] > 50
        # evaluated against the truth file: sub-metre with GNSS, a 10 s outage drifts a little
        assert 0.05 < r["forward_non_outage_rms_h_m"] < 1.0
        assert r["forward_n_outages"] == 1
        assert r["smoothed_rms_h_m"] < r["forward_rms_h_m"]
        assert (out / name / "forward.csv").exists() and (out / name / "summary.json").exists()
    # the two logs differ (different data), the settings are shared (same outage)
    assert t.loc["drive0", "forward_rms_h_m"] != t.loc["drive1", "forward_rms_h_m"]
    paths = res.write(out)
    table = pd.read_csv(paths["csv"])
    assert list(table["status"]) == ["skipped", "skipped", "failed", "ok", "ok"]
    pd.testing.assert_frame_equal(pd.read_parquet(paths["parquet"]), res.table,
                                  check_dtype=False)
    summary = json.loads(paths["json"].read_text())
    assert (summary["jobs"], summary["ok"], summary["failed"]) == (5, 2, 1)
    assert len(summary["skipped"]) == 2
    assert summary["failures"][0]["file"].endswith("broken.toml")


def test_batch_cli_with_a_job_overriding_the_settings(campaign, tmp_path, capsys):
    # a job file that sets its own outage instead of the lab's
    own = campaign / "jobs" / "log0.toml"
    special = tmp_path / "special.toml"
    special.write_text(own.read_text().replace("../log0", str(campaign / "log0")) +
                       "\n[outages]\nwindows = [[30.0, 60.0]]\n")
    out = tmp_path / "cli"
    code = cli_main(["batch", str(special), str(campaign / "jobs" / "log1.toml"),
                     "--settings", str(campaign / "lab.toml"), "-o", str(out),
                     "--summary-only", "--no-progress"])
    assert code == 0
    t = pd.read_csv(out / "batch.csv").set_index("job")
    assert list(t["status"]) == ["ok", "ok"]
    assert not (out / "drive0").exists()                          # --summary-only
    # the longer outage of the special job drifts further than the shared 10 s one
    assert t.loc["drive0", "forward_end_h_err_m_max"] > t.loc["drive1", "forward_end_h_err_m_max"]
    # exit status 3 when a job fails
    assert cli_main(["batch", str(campaign / "jobs" / "*.toml"), "--settings",
                     str(campaign / "lab.toml"), "-o", str(out), "--summary-only",
                     "--no-progress"]) == 3
    assert np.isnan(pd.read_csv(out / "batch.csv").set_index("job").loc["broken", "imu_samples"])
    # skipped files are not failures: exit status 0, one line each
    capsys.readouterr()
    code = cli_main(["batch", str(campaign / "jobs" / "log1.toml"),
                     str(campaign / "jobs" / "missing.toml"),
                     str(campaign / "jobs" / "settings_only.toml"), "--settings",
                     str(campaign / "lab.toml"), "-o", str(out), "--summary-only",
                     "--no-progress"])
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    notes = [x for x in lines if x.startswith("skipped ")]
    assert len(notes) == 2 and "missing.toml: data not present" in notes[0]
