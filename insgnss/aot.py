"""Ahead-of-time kernels: the run's numba kernels compiled when the package is installed.

numba compiles a kernel on its first call in a process and keeps the machine code in its on-disk
cache; a run on an empty cache (the first run after an install or an upgrade, or any run with a
fresh ``NUMBA_CACHE_DIR``) spends 30-40 s compiling about 90 functions before it computes
anything (docs/filter.md, "First run"). Here the same kernels are compiled once more, by
numba's ahead-of-time compiler (``numba.pycc``), into the extension module ``insgnss._aot``
when the package is built (``setup.py``: ``pip install .`` or ``pip install -e .``), so that a
run calls machine code that is already there:

- **which kernels**: every entry of the compile-ahead manifest (``insgnss/data/
  compile_ahead.json``, :mod:`insgnss.compile_ahead`), the kernels a run calls from Python with
  the argument types it calls them with, recorded per process; each ``(kernel, argument
  types)`` is exported once (:func:`entries`). A kernel's callees are compiled into it.
- **how a call finds it**: the kernels of the manifest are decorated with :func:`entry`, which
  attaches the module's exports of it to the :class:`insgnss.jit.Kernel`. A call from Python
  whose arguments have exactly an export's types (array dtype, dimensions and layout; a
  writable array where the export may write; Python or NumPy floats, ints and bools where
  those are expected: :func:`argument_check`) runs the export; any other call goes to the
  numba dispatcher as before (compiled or loaded from the cache on first use). numba-compiled
  code that calls the kernel sees the dispatcher itself, so the JIT path is unchanged.
- **no numba at run time**: the recorded argument types are read without numba
  (:func:`insgnss.kernel_manifest.argument_kinds`), and a kernel makes its numba dispatcher
  only when a call needs it (:mod:`insgnss.jit`): a run whose calls all have exports never
  imports numba (0.2 s of its start).
- **the same code**: the module records a digest of the package's Python sources and of the
  manifest (:func:`source_digest`) when it is built; a module whose digest differs from the
  sources beside it (an edited checkout not rebuilt) is not used. The exports are compiled by
  the same numba as the JIT kernels, for the build machine's CPU (as the JIT compiles for the
  machine it runs on): the results are those of the JIT path, bit for bit on the test jobs
  (tests/test_aot.py).
- **off switch**: ``INSGNSS_AOT=0`` in the environment uses the numba dispatchers only (at
  build time: builds no module). A build that fails (no C compiler, no Python headers) leaves
  the package without the module: every call takes the JIT path, as before.

:func:`status` says whether the module is used and why not.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from .jit import Kernel
from .kernel_manifest import ArrayArg, OmittedArg, ScalarArg, argument_kinds, numba_types, read_only

#: the extension module built by setup.py (:func:`compiler`)
MODULE = "insgnss._aot"
#: environment variable that turns the ahead-of-time kernels off ("0"), at build and at run time
ENV_SWITCH = "INSGNSS_AOT"
#: environment variable: the CPU the build compiles for (default the build machine's, "host";
#: "generic" for a module that runs on any CPU of the architecture, e.g. a wheel to distribute)
ENV_CPU = "INSGNSS_AOT_CPU"

_PACKAGE = Path(__file__).resolve().parent
#: the processes whose manifest kernels are exported (the wander-azimuth frame has no recorded
#: manifest: their kernels are compiled by numba on first use)
PROCESSES = ("strapdown", "foot", "riss")


def source_digest(root: Path = _PACKAGE) -> int:
    """A 63-bit digest of the package's Python sources and its compile-ahead manifest (their
    paths and bytes): the code the exports were compiled from."""
    h = hashlib.sha256()
    files = sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)
    files.append(root / "data" / "compile_ahead.json")
    for p in files:
        try:
            data = p.read_bytes()
        except OSError:
            data = b""
        h.update(p.relative_to(root).as_posix().encode())
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return int.from_bytes(h.digest()[:8], "little") >> 1


def entries(manifest: dict | None = None) -> list[dict]:
    """Manifest entries (``{"module", "name", "args"}``) of every process, each ``(module,
    name, args)`` once, in the manifest's order of processes and entries: export ``k{i}`` of
    the module is entry ``i``."""
    from .kernel_manifest import entry_key, load_manifest

    manifest = load_manifest() if manifest is None else manifest
    out, seen = [], set()
    for process in sorted(set(manifest.get("kernels", {})) & set(PROCESSES)):
        for e in manifest["kernels"][process]:
            key = entry_key(e)
            if key not in seen:
                seen.add(key)
                out.append({"module": e["module"], "name": e["name"], "args": list(e["args"])})
    return out


# --- the argument check of an export --------------------------------------------------------------

def _condition(t, a: str) -> str | None:
    """Python expression true when argument ``a`` has the type ``t``
    (:func:`insgnss.kernel_manifest.argument_kinds`) exactly as numba's dispatcher would type
    it (None: a type the exports do not take)."""
    if isinstance(t, ArrayArg):
        if t.layout not in "CFA":
            return None
        # a dtype compares fastest by identity with numpy's canonical instance (a third of the
        # time of ``== "float64"``), equal but other instances (byte order spelt out) after it
        dt = f"dtype_{t.dtype}"
        cond = [f"type({a}) is ndarray", f"({a}.dtype is {dt} or {a}.dtype == {dt})",
                f"{a}.ndim == {t.ndim}"]
        flags = []
        if t.layout == "C":
            flags.append("c_contiguous")
        elif t.layout == "F":
            flags.append("f_contiguous")
        if t.aligned:
            flags.append("aligned")
        if not t.readonly:  # the export may write into it: a read-only array takes the JIT path
            flags.append("writeable")
        if flags:  # one flags object (each ``.flags`` makes a new one)
            cond += [f"(f := {a}.flags).{flags[0]}"] + [f"f.{f}" for f in flags[1:]]
        return " and ".join(cond)
    if not isinstance(t, ScalarArg):
        return None
    if t.name == "float64":
        return f"(type({a}) is float or type({a}) is float64)"
    if t.name == "int64":
        return (f"((type({a}) is int and -9223372036854775808 <= {a} <= 9223372036854775807)"
                f" or type({a}) is int64)")
    if t.name == "bool":
        return f"(type({a}) is bool or type({a}) is bool_)"
    if t.name == "none":
        return f"{a} is None"
    return None


def export_signature(sig: tuple) -> tuple[tuple, tuple]:
    """``(types the export takes, defaults)``: the trailing arguments a call left out
    (``omitted(default=None)``) become ``none`` arguments of the export, which the call's
    defaults fill (``defaults``: the values appended to the call's arguments); other omitted
    arguments are not exported (None)."""
    n = len(sig)
    while n and isinstance(sig[n - 1], OmittedArg):
        n -= 1
    pad = tuple(t.default for t in sig[n:])
    if any(isinstance(t, OmittedArg) for t in sig[:n]) or any(v is not None for v in pad):
        return None, None
    return tuple(sig[:n]) + (ScalarArg("none"),) * len(pad), pad


def _export_types(e: dict) -> tuple:
    """``(recorded types, export types, defaults)`` of manifest entry ``e``
    (:func:`insgnss.kernel_manifest.argument_kinds`, :func:`export_signature`); export types
    None where no export can take the entry. Raises for a type no export takes."""
    sig = argument_kinds(e["args"])
    args, pad = export_signature(sig)
    if args is not None and argument_check(args) is None:
        args = None
    return sig, args, pad


def argument_check(sig: tuple):
    """A function of ``len(sig)`` positional arguments that is true when their types are
    ``sig`` (:func:`_condition`); None when an argument type is not one an export takes."""
    import numpy as np

    names = [f"a{k}" for k in range(len(sig))]
    conds = [_condition(t, a) for t, a in zip(sig, names, strict=True)]
    if any(c is None for c in conds):
        return None
    body = " and ".join(conds) if conds else "True"
    ns = {"ndarray": np.ndarray, "float64": np.float64, "int64": np.int64, "bool_": np.bool_}
    ns.update({f"dtype_{t.dtype}": np.dtype(t.dtype) for t in sig if isinstance(t, ArrayArg)})
    exec(f"def check({', '.join(names)}):\n    return {body}\n", ns)  # noqa: S102
    return ns["check"]


# --- the exports at run time ----------------------------------------------------------------------

_TABLE: dict | None = None
_STATUS = "not loaded"


def _load() -> dict:
    """``{"module.name": [(n_args, check, export, defaults), ...]}`` of the built module, or
    ``{}`` (:func:`status` says why); ``check`` takes the ``n_args`` arguments a call gives,
    ``defaults`` are appended to them for the export."""
    global _STATUS
    if os.environ.get(ENV_SWITCH, "1") == "0":
        _STATUS = f"off ({ENV_SWITCH}=0)"
        return {}
    try:
        from . import _aot
    except ImportError:
        _STATUS = "not built (no insgnss._aot module: every kernel is compiled by numba)"
        return {}
    if _aot.digest() != source_digest():
        _STATUS = ("stale (the sources changed since insgnss._aot was built: "
                   "reinstall to rebuild it; the kernels are compiled by numba meanwhile)")
        return {}
    table = {}
    for i, e in enumerate(entries()):
        fn = getattr(_aot, f"k{i}r", None)  # read-only arrays (:func:`exports`)
        relaxed = fn is not None
        fn = fn if relaxed else getattr(_aot, f"k{i}", None)
        if fn is None:
            continue
        try:
            _, args, pad = _export_types(e)
        except Exception:  # noqa: BLE001 (a type no export takes: the JIT path)
            continue
        if args is None:
            continue
        given = len(args) - len(pad)  # the arguments a call gives; the defaults follow
        check = argument_check((read_only(args) if relaxed else args)[:given])
        table.setdefault(f"{e['module']}.{e['name']}", []).append((given, check, fn, pad))
    _STATUS = f"used ({sum(map(len, table.values()))} exports of {len(table)} kernels)"
    return table


def table() -> dict:
    """The exports by kernel (:func:`_load`, once per process)."""
    global _TABLE
    if _TABLE is None:
        _TABLE = _load()
    return _TABLE


def status() -> str:
    """Whether the ahead-of-time kernels are used in this process, and why not."""
    table()
    return _STATUS


def entry(kernel):
    """Decorator above ``@njit`` (:func:`insgnss.jit.njit`) of a kernel of the manifest: its
    calls from Python run the built module's exports when the arguments have their types
    (:attr:`insgnss.jit.Kernel.exports`). A numba dispatcher is wrapped in a
    :class:`~insgnss.jit.Kernel` of it first."""
    if not isinstance(kernel, Kernel):
        kernel = Kernel(kernel.py_func, dispatcher=kernel)
    exports = table().get(f"{kernel.__module__}.{kernel.__qualname__}")
    if exports:
        kernel.exports = tuple(exports)
    return kernel


# --- the build ------------------------------------------------------------------------------------

def exports() -> list[tuple[str, object, object]]:
    """``[(export name, numba signature, Python function), ...]`` of :func:`entries` (the
    kernels imported and each signature compiled by numba once, for its return type); entries
    that no longer resolve or whose types an export cannot take are left out."""
    from importlib import import_module

    out = []
    for i, e in enumerate(entries()):
        try:
            disp = getattr(import_module(e["module"]), e["name"])
            disp = getattr(disp, "dispatcher", disp)  # a Kernel: its numba dispatcher
            sig, kinds, _ = _export_types(e)
            if kinds is None:
                continue
            sig, args = numba_types(sig), numba_types(kinds)
            disp.compile(sig)
            ret = disp.overloads[sig].signature.return_type
        except Exception:  # noqa: BLE001 (a stale entry: that kernel takes the JIT path)
            continue
        # the kernel typed with every array argument read-only, where it writes none of them
        # (an export that takes a read-only array takes a writable one as well)
        ro = numba_types(read_only(kinds))
        if ro != args and _types(disp.py_func, ro, ret):
            out.append((f"k{i}r", ret(*ro), disp.py_func))
        elif _types(disp.py_func, args, ret):
            out.append((f"k{i}", ret(*args), disp.py_func))
    return out


def _types(fn, sig: tuple, ret) -> bool:
    """Whether numba's ahead-of-time compiler types ``fn`` for ``sig -> ret``
    (:func:`_check_export`)."""
    try:
        _check_export(fn, sig, ret)
    except Exception:  # noqa: BLE001 (a kernel it does not type: the JIT path)
        return False
    return True


def _check_export(fn, sig: tuple, ret) -> None:
    """Type and lower ``fn`` alone for ``sig -> ret`` with ``numba.pycc``'s flags (an
    explicit return type; no machine code); raises where that fails, e.g. for the read-only
    variant of a kernel that writes an array. It does not catch a failure that depends on the
    other exports of the module (see :data:`PROCESSES`): the whole build fails then, and
    setup.py installs without the module."""
    from numba.core.compiler import Flags, compile_extra
    from numba.core.registry import cpu_target

    flags = Flags()
    flags.no_compile = True
    flags.nrt = True
    ctx = cpu_target.target_context
    library = ctx.codegen().create_library("insgnss_aot_check")
    compile_extra(cpu_target.typing_context, ctx, fn, sig, ret, flags, locals={},
                  library=library)


def compiler(output_dir: str | os.PathLike | None = None):
    """The ``numba.pycc.CC`` of :data:`MODULE`: every export of :func:`exports` and
    ``digest()`` (:func:`source_digest`)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba.pycc is "pending deprecation" since numba 0.57
        from numba.pycc import CC
    cc = CC(MODULE.rsplit(".", 1)[1])
    cc.target_cpu = os.environ.get(ENV_CPU, "host")
    if output_dir is not None:
        cc.output_dir = str(output_dir)
    for name, sig, fn in exports():
        cc.export(name, sig)(fn)
    value = source_digest()

    def digest():
        return value

    cc.export("digest", "int64()")(digest)
    return cc


__all__ = ["ENV_CPU", "ENV_SWITCH", "MODULE", "argument_check", "compiler", "entries",
           "entry", "export_signature", "exports", "read_only", "source_digest", "status", "table"]
