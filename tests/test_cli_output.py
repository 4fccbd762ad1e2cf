"""What the command line prints: warnings one line each without Python source lines, and a
progress bar that starts after the compiled kernels are ready (its ETA measures the filter,
not the numba compiler). Both run in a fresh interpreter, where nothing is compiled or loaded
from the numba cache yet."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from example_data import generate_for
from robustness_helpers import small_job_text

REPO = Path(__file__).resolve().parents[1]

#: runs the CLI and reports the numba dispatchers compiled (or loaded from the cache) while
#: the filter runs with its progress bar
PROBE = r'''
import json, sys
from insgnss.jit import Kernel
import insgnss.job.processes as P

def compiled():
    return {f"{n}.{k}": len(v.loaded.signatures) for n, m in list(sys.modules.items())
            if n.startswith("insgnss") for k, v in vars(m).items()
            if isinstance(v, Kernel) and v.loaded is not None}

real, seen = P.run_filter, {}
def wrapped(*a, progress=False, **kw):
    if progress:
        seen["before"] = compiled()
    r = real(*a, progress=progress, **kw)
    if progress:
        seen["after"] = compiled()
    return r
P.run_filter = wrapped
from insgnss.cli import main
code = main(sys.argv[1:])
b = seen["before"]
print("GREW " + json.dumps({k: v for k, v in seen["after"].items() if v > b.get(k, 0)}))
sys.exit(code)
'''


def _env():
    import os

    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_progress_bar_starts_after_compilation(tmp_path):
    job = small_job_text().replace("report = false\nprogress = false",
                                   "report = false\nprogress = true")
    (tmp_path / "job.toml").write_text(job)
    (tmp_path / "probe.py").write_text(PROBE)
    r = subprocess.run([sys.executable, "probe.py", "process", "job.toml", "-o", "out"],
                       cwd=tmp_path, capture_output=True, text=True, env=_env(), timeout=600)
    assert r.returncode == 0, r.stderr
    line = next(x for x in r.stdout.splitlines() if x.startswith("GREW "))
    assert json.loads(line[5:]) == {}  # nothing compiled under the bar
    assert "filter" in r.stderr and "epoch" in r.stderr  # the bar was shown


def test_warnings_without_source_lines(tmp_path):
    base = {"inputs": {"imu": {"format": "native", "path": "imu.csv"},
                       "gnss": {"format": "native", "path": "gnss.csv"}},
            "initialization": {"method": "static", "static_duration": 20.0},
            "outputs": {"report": False, "progress": False}}
    job, _ = generate_for(base, tmp_path)
    imu = tmp_path / "imu.csv"
    lines = imu.read_text().splitlines()
    imu.write_text("\n".join(lines[:100] + [lines[99]] + lines[100:]) + "\n")  # a repeated row
    (tmp_path / "job.toml").write_text(
        '[inputs.imu]\nformat = "native"\npath = "imu.csv"\n'
        '[inputs.gnss]\nformat = "native"\npath = "gnss.csv"\n'
        '[initialization]\nmethod = "static"\nstatic_duration = 20.0\n'
        '[outputs]\nreport = false\nprogress = false\n')
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "process", "job.toml", "-o", "out"],
                       cwd=tmp_path, capture_output=True, text=True, env=_env(), timeout=600)
    assert r.returncode == 0, r.stderr
    warn = [x for x in r.stderr.splitlines() if "warning" in x]
    assert warn and all(x.startswith("insgnss process: warning: ") for x in warn), r.stderr
    assert any("duplicated time stamp" in x and "imu.csv" in x for x in warn)
    assert ".py:" not in r.stderr and "warn(" not in r.stderr  # no Python file, no source line
    assert len(warn) == len(set(warn))  # each said once


def test_a_warning_is_printed_once_per_command():
    """The same warning from two places of one run (an initialization repeated with the
    measured noise) is one line; another message, or another command, is printed."""

    from insgnss.cli import _warning_printer
    from insgnss.errors import InsgnssWarning

    fmt = _warning_printer("process")
    first = fmt(InsgnssWarning("no gyrocompassing"), InsgnssWarning, "a.py", 1)
    assert first == "insgnss process: warning: no gyrocompassing\n"
    assert fmt(InsgnssWarning("no gyrocompassing"), InsgnssWarning, "b.py", 9) == ""
    assert fmt("other", UserWarning, "a.py", 1) == "insgnss process: warning (UserWarning): other\n"
    assert _warning_printer("process")("no gyrocompassing", InsgnssWarning, "a.py", 1) == first
