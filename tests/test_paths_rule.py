"""One path rule for every command (docs/jobs.md, "Paths"): command-line paths are relative to
the current folder, paths inside a job file relative to the job file."""

from __future__ import annotations

from robustness_helpers import small_job_text

from insgnss.cli import main


def test_process_paths(tmp_path, monkeypatch, capsys):
    jobs = tmp_path / "jobs"
    jobs.mkdir()
    (jobs / "job.toml").write_text(small_job_text(outputs='dir = "results"'))
    here = tmp_path / "elsewhere"
    here.mkdir()
    monkeypatch.chdir(here)
    # the job's [outputs] dir: beside the job file, wherever the command runs
    assert main(["process", "../jobs/job.toml", "--no-progress", "--no-report"]) == 0
    assert (jobs / "results" / "summary.json").exists()
    assert not (here / "results").exists()
    assert str(jobs / "results") in capsys.readouterr().out  # says where it wrote
    # -o on the command line: under the current folder
    assert main(["process", "../jobs/job.toml", "-o", "mine", "--no-progress",
                 "--no-report"]) == 0
    assert (here / "mine" / "summary.json").exists() and not (jobs / "mine").exists()
