"""No data loss (issue 8): an ``insgnss process`` interrupted during its output phase leaves the
complete previous outputs or a set marked INCOMPLETE, never a half-written file under a final
name. The subprocess tests slow the writers down (chunked writes, slow renames) so that the
signal always lands where intended."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from robustness_helpers import SHELL_SIGINT, small_job_text

from insgnss.config import load_job
from insgnss.io.outputset import LOCK_NAME, MARKER, STAGING_PREFIX, OutputSet
from insgnss.pipeline import run_job, write_outputs

CHILD = SHELL_SIGINT + r"""
import os, sys, time
import insgnss.io.native as native
mode = sys.argv[1]
if mode == "slow_write":
    def csv_writer(out, **_):
        text = out.to_csv(float_format="%.15g", na_rep="nan")
        def write(p):
            with open(p, "w") as fh:
                for i in range(0, len(text), 20000):
                    fh.write(text[i:i + 20000])
                    fh.flush()
                    time.sleep(0.02)
        return write
    native.csv_writer = csv_writer
elif mode == "slow_commit":
    _replace = os.replace
    def replace(src, dst):
        _replace(src, dst)
        if ".insgnss-staging-" in str(src):
            time.sleep(0.5)
    os.replace = replace
from insgnss.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _snapshot(folder: Path) -> dict[str, bytes]:
    """The files of an output folder (without the lock file of a run, see test_output_safety)."""
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name != LOCK_NAME}


def _staged(folder: Path) -> list[Path]:
    return [f for d in folder.glob(STAGING_PREFIX + "*") for f in d.rglob("*") if f.is_file()]


def _wait(proc, cond, what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return
        if proc.poll() is not None:
            pytest.fail(f"the run ended before {what}: {proc.stderr.read()}")
        time.sleep(0.01)
    proc.kill()
    pytest.fail(f"timeout waiting for {what}")


@pytest.fixture(scope="module")
def previous(tmp_path_factory):
    """A job file and a complete previous output set (seed 7)."""
    d = tmp_path_factory.mktemp("job")
    job_path = d / "job.toml"
    job_path.write_text(small_job_text())
    out = d / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        write_outputs(run_job(load_job(job_path), progress=False), out)
    return job_path, out, _snapshot(out)


def _child(mode: str, job_path: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", CHILD, mode, "process", str(job_path), "-o",
                             str(out), "--no-progress", "--seed", "8"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _fresh(previous, tmp_path) -> tuple[Path, Path, dict]:
    job_path, out0, snap = previous
    out = tmp_path / "out"
    out.mkdir()
    for name, data in snap.items():
        (out / name).write_bytes(data)
    return job_path, out, snap


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_interrupt_while_writing_keeps_the_previous_outputs(previous, tmp_path, sig):
    job_path, out, snap = _fresh(previous, tmp_path)
    proc = _child("slow_write", job_path, out)
    _wait(proc, lambda: any(f.stat().st_size > 100_000 for f in _staged(out)),
          "a staged file is half written")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    # the final names hold exactly the previous complete set
    assert _snapshot(out) == snap
    assert not (out / MARKER).exists()
    if sig == signal.SIGINT:
        assert proc.returncode == 130 and "interrupted" in err and "Traceback" not in err
        assert not list(out.glob(STAGING_PREFIX + "*"))  # Ctrl-C cleans up after itself
        assert not (out / LOCK_NAME).exists()
    else:
        assert proc.returncode == -signal.SIGKILL
        assert _staged(out)  # the half-written file stays hidden in the staging folder
        assert (out / LOCK_NAME).exists()  # and the lock, now stale
        # the next run removes the leftovers and replaces the set completely
        r = subprocess.run([sys.executable, "-m", "insgnss.cli", "process", str(job_path), "-o",
                            str(out), "--no-progress", "--seed", "8"], capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        assert "stale lock" in r.stderr
        assert not list(out.glob(STAGING_PREFIX + "*")) and not (out / MARKER).exists()
        assert not (out / LOCK_NAME).exists()
        new = _snapshot(out)
        assert set(new) == set(snap) and new["forward.csv"] != snap["forward.csv"]
        assert json.loads(new["summary.json"])["seed"] == 8


def test_kill_while_replacing_leaves_a_marked_set_of_whole_files(previous, tmp_path):
    job_path, out, snap = _fresh(previous, tmp_path)
    proc = _child("slow_commit", job_path, out)
    changed = lambda: (out / MARKER).exists() and any(  # noqa: E731
        (out / n).read_bytes() != snap[n] for n in snap if n != "summary.json")
    _wait(proc, changed, "the commit has replaced a file")
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    marker = (out / MARKER).read_text()
    assert "interrupted" in marker and "forward.csv" in marker
    # every final file is whole: either the previous run's or the new run's
    ref = tmp_path / "ref"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        write_outputs(run_job(load_job(job_path), progress=False, seed=8), ref)
    new = _snapshot(ref)
    now = _snapshot(out)
    n_new = 0
    for name, data in now.items():
        if name in (MARKER, "summary.json"):
            continue
        assert data in (snap[name], new[name]), name
        n_new += data == new[name] != snap[name]
    assert 1 <= n_new < len(snap) - 1
    json.loads(now["summary.json"])  # a whole JSON document either way


def test_output_set_commit_abort_and_stale_files(tmp_path):
    (tmp_path / "old.csv").write_text("previous run\n")
    (tmp_path / "keep.txt").write_text("not an output\n")
    with OutputSet(tmp_path, stale=["old.csv", "a.csv"]) as outs:
        outs.path("a.csv").write_text("a\n")
        outs.path("b.csv").write_text("b\n")
        paths = outs.commit()
    assert sorted(paths) == ["a.csv", "b.csv"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv", "keep.txt"]
    # an exception before the commit leaves the folder as it was
    with pytest.raises(KeyboardInterrupt):
        with OutputSet(tmp_path, stale=["a.csv", "b.csv"]) as outs:
            outs.path("a.csv").write_text("new a\n")
            raise KeyboardInterrupt
    assert (tmp_path / "a.csv").read_text() == "a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv", "keep.txt"]
    # announced but never written: the commit refuses and nothing moves
    with pytest.raises(FileNotFoundError):
        with OutputSet(tmp_path) as outs:
            outs.path("a.csv").write_text("newer a\n")
            outs.path("c.csv")
            outs.commit()
    assert (tmp_path / "a.csv").read_text() == "a\n" and not (tmp_path / MARKER).exists()
    with pytest.raises(ValueError):
        OutputSet(tmp_path).path("../escape.csv")


def test_interrupted_commit_is_marked(tmp_path, monkeypatch):
    (tmp_path / "a.csv").write_text("old a\n")
    (tmp_path / "b.csv").write_text("old b\n")
    calls = []
    real = os.replace

    def replace(src, dst):
        if STAGING_PREFIX in str(src):
            calls.append(dst)
            if len(calls) == 2:
                raise KeyboardInterrupt
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with OutputSet(tmp_path) as outs:
            outs.path("a.csv").write_text("new a\n")
            outs.path("b.csv").write_text("new b\n")
            outs.commit()
    assert (tmp_path / "a.csv").read_text() == "new a\n"
    assert (tmp_path / "b.csv").read_text() == "old b\n"
    assert "interrupted" in (tmp_path / MARKER).read_text()


def test_incomplete_commit_keeps_the_reason(tmp_path):
    with OutputSet(tmp_path) as outs:
        outs.path("forward.csv").write_text("x\n")
        paths = outs.commit(complete=False, reason="the filter stopped at t = 5 s")
    assert MARKER in paths
    text = (tmp_path / MARKER).read_text()
    assert "stopped at t = 5 s" in text and "forward.csv" in text


def test_outputs_never_replace_an_input(tmp_path):
    from insgnss.errors import ConfigError

    src = tmp_path / "forward.csv"
    src.write_text("input\n")
    with pytest.raises(ConfigError, match="refusing to overwrite an input"):
        with OutputSet(tmp_path, protect=[src]) as outs:
            outs.path("forward.csv")
    assert src.read_text() == "input\n"
