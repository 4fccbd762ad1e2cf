"""Start-up: the command line loads no heavy module, lazy exports, robust package import.

Each check runs in a fresh interpreter (``sys.modules`` of the test process already holds
everything).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "pandas", "numba", "scipy", "matplotlib", "filterpy", "pyarrow", "allantools")


def _python(code: str, cwd: Path | None = None, env: dict | None = None):
    env = {**os.environ, "PYTHONPATH": str(REPO), **(env or {})}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=300)


def test_help_imports_no_heavy_module():
    out = _python(f"""
        import contextlib, io, sys
        from insgnss import cli
        with contextlib.redirect_stdout(io.StringIO()) as buf:
            assert cli.main([]) == 1  # no command: prints the help
        assert "process" in buf.getvalue() and "simulate" in buf.getvalue()
        for name in ("process", "simulate", "mechanize", "allan", "compare", "batch"):
            with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):
                cli.main([name, "--help"])
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in {HEAVY!r})
        ours = sorted(m for m in sys.modules if m.startswith("insgnss.")
                      and not m.startswith(("insgnss.commands", "insgnss.cli")))
        print(loaded, ours)
    """)
    assert out.returncode == 0, out.stderr
    loaded, ours = out.stdout.strip().split("] [")
    assert loaded == "[", f"heavy modules imported by the CLI parser: {loaded}]"
    # only the version, the lazy-export helper and the error classes
    assert ours == "'insgnss._lazy', 'insgnss._version', 'insgnss.errors']"


def test_light_commands_import_no_filter_or_plotting(tmp_path):
    """``insgnss simulate`` and ``insgnss mechanize`` (without --figure) run without the filter
    package, filterpy or matplotlib."""
    out = _python(f"""
        import contextlib, io, sys
        from pathlib import Path
        import numpy as np
        from insgnss.cli import main
        tmp = Path({str(tmp_path)!r})
        sc = tmp / "sc.toml"
        sc.write_text('[scenario]\\nname = "s"\\nseed = 1\\nimu_rate = 100.0\\n'
                      '[trajectory]\\nlat = 45.0\\nlon = 7.0\\nheight = 100.0\\n'
                      'segments = [{{ type = "static", duration = 20.0 }}]\\n'
                      '[imu]\\ngrade = "tactical"\\n')
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["simulate", str(sc), "-o", str(tmp / "sim")]) == 0
            assert main(["mechanize", str(tmp / "sim" / "imu.csv"), "--lat", "45", "--lon", "7",
                         "--height", "100", "--attitude", "0,0,0", "--gyro-unit", "rad",
                         "--accel-unit", "m/s", "-o",
                         str(tmp / "traj.csv")]) == 0
        assert (tmp / "traj.csv").exists()
        bad = sorted(m for m in sys.modules
                     if m.split(".")[0] in ("matplotlib", "filterpy")
                     or m.startswith(("insgnss.filter", "insgnss.pipeline", "insgnss.report",
                                      "insgnss.plots")))
        print(bad)
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_lazy_top_level_exports():
    import insgnss
    from insgnss.mechanization import INSMechanization as M2
    from insgnss.mechanization.strapdown import INSMechanization, NavState, mechanize

    assert insgnss.INSMechanization is INSMechanization is M2
    assert insgnss.NavState is NavState and insgnss.mechanize is mechanize
    from insgnss import InsgnssError
    from insgnss.errors import InsgnssError as E

    assert InsgnssError is E
    assert set(insgnss.__all__) <= set(dir(insgnss))
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        insgnss.not_a_name  # noqa: B018
    import insgnss.io as io

    for name in io.__all__:
        assert getattr(io, name) is not None, name
    with pytest.raises(ImportError):
        from insgnss.io import read_everything  # noqa: F401


def test_version_single_source():
    import insgnss
    from insgnss._version import __version__

    meta = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert "version" in meta["project"]["dynamic"]
    assert meta["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "insgnss._version.__version__"}
    assert insgnss.__version__ == __version__
    assert __version__.count(".") >= 2


def test_no_submodule_takes_the_version_from_the_package():
    """Under a shadowing namespace package ``insgnss`` has no ``__version__``: submodules read
    it from ``insgnss._version``."""
    import re

    bad = [str(p.relative_to(REPO)) for p in (REPO / "insgnss").rglob("*.py")
           if re.search(r"^\s*from (insgnss|\.+) import [^\n]*\b__version__\b", p.read_text(),
                        re.MULTILINE)
           and p.name != "__init__.py"]
    assert bad == []


def test_cli_import_with_a_shadowing_checkout(tmp_path):
    """A folder holding a checkout named ``insgnss`` (no ``__init__.py`` at its top) in the current
    directory is found as a namespace package ``insgnss``, while the real package's modules come
    from setuptools' editable finder (it maps the immediate children ``insgnss.X`` to the
    checkout's package folder). ``import insgnss.cli`` must work there (it failed with "cannot
    import name '__version__'"). The finder below reproduces that layout however insgnss is
    installed."""
    checkout = tmp_path / "insgnss"
    (checkout / "docs").mkdir(parents=True)
    (checkout / "README.md").write_text("another checkout\n")
    code = f"""
        import sys
        from importlib.machinery import PathFinder

        class ShadowedEditable:
            @classmethod
            def find_spec(cls, fullname, path=None, target=None):
                if fullname == "insgnss":  # the cwd's folder: a namespace package
                    return PathFinder.find_spec(fullname, [{str(tmp_path)!r}])
                if fullname.rpartition(".")[0] == "insgnss":  # the editable finder's mapping
                    return PathFinder.find_spec(fullname, [{str(REPO / "insgnss")!r}])
                return None

        sys.meta_path.insert(0, ShadowedEditable)
        import insgnss
        assert getattr(insgnss, "__file__", None) is None, "not shadowed: the test is void"
        import insgnss.cli
        print(insgnss.cli.__version__)
        insgnss.cli.build_parser()
    """
    out = _python(code, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    from insgnss._version import __version__

    assert out.stdout.strip() == __version__


def test_filter_run_imports_no_filterpy_scipy_stats_or_plotting():
    """A filter run with the default (compiled) Kalman backend loads neither filterpy (its
    ``kalman`` package imports ``scipy.stats``), scipy.stats nor matplotlib; ``kalman = "filterpy"`` does
    load filterpy (the reference path is really taken)."""
    code = """
        import sys
        sys.path.insert(0, {tests!r})
        import numpy as np
        from filter_sim import car_truth, corrupt_imu, gnss_from_truth, perturbed_initial
        from insgnss.imu import grade
        truth = car_truth(30.0, 50.0)
        rng = np.random.default_rng(4)
        imu, _ = corrupt_imu(truth, grade("tactical"), rng)
        gnss = gnss_from_truth(truth, rng)
        init, _ = perturbed_initial(truth, rng)
        pre = set(sys.modules)  # the simulation helpers load scipy.signal (and scipy.stats)
        from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity, run_filter
        res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)],
                         FilterConfig(imu_model="tactical", kalman={kalman!r}))
        assert res.complete and res.innovations["accepted"].all()
        print(sorted(m for m in set(sys.modules) - pre
                     if m.split(".")[0] in ("filterpy", "matplotlib")
                     or m.startswith("scipy.stats")))
    """
    tests = str(REPO / "tests")
    out = _python(code.format(tests=tests, kalman="compiled"))
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().splitlines()[-1] == "[]"
    out = _python(code.format(tests=tests, kalman="filterpy"))
    assert out.returncode == 0, out.stderr[-3000:]
    assert "'filterpy.kalman'" in out.stdout.strip().splitlines()[-1]
