"""No data loss: a writer killed mid-write leaves no partial file under the final name.

The deterministic tests drive ``atomic_write`` (which every writer uses) with a slow, chunked
write function so that the kill always lands mid-write; one test kills the real trajectory
writer on a large table as soon as its temporary file appears.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from robustness_helpers import SHELL_SIGINT

SLOW_CHILD = SHELL_SIGINT + r"""
import sys, time
from insgnss.io.native import atomic_write

def slow(path):
    with open(path, "w") as fh:
        for _ in range(500):
            fh.write("x" * 10000 + "\n")
            fh.flush()
            time.sleep(0.01)

print("writing", flush=True)
atomic_write(sys.argv[1], slow)
print("done", flush=True)
"""

TRAJ_CHILD = r"""
import sys
import numpy as np
import pandas as pd
from insgnss.io import write_trajectory_csv

n = int(sys.argv[2])
cols = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]
df = pd.DataFrame(np.random.default_rng(0).random((n, 9)), columns=cols,
                  index=pd.Index(1.4e9 + 0.01 * np.arange(n), name="time"))
print("writing", flush=True)
write_trajectory_csv(df, sys.argv[1])
print("done", flush=True)
"""


def _tmp_files(folder: Path, name: str):
    return [p for p in folder.iterdir() if p.name.startswith(f".{name}.") and p.name.endswith(".tmp")]


def _start(script: str, *args) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", script, *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing", proc.stderr.read()
    return proc


def _wait_for_tmp(proc, folder: Path, name: str, min_size: int, timeout: float = 60.0) -> bool:
    """True once the temporary file has ``min_size`` bytes; False if the writer finished."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        tmp = _tmp_files(folder, name)
        if tmp:
            try:
                if tmp[0].stat().st_size >= min_size:
                    return True
            except FileNotFoundError:  # renamed in the meantime
                pass
        if proc.poll() is not None:
            return False
        time.sleep(0.005)
    pytest.fail("the writer never started writing")


def _finish(proc) -> str:
    try:
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return out


def test_sigkill_mid_write_leaves_no_partial_final_file(tmp_path):
    target = tmp_path / "out.csv"
    proc = _start(SLOW_CHILD, target)
    assert _wait_for_tmp(proc, tmp_path, target.name, 200_000)
    proc.send_signal(signal.SIGKILL)
    assert "done" not in _finish(proc)
    assert not target.exists()
    # what is left is only the clearly named temporary file
    left = list(tmp_path.iterdir())
    assert len(left) == 1 and left[0].name.startswith(".out.csv.") and left[0].name.endswith(".tmp")
    assert left[0].stat().st_size >= 200_000


def test_sigkill_keeps_the_previous_complete_file(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("time,lat_deg\n1.0,40.0\n")
    before = target.read_bytes()
    proc = _start(SLOW_CHILD, target)
    assert _wait_for_tmp(proc, tmp_path, target.name, 200_000)
    proc.send_signal(signal.SIGKILL)
    assert "done" not in _finish(proc)
    assert target.read_bytes() == before


def test_ctrl_c_removes_the_temporary_file(tmp_path):
    target = tmp_path / "out.csv"
    proc = _start(SLOW_CHILD, target)
    assert _wait_for_tmp(proc, tmp_path, target.name, 200_000)
    proc.send_signal(signal.SIGINT)
    _finish(proc)
    assert proc.returncode != 0
    assert not target.exists() and _tmp_files(tmp_path, target.name) == []


def test_sigkill_of_the_trajectory_writer(tmp_path):
    """Kill the real writer as soon as its temporary file exists: no partial final file. If the
    write won the race, the final file must be complete."""
    n = 400_000
    target = tmp_path / "traj.csv"
    proc = _start(TRAJ_CHILD, target, n)
    mid_write = _wait_for_tmp(proc, tmp_path, target.name, 0)
    if mid_write:
        proc.send_signal(signal.SIGKILL)
    out = _finish(proc)
    if "done" in out:
        assert sum(1 for _ in target.open()) == n + 1
    else:
        assert not target.exists()


def test_atomic_write_gives_the_usual_file_mode(tmp_path):
    import os

    from insgnss.io.native import atomic_write_text

    umask = os.umask(0)
    os.umask(umask)
    p = atomic_write_text(tmp_path / "out.txt", "x")
    assert os.stat(p).st_mode & 0o777 == 0o666 & ~umask
