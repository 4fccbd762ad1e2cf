"""Ahead-of-time kernels (insgnss/aot.py): the argument check that sends a call to an export or
to numba, the lazy kernel (insgnss/jit.py), the source digest, and - with the module built - a
first run that compiles nothing, imports no numba and gives the JIT path's results byte for
byte."""

import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numba.core import types

from insgnss import aot, jit
from insgnss.kernel_manifest import (
    ArrayArg,
    OmittedArg,
    ScalarArg,
    argument_kinds,
    argument_types,
    numba_types,
    read_only,
    type_namespace,
)

ROOT = Path(__file__).resolve().parents[1]
F8C2 = ArrayArg("float64", 2, "C")
F8, I8, B, NONE = (ScalarArg(n) for n in ("float64", "int64", "bool", "none"))


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
    assert check(*read_only((F8C2,)))(ro)     # a read-only export takes both
    assert check(*read_only((F8C2,)))(a)
    assert check(ArrayArg("float64", 2, "A"))(a[:, ::2])


def test_scalar_checks_follow_numbas_typing():
    f, i, b, n = check(F8), check(I8), check(B), check(NONE)
    assert f(1.5) and f(np.float64(1.5))
    assert not f(1) and not f(np.float32(1.5)) and not f(True)
    assert i(3) and i(np.int64(3)) and i(-(2 ** 63))
    assert not i(True) and not i(3.0) and not i(2 ** 63) and not i(np.int32(3))
    assert b(True) and b(np.bool_(False)) and not b(1)
    assert n(None) and not n(0.0)
    assert check(ScalarArg("float32")) is None   # a type no export takes: the JIT path
    with pytest.raises(NameError):              # one the descriptions do not know
        argument_kinds(["UniTuple(float64, 2)"])


def test_omitted_trailing_defaults_become_none_arguments():
    sig = (F8, OmittedArg(None), OmittedArg(None))
    assert aot.export_signature(sig) == ((F8, NONE, NONE), (None, None))
    assert aot.export_signature((OmittedArg(1.0), F8)) == (None, None)
    assert aot.export_signature((F8, OmittedArg(2.0))) == (None, None)


def test_argument_kinds_are_numbas_types_of_every_recorded_argument():
    """The numba-free reading of the manifest's type strings gives numba's own types back
    (the build compiles them), for every argument the packaged manifest records."""
    from insgnss.kernel_manifest import load_manifest

    recorded = {a for es in load_manifest()["kernels"].values() for e in es for a in e["args"]}
    assert len(recorded) > 10
    ns = type_namespace()
    for a in sorted(recorded):
        assert numba_types(argument_kinds([a])) == argument_types([a], ns), a
    ro = numba_types(read_only(argument_kinds(["Array(float64, 2, 'C', False, aligned=True)"])))
    assert ro == (types.Array(types.float64, 2, "C", readonly=True),)


@jit.njit(cache=False)
def _twice(x):
    return 2.0 * x


def test_entry_dispatches_by_argument_types_and_numba_sees_the_dispatcher():
    calls = []

    def export(x, pad=None):
        calls.append((x, pad))
        return -1.0

    e = jit.Kernel(_twice.py_func)
    e.exports = ((1, check(F8), export, ()),)
    assert e(3.0) == -1.0 and calls == [(3.0, None)]   # the export
    assert e.loaded is None                              # no dispatcher made for it
    assert e(3) == 6                                     # an int: the dispatcher
    assert e.loaded is not None and len(e.signatures) == 1
    assert e(x=3.0) == 6.0                               # keywords: the dispatcher
    assert e.py_func is _twice.py_func and e.__name__ == "_twice"
    padded = jit.Kernel(_twice.py_func)
    padded.exports = ((1, check(F8), export, (None,)),)
    padded(2.0)
    assert calls[-1] == (2.0, None)

    @numba.njit
    def caller(x):
        return e(x) + 1.0   # compiled code calls the dispatcher, not the export

    assert caller(3.0) == 7.0
    assert isinstance(aot.entry(_twice), jit.Kernel)
    wrapped = aot.entry(numba.njit(lambda x: x + 1.0))  # a numba dispatcher: a Kernel of it
    assert isinstance(wrapped, jit.Kernel) and wrapped(1.0) == 2.0


def test_kernel_pickles_by_name_and_is_its_dispatcher_for_numba():
    import pickle

    from insgnss.filter import kalman

    k = kalman._predict
    assert isinstance(k, jit.Kernel)
    assert pickle.loads(pickle.dumps(k)) is k
    assert not hasattr(k, "__array_interface__")  # introspection does not load numba's side
    assert "insgnss.filter.kalman._predict" in repr(k)


def test_a_run_on_exports_imports_no_numba(tmp_path):
    """With the module built, a run whose kernels are all exported (the bundled demo's job)
    never imports numba: the 0.2 s of its import and of making the dispatchers are saved."""
    if not aot.status().startswith("used"):
        pytest.skip(f"insgnss._aot: {aot.status()}")
    probe = ("import sys\nfrom insgnss.cli import main\nrc = main(sys.argv[1:])\n"
             "print('NUMBA', 'numba' in sys.modules)\nsys.exit(rc)\n")
    (tmp_path / "probe.py").write_text(probe)
    r = subprocess.run([sys.executable, "probe.py", "demo", "-o", "out", "--no-progress"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=600,
                       env=dict(os.environ, INSGNSS_COMPILE_AHEAD="0"))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "NUMBA False" in r.stdout, r.stdout[-2000:]


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
        assert getattr(import_module(e["module"]), e["name"]).exports, key


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
