"""The package's import structure (issue 14): no import circle among insgnss modules, and every
module imports on its own in a fresh interpreter.

The graph is built from the module-level import statements (function-local imports are lazy
and do not run at import time, so they cannot form a circle at import; ``if TYPE_CHECKING:``
blocks never run). Importing ``a.b.c`` also runs the ``__init__`` of ``a.b`` and ``a``, so those
packages are edges too, unless the importer lives inside them (a package's ``__init__`` runs
before any of its modules anyway).
"""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "insgnss"


def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        parts = list(p.relative_to(REPO).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _top_level_imports(tree: ast.Module):
    """Import nodes executed when the module is imported (module body, top-level if/try)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop(0)
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If):
            if not _is_type_checking(node.test):
                stack.extend(node.body + node.orelse)
        elif isinstance(node, ast.Try):
            stack.extend(node.body + node.orelse + node.finalbody
                         + [s for h in node.handlers for s in h.body])


def _all_imports(tree: ast.Module):
    """Every import statement of a module, function-local (lazy) ones included."""
    return (n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)))


def import_graph(lazy: bool = False) -> dict[str, set[str]]:
    """insgnss module -> insgnss modules its import runs (see the module docstring); with
    ``lazy`` also the modules its functions import when they run."""
    walk = _all_imports if lazy else _top_level_imports
    mods = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        package = name if is_pkg else name.rpartition(".")[0]
        targets = set()
        for node in walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets.update(a.name for a in node.names)
                continue
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets.add(mod)
            targets.update(f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in mods)
        edges = set()
        for t in targets:
            if t not in mods or name.startswith(t + "."):  # unknown, or the importer's package
                continue
            edges.add(t)
            parts = t.split(".")
            for k in range(1, len(parts)):  # the packages whose __init__ the import runs
                anc = ".".join(parts[:k])
                if not (name == anc or name.startswith(anc + ".")):
                    edges.add(anc)
        edges.discard(name)
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle (as a path that returns to its start), or None."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    path: list[str] = []

    def visit(n):
        state[n] = 1
        path.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return path[path.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        path.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


def test_cycle_finder_finds_a_circle_and_accepts_a_tree():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_graph_sees_relative_and_package_imports():
    g = import_graph()
    # pipeline is a facade over the job package; the job layer uses the engine and the readers
    assert "insgnss.job.run" in g["insgnss.pipeline"]
    assert "insgnss.filter.engine" in g["insgnss.job.processes"]
    assert "insgnss.filter" in g["insgnss.job.processes"]  # the package __init__ runs too
    assert "insgnss.job" not in g["insgnss.job.run"]  # its own package: not an edge


def test_no_import_circle_among_insgnss_modules():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def test_no_circle_through_lazy_imports_either():
    """A function-local import hides a circle from the interpreter but not from the reader
    (e.g. the old ``policies.run_segments`` calling back into ``pipeline.run_job``)."""
    g = import_graph(lazy=True)
    assert "insgnss.foot" in g["insgnss.job.processes"]  # lazy: imported inside run_foot
    cycle = find_cycle(g)
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def test_job_layer_steps_do_not_import_their_callers():
    """Each step of the job layer imports only the steps below it: the segment logic gets the
    single-run function passed in and never imports run; no step imports the facade."""
    g = import_graph(lazy=True)
    job = {n for n in g if n.startswith("insgnss.job.")}
    used = set().union(*(g[n] for n in job))
    assert "insgnss.job.run" not in used and "insgnss.pipeline" not in used
    assert not any("insgnss.job" in g[n] or "insgnss.pipeline" in g[n]
                   for n in ("insgnss.policies", "insgnss.evaluate", "insgnss.foot"))


@pytest.mark.parametrize("chunk", [0, 1])
def test_every_module_imports_in_a_fresh_interpreter(chunk):
    """Each module alone, in a process of its own (forked from an interpreter that has loaded
    only the third-party libraries), so an import that works only after another insgnss module
    was loaded is caught."""
    names = sorted(_modules())[chunk::2]
    script = textwrap.dedent(f"""
        import os, sys, traceback
        import numpy, pandas, scipy.stats, numba, filterpy.kalman, matplotlib
        matplotlib.use("Agg")
        failed = []
        for name in {names!r}:
            pid = os.fork()
            if pid == 0:
                try:
                    __import__(name)
                except BaseException:
                    traceback.print_exc()
                    os._exit(1)
                os._exit(0)
            _, status = os.waitpid(pid, 0)
            if status:
                failed.append(name)
        print("FAILED", failed)
        sys.exit(1 if failed else 0)
    """)
    # cwd = the repository: ``python -c`` puts it first on sys.path
    r = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
