"""Output safety (issue 12, items 1, 4, 5): a run never deletes, moves or changes one of its
inputs; every unusable output location is an InsgnssError (exit 2) before any computation;
an output folder is locked while a run uses it."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from job_helpers import recorded_job_text, simulate_recording
from robustness_helpers import small_job_text

from insgnss.cli import main
from insgnss.config import load_job
from insgnss.errors import ConfigError, InsgnssError, InsgnssWarning
from insgnss.io.outputset import (
    LOCK_NAME,
    MARKER,
    STAGING_PREFIX,
    OutputBusyError,
    OutputSet,
    check_output_location,
    lock_output_folder,
)

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return simulate_recording(tmp_path_factory.mktemp("rec") / "data")


# --- item 1: never delete an input ---------------------------------------------------------------
def test_commit_keeps_an_input_that_has_a_stale_output_name(tmp_path):
    ref = tmp_path / "smoothed.csv"
    ref.write_text("the reference, an input\n")
    with pytest.warns(InsgnssWarning, match="input"):
        with OutputSet(tmp_path, protect=[ref], stale=["smoothed.csv", "forward.csv"]) as outs:
            outs.path("forward.csv").write_text("new\n")
            outs.commit()
    assert ref.read_text() == "the reference, an input\n"
    assert (tmp_path / "forward.csv").read_text() == "new\n"


@pytest.mark.parametrize("how", ["relative", "symlinked_folder", "symlinked_file", "hard_link"])
def test_commit_recognises_an_input_however_it_is_named(tmp_path, monkeypatch, how):
    data = tmp_path / "data"
    data.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    if how == "relative":  # the job names it relative to another folder
        victim = out / "smoothed.csv"
        victim.write_text("input\n")
        monkeypatch.chdir(data)
        protect = Path("..") / "out" / ".." / "out" / "smoothed.csv"
    elif how == "symlinked_folder":  # the output folder is reached through a link
        victim = out / "smoothed.csv"
        victim.write_text("input\n")
        (tmp_path / "link").symlink_to(out)
        protect = tmp_path / "link" / "smoothed.csv"
    elif how == "symlinked_file":  # the input path is a link that lives in the output folder
        victim = data / "ref.csv"
        victim.write_text("input\n")
        (out / "smoothed.csv").symlink_to(victim)
        protect = out / "smoothed.csv"
    else:  # the same file under two names
        victim = data / "ref.csv"
        victim.write_text("input\n")
        os.link(victim, out / "smoothed.csv")
        protect = victim
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with OutputSet(out, protect=[protect], stale=["smoothed.csv"]) as outs:
            outs.path("forward.csv").write_text("new\n")
            outs.commit()
    assert victim.read_text() == "input\n"
    assert (out / "smoothed.csv").exists()


def test_write_outputs_keeps_the_reference_stored_under_an_output_name(recording, tmp_path):
    """The issue's case: ``[inputs.reference] path = "out/smoothed.csv"``, ``smoother =
    false``, outputs to ``out/``: exited 0 and deleted the reference."""
    from insgnss.pipeline import run_job, write_outputs

    out = tmp_path / "out"
    out.mkdir()
    shutil.copy(recording / "truth.csv", out / "smoothed.csv")
    before = (out / "smoothed.csv").read_bytes()
    job_file = tmp_path / "job.toml"
    job_file.write_text(recorded_job_text(recording, reference="out/smoothed.csv",
                                          filter="smoother = false"))
    job = load_job(job_file)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(job, progress=False)
        write_outputs(res)
    assert (out / "smoothed.csv").read_bytes() == before
    assert (out / "forward.csv").exists() and (out / "summary.json").exists()


def test_process_refuses_that_folder_before_computing(recording, tmp_path, monkeypatch,
                                                       capsys):
    out = tmp_path / "out"
    out.mkdir()
    shutil.copy(recording / "truth.csv", out / "smoothed.csv")
    before = (out / "smoothed.csv").read_bytes()
    job_file = tmp_path / "job.toml"
    job_file.write_text(recorded_job_text(recording, reference="out/smoothed.csv",
                                          filter="smoother = false"))
    _no_computation(monkeypatch)
    assert main(["process", str(job_file), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "smoothed.csv" in err and "input" in err and "Traceback" not in err
    assert (out / "smoothed.csv").read_bytes() == before


# --- item 4: every unusable output location and bad value: exit 2 before computing ------------
def _no_computation(monkeypatch):
    import insgnss.pipeline as pl

    def computing(*a, **k):
        raise AssertionError("the computation started")

    monkeypatch.setattr(pl, "run_job", computing)
    monkeypatch.setattr(pl, "load_inputs", computing)


@pytest.fixture
def sim_job(tmp_path):
    f = tmp_path / "job.toml"
    f.write_text(small_job_text())
    return f


@pytest.mark.parametrize("lines,key", [
    ('[filter]\nimu_grade = "bogus"\n', "filter.imu_grade"),
    ("[outages.periodic]\nstart = 10.0\nlength = 0.0\ngap = 5.0\n", "outages.periodic.length"),
    ("[outages]\nwindows = [[30.0, 40.0, 50.0]]\n", "outages.windows"),
    ("[outages.periodic]\nstart = 10.0\nlength = 1e-7\ngap = 0.0\n", "outages.periodic.gap"),
])
def test_process_job_value_errors_exit_2_before_computing(tmp_path, monkeypatch, capsys,
                                                          lines, key):
    f = tmp_path / "job.toml"
    f.write_text(small_job_text() + lines)
    _no_computation(monkeypatch)
    assert main(["process", str(f), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert key in err and str(f) in err and "Traceback" not in err


def test_output_path_that_is_a_file(sim_job, tmp_path, monkeypatch, capsys):
    target = tmp_path / "result.csv"
    target.write_text("not a folder\n")
    _no_computation(monkeypatch)
    for args in (["process", str(sim_job), "-o", str(target)],
                 ["process", str(sim_job), "-o", str(target / "sub")],
                 ["demo", "-o", str(target)],
                 ["compare", str(sim_job), "-o", str(target)],
                 ["montecarlo", str(sim_job), "--runs", "2", "-o", str(target)],
                 ["batch", str(sim_job), "-o", str(target)]):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert "result.csv" in err and "not a folder" in err and "Traceback" not in err, args
    assert target.read_text() == "not a folder\n"


def test_output_pointing_at_an_input_file(recording, tmp_path, monkeypatch, capsys):
    job_file = tmp_path / "job.toml"
    job_file.write_text(recorded_job_text(recording))
    imu = recording / "imu.csv"
    before = imu.stat().st_mtime_ns, imu.stat().st_size
    _no_computation(monkeypatch)
    assert main(["process", str(job_file), "-o", str(imu)]) == 2
    err = capsys.readouterr().err
    assert "imu.csv" in err and "input" in err and "Traceback" not in err
    assert (imu.stat().st_mtime_ns, imu.stat().st_size) == before
    assert main(["process", str(job_file), "-o", str(job_file)]) == 2  # the job file too
    assert "input" in capsys.readouterr().err


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder this process cannot write: chmod 0555, or for root (who writes anywhere) a
    sysfs folder, which even root cannot create files in."""
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        yield ro
        ro.chmod(0o755)
        return
    ro = Path("/sys/kernel")
    try:
        os.close(os.open(ro / ".insgnss-probe", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except OSError:
        yield ro
        return
    os.unlink(ro / ".insgnss-probe")
    pytest.skip("no folder that root cannot write")


def test_read_only_output_folder_is_found_before_computing(read_only_folder, sim_job,
                                                           monkeypatch, capsys):
    with pytest.raises(InsgnssError, match="not writable") as exc:
        check_output_location(read_only_folder)
    assert str(read_only_folder) in str(exc.value)
    with pytest.raises(InsgnssError, match="cannot create"):
        check_output_location(read_only_folder / "new")
    _no_computation(monkeypatch)
    assert main(["process", str(sim_job), "-o", str(read_only_folder)]) == 2
    err = capsys.readouterr().err
    assert "not writable" in err and "Traceback" not in err


def test_check_output_location_creates_a_usable_folder(tmp_path):
    out = check_output_location(tmp_path / "a" / "b")
    assert out.is_dir() and not list(out.iterdir())  # the write probe leaves nothing
    with pytest.raises(ConfigError, match="input"):
        check_output_location(tmp_path / "a", protect=[tmp_path / "a"])


# --- item 5: one run per output folder ---------------------------------------------------------
HOLD = r"""
import sys, time
from insgnss.io.outputset import lock_output_folder
with lock_output_folder(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def _holder(folder: Path, seconds: float) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(folder), str(seconds)],
                         stdout=subprocess.PIPE, text=True, env=ENV)
    assert p.stdout.readline().strip() == "locked"
    return p


def test_second_holder_is_refused_with_pid_and_start_time(tmp_path):
    p = _holder(tmp_path, 30)
    try:
        with pytest.raises(OutputBusyError) as exc:
            with lock_output_folder(tmp_path):
                pass
        msg = str(exc.value)
        assert f"in use by pid {p.pid} since" in msg and str(tmp_path) in msg
        assert isinstance(exc.value, InsgnssError)
        # an OutputSet in that folder is refused as well and touches nothing
        (tmp_path / "forward.csv").write_text("theirs\n")
        with pytest.raises(OutputBusyError):
            OutputSet(tmp_path, stale=["forward.csv"])
        assert (tmp_path / "forward.csv").read_text() == "theirs\n"
    finally:
        p.kill()
        p.wait()


def test_wait_for_the_folder(tmp_path):
    p = _holder(tmp_path, 1.5)
    t0 = time.monotonic()
    with pytest.warns(InsgnssWarning, match="waiting"):
        with lock_output_folder(tmp_path, wait=True, poll=0.05):
            assert time.monotonic() - t0 > 1.0  # the holder kept it for 1.5 s
            assert json.loads((tmp_path / LOCK_NAME).read_text())["pid"] == os.getpid()
    p.wait()
    assert not (tmp_path / LOCK_NAME).exists()


def test_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    import socket

    (tmp_path / LOCK_NAME).write_text(json.dumps(
        {"pid": int(dead), "host": socket.gethostname(), "started": "2024-01-01T00:00:00"}))
    with pytest.warns(InsgnssWarning, match=f"stale lock.*pid {dead}"):
        with lock_output_folder(tmp_path):
            info = json.loads((tmp_path / LOCK_NAME).read_text())
            assert info["pid"] == os.getpid()
    assert not (tmp_path / LOCK_NAME).exists()


def test_lock_is_reentrant_in_one_process(tmp_path):
    with lock_output_folder(tmp_path):
        with OutputSet(tmp_path) as outs:  # the command holds the lock; the set reuses it
            outs.path("a.csv").write_text("a\n")
            outs.commit()
        assert (tmp_path / LOCK_NAME).exists()
    assert not (tmp_path / LOCK_NAME).exists() and (tmp_path / "a.csv").exists()


def _snapshot_ok(out: Path) -> dict:
    names = sorted(p.name for p in out.iterdir())
    assert MARKER not in names and not [n for n in names if n.startswith(STAGING_PREFIX)]
    assert LOCK_NAME not in names
    s = json.loads((out / "summary.json").read_text())
    assert sorted(s["files"]) == sorted(n for n in names)  # one whole set, nothing else
    return s


@pytest.mark.parametrize("wait", [False, True])
def test_two_process_runs_half_a_second_apart(tmp_path, sim_job, wait):
    """Must show: two ``insgnss process`` runs started 0.5 s apart on one folder: no
    traceback, one whole set."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "insgnss.cli", "process", str(sim_job), "-o", str(out),
           "--no-progress"] + (["--wait"] if wait else [])
    t0 = time.monotonic()
    first = subprocess.Popen(cmd + ["--seed", "1"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=ENV)
    # half a second, and the first holds the folder: on a loaded machine its start-up alone
    # can take longer, and a second run started before it would simply come first
    while not (out / LOCK_NAME).exists() and first.poll() is None \
            and time.monotonic() - t0 < 60:
        time.sleep(0.01)
    time.sleep(max(0.0, 0.5 - (time.monotonic() - t0)))
    second = subprocess.Popen(cmd + ["--seed", "2"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=ENV)
    r1, r2 = first.communicate(timeout=600), second.communicate(timeout=600)
    for _, err in (r1, r2):
        assert "Traceback" not in err, err
    s = _snapshot_ok(out)
    if wait:
        assert first.returncode == 0 and second.returncode == 0, (r1[1], r2[1])
        waited = [seed for seed, (_, err) in ((1, r1), (2, r2)) if "waiting" in err]
        assert len(waited) == 1, (r1[1], r2[1])
        assert s["seed"] == waited[0]  # the run that waited replaced the set as a whole
    else:
        codes = sorted([first.returncode, second.returncode])
        assert codes == [0, 2], (r1[1], r2[1])
        loser = r2 if second.returncode == 2 else r1
        assert "in use by pid" in loser[1] and str(out) in loser[1]
