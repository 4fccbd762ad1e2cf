"""The compile-ahead helper (insgnss.compile_ahead): its manifest matches the code, it fills
numba's cache in the reverse order of first use and only loads what is cached, and it is
started only on a cold cache with two or more cores."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from insgnss import compile_ahead as ca

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("process", ["strapdown", "foot"])
def test_manifest_matches_the_kernels(process):
    """Every recorded kernel still exists with as many arguments as recorded: a renamed kernel
    or a changed argument list needs a new recording (``python -m insgnss.compile_ahead record
    PROCESS -- CLI ARGS`` with the command in the manifest's ``recorded_with``), else the helper
    silently skips it."""
    from insgnss.job.processes import PROCESSES

    manifest = ca.load_manifest()
    assert process in PROCESSES
    entries = manifest["kernels"][process]
    assert len(entries) >= 15
    resolved = ca.kernel_signatures(process)
    assert len(resolved) == len(entries)
    for (disp, sig), e in zip(resolved, entries, strict=True):
        assert disp.py_func.__qualname__ == e["name"]
        n_params = len(inspect.signature(disp.py_func).parameters)
        assert len(sig) == n_params, (e["module"], e["name"])
    # the heaviest kernels of a filter + smoother run are among them
    names = {e["name"] for e in entries}
    assert {"assemble_output", "propagate_nominal", "discretize"} <= names
    assert names & {"mbf_backward", "_mbf_backward15"}


def test_unknown_entries_are_skipped():
    manifest = {"kernels": {"p": [
        {"module": "insgnss.detect", "name": "no_such_kernel", "args": ["int64"]},
        {"module": "insgnss.detect", "name": "drop_short_runs", "args": ["not_a_type"]},
        {"module": "insgnss.detect", "name": "drop_short_runs",
         "args": ["Array(bool, 1, 'C', False, aligned=True)", "int64"]},
    ]}}
    out = ca.kernel_signatures("p", manifest)
    assert len(out) == 1
    assert out[0][0].py_func.__name__ == "drop_short_runs"
    assert ca.kernel_signatures("absent", manifest) == []


def test_switched_off_or_one_core(monkeypatch):
    monkeypatch.setenv(ca.ENV_SWITCH, "0")
    assert not ca.wanted("strapdown")
    assert ca.start("strapdown") is None
    monkeypatch.delenv(ca.ENV_SWITCH)
    monkeypatch.setattr(ca, "_cores", lambda: 1)
    assert not ca.wanted("strapdown")
    monkeypatch.setattr(ca, "_cores", lambda: 2)
    assert not ca.wanted("no_such_process")


#: the child: compile_backward over three small kernels into an empty cache, twice
CHILD = r"""
import json, sys
from insgnss import compile_ahead as ca
manifest = json.loads(sys.argv[1])
disps = [d for d, _ in ca.kernel_signatures("p", manifest)]
before = [ca.is_cached(d) for d in disps]
wanted_before = ca.wanted("p", manifest)
first = ca.compile_backward("p", manifest)
print(json.dumps({"before": before, "after": [ca.is_cached(d) for d in disps],
                  "first": first, "wanted": ca.wanted("p", manifest),
                  "wanted_before": wanted_before, "cores": ca._cores()}))
"""


def _run_child(manifest: dict, cache: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(REPO))
    env.pop(ca.ENV_SWITCH, None)
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(manifest)], env=env,
                         capture_output=True, text=True, check=True, cwd=REPO)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_helper_fills_the_cache_backward(tmp_path):
    """On an empty cache the helper compiles the kernels last-first and writes them into the
    cache; a second helper finds them there and compiles nothing."""
    arr_b = "Array(bool, 1, 'C', False, aligned=True)"
    arr_f = "Array(float64, 1, 'C', False, aligned=True)"
    manifest = {"kernels": {"p": [
        {"module": "insgnss.detect", "name": "drop_short_runs", "args": [arr_b, "int64"]},
        {"module": "insgnss.detect", "name": "shrink_runs", "args": [arr_b, "int64"]},
        {"module": "insgnss.detect", "name": "hysteresis_decision",
         "args": [arr_f, arr_f, "float64"]},
    ]}}
    if len(ca.kernel_signatures("p", manifest)) != 3:
        pytest.skip("the test's kernels changed their arguments")
    cold = _run_child(manifest, tmp_path / "cache")
    assert cold["before"] == [False, False, False]
    assert cold["wanted_before"] is (cold["cores"] >= 2)  # cold: a run starts the helper
    assert cold["first"] == ["hysteresis_decision", "shrink_runs", "drop_short_runs"]
    assert cold["after"] == [True, True, True]
    assert cold["wanted"] is False  # the last kernel is cached now: no helper for a run
    warm = _run_child(manifest, tmp_path / "cache")
    assert warm["before"] == [True, True, True]
    assert warm["first"] == []  # loaded from the cache, nothing compiled


def test_start_and_stop_the_helper(monkeypatch):
    """The helper is the module run by the same interpreter on the same insgnss; with nothing
    to compile it ends by itself, and stop() of an ended helper is a no-op."""
    monkeypatch.setattr(ca, "wanted", lambda process: True)
    helper = ca.start("no_such_process")
    assert helper is not None
    assert helper.wait(timeout=120) == 0
    ca.stop(helper)
    with ca.compile_ahead("no_such_process") as h:
        assert h is not None
    assert h.poll() is not None  # ended when the block ends
