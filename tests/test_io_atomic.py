"""No data loss: a writer killed mid-write leaves no partial file under the final name."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

CHILD = r"""
import sys
import numpy as np
import pandas as pd
from insgnss.io import {writer}

n = int(sys.argv[2])
cols = ["lat", "lon", "height", "vel_e", "vel_n", "vel_u", "roll", "pitch", "heading"]
df = pd.DataFrame(np.random.default_rng(0).random((n, 9)), columns=cols,
                  index=pd.Index(1.4e9 + 0.01 * np.arange(n), name="time"))
print("writing", flush=True)
{writer}(df, sys.argv[1])
print("done", flush=True)
"""


def _tmp_files(folder: Path, name: str):
    return [p for p in folder.iterdir() if p.name.startswith(f".{name}.") and p.name.endswith(".tmp")]


def _run_and_interrupt(tmp_path, writer, sig, n=300_000, timeout=60.0):
    target = tmp_path / "out.csv"
    proc = subprocess.Popen([sys.executable, "-c", CHILD.format(writer=writer), str(target), str(n)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:  # wait until the temporary file has data
            tmp = _tmp_files(tmp_path, target.name)
            if tmp and tmp[0].stat().st_size > 100_000:
                break
            time.sleep(0.01)
        else:
            pytest.fail("the writer never started writing")
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "done" not in out, "the write finished before the signal: test inconclusive"
    return target


def test_sigkill_mid_write_leaves_no_partial_final_file(tmp_path):
    target = _run_and_interrupt(tmp_path, "write_trajectory_csv", signal.SIGKILL)
    assert not target.exists()
    # what is left is only the clearly named temporary file
    assert all(p.name.startswith(".out.csv.") and p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_sigkill_keeps_the_previous_complete_file(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("time,lat_deg\n1.0,40.0\n")
    before = target.read_bytes()
    _run_and_interrupt(tmp_path, "write_trajectory_csv", signal.SIGKILL)
    assert target.read_bytes() == before


def test_ctrl_c_removes_the_temporary_file(tmp_path):
    target = _run_and_interrupt(tmp_path, "write_trajectory_csv", signal.SIGINT)
    assert not target.exists()
    assert _tmp_files(tmp_path, target.name) == []
