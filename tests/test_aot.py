"""Ahead-of-time kernels (insgnss/aot.py): the argument check that sends a call to an export or
to numba, the entry wrapper, the source digest, and - with the module built - a first run that
compiles nothing and gives the JIT path's results byte for byte."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from numba.core import types

from insgnss import aot

ROOT = Path(__file__).resolve().parents[1]
F8C2 = types.Array(types.float64, 2, "C")


def check(*sig):
    return aot.argument_check(tuple(sig))


def test_array_check_takes_exactly_the_exported_type():
    c = check(F8C2)
    a = np.zeros((3, 4))
    assert c(a)
    assert not c(a.astype(np.int64))          # dtype: pycc would read the bytes as floats
    assert not c(np.asfortranarray(a))        # layout: C indexing of an F array is wrong
    assert not c(a[:, ::2])                   # strided view
    assert not c(np.zeros(3))                 # dimensions
    assert not c(a.tolist())                  # not an array
    ro = a.copy()
    ro.flags.writeable = False
    assert not c(ro)                          # the export may write into it
    assert check(F8C2.copy(readonly=True))(ro)  # a read-only export takes both
    assert check(F8C2.copy(readonly=True))(a)
    assert check(F8C2.copy(layout="A"))(a[:, ::2])


def test_scalar_checks_follow_numbas_typing():
    f, i, b, n = check(types.float64), check(types.int64), check(types.boolean), \
        check(types.none)
    assert f(1.5) and f(np.float64(1.5))
    assert not f(1) and not f(np.float32(1.5)) and not f(True)
    assert i(3) and i(np.int64(3)) and i(-(2 ** 63))
    assert not i(True) and not i(3.0) and not i(2 ** 63) and not i(np.int32(3))
    assert b(True) and b(np.bool_(False)) and not b(1)
    assert n(None) and not n(0.0)
    assert check(types.float32) is None   # a type no export takes: the JIT path
    assert check(types.UniTuple(types.float64, 2)) is None


def test_omitted_trailing_defaults_become_none_arguments():
    sig = (types.float64, types.Omitted(None), types.Omitted(None))
    assert aot.export_signature(sig) == ((types.float64, types.none, types.none), (None, None))
    assert aot.export_signature((types.Omitted(1.0), types.float64)) == (None, None)
    assert aot.export_signature((types.float64, types.Omitted(2.0))) == (None, None)


@njit
def _twice(x):
    return 2.0 * x


def test_entry_dispatches_by_argument_types_and_numba_sees_the_dispatcher():
    calls = []

    def export(x, pad=None):
        calls.append((x, pad))
        return -1.0

    e = aot.Entry(_twice, [(1, check(types.float64), export, ())])
    assert e(3.0) == -1.0 and calls == [(3.0, None)]   # the export
    assert e(3) == 6                                     # an int: the dispatcher
    assert e(x=3.0) == 6.0                               # keywords: the dispatcher
    assert e.py_func is _twice.py_func and e.__name__ == "_twice"
    padded = aot.Entry(_twice, [(1, check(types.float64), export, (None,))])
    padded(2.0)
    assert calls[-1] == (2.0, None)

    @njit
    def caller(x):
        return e(x) + 1.0   # compiled code calls the dispatcher, not the export

    assert caller(3.0) == 7.0
    assert aot.entry(_twice) is _twice or isinstance(aot.entry(_twice), aot.Entry)


def test_source_digest_follows_the_sources(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "data").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "data" / "compile_ahead.json").write_text("{}")
    d0 = aot.source_digest(pkg)
    assert 0 <= d0 < 2 ** 63 and aot.source_digest(pkg) == d0
    (pkg / "a.py").write_text("x = 2\n")
    assert aot.source_digest(pkg) != d0
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "b.py").write_text("")
    assert aot.source_digest(pkg) != d0


def test_entries_are_the_manifests_kernels_once():
    manifest = {"kernels": {"strapdown": [
        {"module": "m", "name": "f", "args": ["float64"]},
        {"module": "m", "name": "f", "args": ["float64"]},
        {"module": "m", "name": "f", "args": ["int64"]}],
        "foot": [{"module": "m", "name": "f", "args": ["int64"]},
                 {"module": "m", "name": "g", "args": []}],
        "wander": [{"module": "m", "name": "h", "args": []}]}}  # no process of the module
    got = aot.entries(manifest)
    # processes in name order, each entry once
    assert [(e["name"], e["args"]) for e in got] == [
        ("f", ["int64"]), ("g", []), ("f", ["float64"])]


built = aot.status().startswith("used")
needs_module = pytest.mark.skipif(
    not built and os.environ.get("CI") != "true",
    reason=f"insgnss._aot: {aot.status()} (pip install -e . builds it)")


@needs_module
def test_the_module_is_built_and_current():
    """The README's install builds it (CI: a clean clone, so never stale)."""
    assert built, aot.status()


@needs_module
def test_every_kernel_of_the_manifest_is_exported_and_an_entry():
    """A kernel recorded in the manifest but not decorated with ``aot.entry`` would be built
    and never called; one the ahead-of-time compiler left out would compile on first use."""
    from importlib import import_module

    table = aot.table()
    for e in aot.entries():
        key = f"{e['module']}.{e['name']}"
        assert key in table, key
        assert isinstance(getattr(import_module(e["module"]), e["name"]), aot.Entry), key


def _run(args: list[str], out: Path, env: dict) -> None:
    subprocess.run([sys.executable, "-m", "insgnss.cli", *args, "-o", str(out),
                    "--no-progress"], check=True, env=env, cwd=ROOT,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


#: one command per process of the module (aot.PROCESSES): the bundled demo (simulation,
#: alignment, strapdown filter, smoother, evaluation, report), the foot-mounted walk
#: (simulation, stance detection, high-rate ZUPT/ZARU filter, smoother) and the RISS land
#: vehicle (simulation with an odometer, RISS filter, smoother)
FIRST_RUNS = {"strapdown": ["demo"], "foot": ["process", "scenarios/foot_walk.toml"],
              "riss": ["process", "scenarios/land_vehicle_riss.toml"]}


@pytest.mark.slow
@needs_module
@pytest.mark.parametrize("process", sorted(FIRST_RUNS))
def test_first_run_compiles_nothing_and_equals_the_jit_path(tmp_path, process):
    """A run of each process on an empty numba cache: no kernel is compiled (every call finds
    its export), and its trajectories and innovations are byte for byte those of the JIT
    path."""
    assert set(FIRST_RUNS) == set(aot.PROCESSES)
    env = dict(os.environ, PYTHONPATH=str(ROOT), INSGNSS_COMPILE_AHEAD="0",
               NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    _run(FIRST_RUNS[process], tmp_path / "aot", env)
    compiled = sorted(p.name for p in (tmp_path / "cache").rglob("*.nbi"))
    assert compiled == []
    jit = dict(env, INSGNSS_AOT="0")
    del jit["NUMBA_CACHE_DIR"]  # the package's cache (the build filled it)
    _run(FIRST_RUNS[process], tmp_path / "jit", jit)
    for name in ("forward.csv", "smoothed.csv", "innovations.csv", "rejected.csv"):
        assert (tmp_path / "aot" / name).read_bytes() == (tmp_path / "jit" / name).read_bytes()
