"""Compile ahead: a second process fills numba's cache with the kernels a run needs last.

numba compiles a kernel on its first call and keeps the machine code in its on-disk cache
(``cache=True``: the package's ``__pycache__``, or ``NUMBA_CACHE_DIR``). Compiling holds one
global lock and one core, so a run on an empty cache (the first run after an install or an
upgrade) spends most of its time compiling, one kernel after the other, while the other cores
wait: on the real car drive 52-58 s of a 58 s run (115 functions).

When the cache is cold, :func:`compile_ahead` starts a helper process
(``python -m insgnss.compile_ahead PROCESS``) that compiles the run's kernels in the reverse of
the order the run first calls them, writing each into the same cache. The run compiles from
the front as before; when it reaches a kernel the helper has finished, numba loads it from the
cache (it reads the cache index at every first call). The helper only loads a kernel it finds
in the cache (jobs differ in the order of their middle kernels, so it does not stop there) and
ends with the list or with the run. The results are those of any run: the same code, compiled
by the same numba, into the same cache; only the process that compiles a kernel differs.

The order and the argument types come from :data:`MANIFEST`, recorded from a cold run of a
representative job per process (``python -m insgnss.compile_ahead record PROCESS -- CLI ARGS``,
e.g. ``record strapdown -- demo -o out/demo``): the top-level compile events of numba
(``numba:compile``; a kernel's callees are compiled with it), with each argument type as its
``repr`` (``Array(float64, 2, 'C', False, aligned=True)``). A kernel a job does not need costs the
helper time, not the run; an entry that no longer matches the code (renamed kernel, changed
arguments) is skipped. The helper runs only with two or more usable cores and is turned off with
``INSGNSS_COMPILE_AHEAD=0``. Killed at the end of a run while writing a cache file, it may leave a
``*.tmp.*`` file beside the cache, which numba ignores.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from contextlib import contextmanager
from importlib import import_module
from pathlib import Path

from .executors import usable_cores as _cores
from .kernel_manifest import MANIFEST, entry_key, load_manifest
from .kernel_manifest import argument_types as _argument_types
from .kernel_manifest import type_namespace as _type_namespace

#: environment variable that turns the helper off ("0")
ENV_SWITCH = "INSGNSS_COMPILE_AHEAD"


def kernel_signatures(process: str, manifest: dict | None = None) -> list[tuple]:
    """``[(dispatcher, argument types), ...]`` of ``process`` in the order of first use; entries
    whose kernel or argument types do not resolve on this installation are left out."""
    entries = (load_manifest() if manifest is None else manifest).get("kernels", {}).get(
        process, [])
    ns = _type_namespace() if entries else {}
    out = []
    for e in entries:
        try:
            disp = getattr(import_module(e["module"]), e["name"])
            sig = _argument_types(e["args"], ns)
        except Exception:  # noqa: BLE001 (a stale entry: the run compiles it itself)
            continue
        if hasattr(disp, "compile") and hasattr(disp, "stats"):
            out.append((disp, sig))
    return out


def is_cached(disp) -> bool:
    """Whether numba's cache holds a current entry of the kernel ``disp`` (an index file whose
    source stamp matches). Unknown (numba's cache internals changed): True, so that no helper
    is started on a guess."""
    try:
        return bool(disp._cache._cache_file._load_index())
    except Exception:  # noqa: BLE001
        return True


def wanted(process: str, manifest: dict | None = None) -> bool:
    """Whether a run of ``process`` should start the helper: switched on, two or more usable
    cores, no ahead-of-time kernels for the process (:mod:`insgnss.aot`), a manifest for the
    process, and its last kernel not in the cache (a cold cache)."""
    if os.environ.get(ENV_SWITCH, "1") == "0" or _cores() < 2:
        return False
    from . import aot

    if process in aot.PROCESSES and aot.table():  # its kernels are compiled already
        return False
    manifest = load_manifest() if manifest is None else manifest
    entries = manifest.get("kernels", {}).get(process)
    if not entries:
        return False
    last = kernel_signatures(process, {"kernels": {process: entries[-1:]}})
    return bool(last) and not is_cached(last[0][0])


def start(process: str) -> subprocess.Popen | None:
    """Start the helper for ``process`` when :func:`wanted`; returns it (or None)."""
    if not wanted(process):
        return None
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[1])  # the same insgnss (numba's cache is per file)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    env[ENV_SWITCH] = "0"
    try:
        return subprocess.Popen([sys.executable, "-m", "insgnss.compile_ahead", process],
                                env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None


def stop(helper: subprocess.Popen | None) -> None:
    """End the helper (its finished kernels stay in the cache)."""
    if helper is None or helper.poll() is not None:
        return
    helper.terminate()
    try:
        helper.wait(timeout=5.0)
    except subprocess.TimeoutExpired:
        helper.kill()
        helper.wait()


@contextmanager
def compile_ahead(process: str):
    """Run the enclosed block with the helper of ``process`` compiling beside it (module
    docstring); a no-op when the cache is warm."""
    helper = start(process)
    try:
        yield helper
    finally:
        stop(helper)


def compile_backward(process: str, manifest: dict | None = None) -> list[str]:
    """The helper's work: compile the kernels of ``process`` from the last used to the first;
    a kernel already in the cache (the run, or an earlier run, compiled it) is only loaded.
    Returns the names of the kernels compiled here."""
    done = []
    for disp, sig in reversed(kernel_signatures(process, manifest)):
        hits = disp.stats.cache_hits[sig]
        try:
            disp.compile(sig)
        except Exception:  # noqa: BLE001 (types that no longer fit: the run compiles it)
            continue
        if disp.stats.cache_hits[sig] == hits:
            done.append(disp.py_func.__qualname__)
    return done


def trace(out: str | Path, cli_args: list[str]) -> int:
    """Run ``insgnss CLI_ARGS`` in this process and write its top-level compile events (the
    kernels of the insgnss package, in the order they were compiled) to ``out``."""
    import time

    from numba.core import event

    events, stack = [], []

    class _Listener(event.Listener):
        def on_start(self, ev):
            f = ev.data["dispatcher"].py_func
            stack.append((f.__module__, f.__qualname__, [repr(a) for a in ev.data["args"]],
                          time.perf_counter()))

        def on_end(self, ev):
            module, name, args, t0 = stack.pop()
            if not stack and module.split(".")[0] == "insgnss":
                events.append({"module": module, "name": name, "args": args,
                               "seconds": round(time.perf_counter() - t0, 2)})

    event.register("numba:compile", _Listener())
    from .cli import main as cli_main

    try:
        rc = cli_main(cli_args)
    except SystemExit as e:
        rc = e.code
    Path(out).write_text(json.dumps(events))
    return int(rc or 0)


def record(process: str, cli_args: list[str], manifest_path: str | Path | None = None,
           add: bool = False) -> dict:
    """Record the kernels of ``process`` from a cold run of ``insgnss CLI_ARGS`` (a child with
    an empty temporary ``NUMBA_CACHE_DIR`` and the ahead-of-time kernels off, so that every
    kernel compiles) into the manifest (default: the packaged one). ``add``: append the
    kernels (and argument types) the recorded entries of ``process`` do not have yet, after
    them, instead of replacing them: the union of several jobs (the ahead-of-time build
    exports every entry, :mod:`insgnss.aot`)."""
    import tempfile

    import numba

    from .aot import ENV_SWITCH as AOT_SWITCH

    path = Path(manifest_path) if manifest_path else \
        Path(__file__).resolve().parent / "data" / MANIFEST
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "events.json"
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "cache"),
                   **{ENV_SWITCH: "0", AOT_SWITCH: "0"})
        subprocess.run([sys.executable, "-m", "insgnss.compile_ahead", "trace", str(out),
                        *cli_args], env=env, check=True)
        events = json.loads(out.read_text())
    ns = _type_namespace()
    keep = []
    for e in events:
        try:
            _argument_types(e["args"], ns)
        except Exception:  # noqa: BLE001 (e.g. omitted arguments: left to the run)
            continue
        keep.append(e)
    manifest = json.loads(path.read_text()) if path.exists() else {}
    manifest["numba"] = numba.__version__
    command = "insgnss " + " ".join(cli_args)
    kernels = manifest.setdefault("kernels", {})
    if add and kernels.get(process):
        have = {entry_key(e) for e in kernels[process]}
        keep = kernels[process] + [e for e in keep if entry_key(e) not in have]
        was = manifest.setdefault("recorded_with", {}).get(process, "")
        command = was + (" + " if was else "") + command
    manifest.setdefault("recorded_with", {})[process] = command
    kernels[process] = keep
    path.write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest


def main(argv: list[str] | None = None) -> int:
    """``python -m insgnss.compile_ahead PROCESS`` (the helper),
    ``... record PROCESS [--add] -- CLI ARGS`` (update the manifest; ``--add``: append to it),
    ``... trace OUT CLI ARGS``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["trace"]:
        return trace(argv[1], argv[2:])
    if argv[:1] == ["record"]:
        cli = argv[argv.index("--") + 1:] if "--" in argv else argv[2:]
        add = "--add" in argv[2:argv.index("--") if "--" in argv else 2]
        m = record(argv[1], cli, add=add)
        print(f"recorded {len(m['kernels'][argv[1]])} kernels of {argv[1]!r}")
        return 0
    if len(argv) != 1:
        print(main.__doc__, file=sys.stderr)
        return 2
    compile_backward(argv[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
