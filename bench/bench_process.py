"""Benchmark: the whole ``insgnss process`` run as a user runs it.

Each run is a child process ``insgnss process JOB -o OUT --no-progress`` of this checkout
(``PYTHONPATH`` set to it). Measured per run: wall time, CPU time (user + system of the child
and the figure workers it reaped: on a loaded shared machine it moves much less than the wall
time), peak resident memory of the child
(``ru_maxrss`` from ``os.wait4``, the child's own ``getrusage``), throughput (IMU samples/s and
times real time) and the size of what it wrote. Modes:

- **warm**: the package's numba cache is filled by one untimed run first; the median of
  ``--repeat`` runs is reported;
- **cold**: one run with an empty temporary ``NUMBA_CACHE_DIR`` (every kernel compiled; the
  package's cache is not touched); the compile time of each kernel is printed (numba's
  compile events, exclusive of the callees compiled meanwhile, with the number of
  specialisations; the kernels the compile-ahead helper compiled beside it are loaded, not
  listed: ``INSGNSS_COMPILE_AHEAD=0`` in the environment measures a run without it). The
  listener is registered when a kernel first loads numba, so a run on the ahead-of-time
  kernels imports no numba here either ("nothing compiled (numba not even imported)");
- **no report**: one warm run with ``--no-report``.

Data sets:

- ``sim``: a 1 h / 200 Hz simulated car drive (``scenarios/car_highway_tactical_outages.toml``
  extended to ``--hours``: tactical IMU, 1 Hz GNSS position and velocity with 60 s outages),
  written once with ``insgnss simulate`` into ``--data`` (reused when present) and processed
  from its files with a job written beside them (native CSV inputs, truth as reference);
- ``drive``: the real car drive ``scenarios/drive_0708.toml`` (55k samples at 100 Hz, RTK,
  11 outages), skipped when the shared data is absent. The ``car`` profile estimates the noise
  by maximum likelihood first (``filter.autotune``: about 200 forward filter runs, minutes);
  ``--no-autotune`` runs a copy of the job with ``filter.autotune = false`` (one filter and
  smoother run with the profile's noise: the whole-process cost of reading, filtering,
  smoothing and writing the drive).

The breakdown comes from ``summary.json`` ``timing_s`` (read, filter, smoother, the rest of
the job) and from timers the child puts around its imports, ``write_outputs``, the report and
``write_tables`` (the trajectories, written while the figures are drawn: the report line is
what the figures took beyond them) (wrapped module attributes; the work is the same); the
remainder is the interpreter's start and exit and the job loading.
KF-GINS is timed only when a ``KF-GINS`` executable is on PATH; otherwise the issue's
figures are printed for reference.

``--stages``: one warm run per data set with the child's resident memory sampled every 4 ms
and attributed to the stage running (read, forward filter, smoother, output tables,
evaluation, write and report, the rest of the job), printed as the peak of each stage.

Run: ``python bench/bench_process.py [--repeat 3] [--only sim|drive] [--no-cold]
[--no-autotune] [--stages]``. Prints
numbers; not a timed test. The machine has 2 cores shared with other work: say so with the
numbers (the load average is printed).
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "scenarios" / "car_highway_tactical_outages.toml"
DRIVE_JOB = REPO / "scenarios" / "drive_0708.toml"
DEFAULT_DATA = Path(tempfile.gettempdir()) / "insgnss-bench-process"
#: the checkout whose insgnss the children run (``--code``; default this one)
CODE = REPO

#: the job processing the simulated files (paths relative to the job file)
SIM_JOB = """\
# written by bench/bench_process.py: the simulated drive processed from its files
[job]
name = "sim_{hours:g}h_200hz"
time_base = "run"

[inputs.imu]
format = "native"
path = "imu.csv"

[inputs.gnss]
format = "native"
path = "gnss.csv"
lever_arm = [0.0, 1.2, 1.5]   # the scenario's antenna lever arm

[inputs.reference]
format = "native"
path = "truth.csv"
point = "imu"

[initialization]
method = "static"
static_duration = 60.0        # the scenario stands still for 120 s

[aiding]
gnss_velocity = true

[filter]
imu_grade = "tactical"
smoother = true
"""

#: the speed issue's measurements (2026-12-01, same machine, median of 3 pairs)
ISSUE_FIGURES = """\
reference (speed issue, 2026-12-01): insgnss before the work / KF-GINS (forward only)
  1 h / 200 Hz, default outputs:   11.9-16.5 s, 1,346 MiB  /  9.9-11.6 s, 4.6 MiB
  1 h / 200 Hz, .nav only, no report: 8.1-9.9 s,  990 MiB  /  same
  real drive (55k samples):          4.2-4.5 s,   450 MiB  /  0.8 s
  cold numba cache, drive:          14.6 s
  targets: 1 h <= 2.5 s warm and <= 400 MiB; drive <= 1.5 s warm, <= 6 s cold"""


#: the child: ``insgnss process`` as the console script runs it, with timers around the
#: imports, ``write_outputs`` and the report (module attributes wrapped; the work is unchanged)
CHILD = r"""
import atexit, importlib, json, os, sys, time
t0 = time.perf_counter()
marks = {}
atexit.register(lambda: open(os.environ["BENCH_MARKS"], "w").write(json.dumps(
    dict(marks, numba_loaded="numba" in sys.modules))))
if os.environ.get("BENCH_COMPILE"):  # compile time per kernel (numba's compile events)
    _stack, _comp = [], {}
    marks["compile"] = _comp
    def _listen():
        from numba.core import event as _ev
        class _Compile(_ev.Listener):
            def on_start(self, e):
                f = e.data["dispatcher"].py_func
                _stack.append([f"{f.__module__}.{f.__qualname__}", time.perf_counter(), 0.0])
            def on_end(self, e):
                name, start, inner = _stack.pop()
                dt = time.perf_counter() - start
                if _stack:
                    _stack[-1][2] += dt
                c = _comp.setdefault(name, [0.0, 0])
                c[0] += dt - inner  # exclusive: the callees compiled meanwhile are their own
                c[1] += 1
        _ev.register("numba:compile", _Compile())
    try:  # registered when a kernel first loads numba (insgnss.jit.register_numba runs
        import insgnss.jit as _jit  # before any dispatcher is made): a run that compiles
    except ImportError:             # nothing imports no numba, here as for a user
        _listen()                   # (a checkout from before insgnss.jit: at once)
    else:
        _register = _jit.register_numba
        def _register_and_listen():
            first = not _jit._REGISTERED
            _register()
            if first:
                _listen()
        _jit.register_numba = _register_and_listen
import insgnss.cli, insgnss.pipeline
marks["import"] = time.perf_counter() - t0

def timed(f, key):
    def wrapper(*a, **k):
        t = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            marks[key] = marks.get(key, 0.0) + time.perf_counter() - t
    return wrapper

def report_timer():
    t = time.perf_counter()
    import insgnss.report as rep  # matplotlib: part of the report's cost
    marks["report"] = time.perf_counter() - t
    if not getattr(rep.write_report, "_timed", False):
        rep.write_report = timed(rep.write_report, "report")
        rep.write_report._timed = True

mods = []
for name in ("insgnss.job.outputs", "insgnss.job.run", "insgnss.pipeline"):
    try:
        mods.append(importlib.import_module(name))
    except ImportError:
        pass
original = next(m.write_outputs for m in mods if hasattr(m, "write_outputs"))
def write_outputs(result, *a, **k):
    if result.job["outputs"]["report"]:
        report_timer()
    return original(result, *a, **k)
wrapped = timed(write_outputs, "write_outputs")
for mod in mods:
    if getattr(mod, "write_outputs", None) is original:
        mod.write_outputs = wrapped
    if hasattr(mod, "write_tables"):  # run while the figures are drawn, inside the report
        mod.write_tables = timed(mod.write_tables, "tables")
if os.environ.get("BENCH_STAGES"):  # --stages: resident memory sampled per stage
    import threading
    page = os.sysconf("SC_PAGE_SIZE") / 2.0**20
    stack, peaks, order = ["start-up (imports)"], {}, []
    def rss():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * page
    def sample():
        while True:
            r, s = rss(), stack[-1]
            if r > peaks.get(s, 0.0):
                peaks[s] = r
            time.sleep(0.004)
    threading.Thread(target=sample, daemon=True).start()
    def staged(f, name):
        def wrapper(*a, **k):
            stack.append(name)
            if name not in order:
                order.append(name)
            try:
                return f(*a, **k)
            finally:
                stack.pop()
        return wrapper
    import insgnss.filter.engine as eng, insgnss.filter.strapdown_model as sdm
    import insgnss.job.processes as procs, insgnss.job.run as jrun
    jrun.load_inputs = staged(jrun.load_inputs, "read")
    eng.run_engine = staged(eng.run_engine, "forward filter")
    eng.smooth = staged(eng.smooth, "smoother (backward pass)")
    sdm.StrapdownModel.output = staged(sdm.StrapdownModel.output, "output tables")
    procs.evaluate_result = staged(procs.evaluate_result, "evaluation")
    for mod in mods:
        if getattr(mod, "write_outputs", None) is wrapped:
            mod.write_outputs = staged(wrapped, "write (files, report)")
    stack.append("job (rest)")
    order[:0] = ["start-up (imports)", "job (rest)"]
    peaks["start-up (imports)"] = rss()
    atexit.register(lambda: marks.update(stages=[(k, peaks.get(k, 0.0)) for k in order]))
import insgnss.cli as cli
if hasattr(cli, "entry"):  # the console script's entry (ends without the teardown)
    cli.entry()
sys.exit(cli.main())
"""


@dataclass
class Run:
    wall: float
    rss_mib: float
    code: int
    cpu: float = 0.0  #: user + system CPU seconds of the child and the workers it reaped
    summary: dict = field(default_factory=dict)
    written_mb: float = 0.0
    stderr: str = ""
    marks: dict = field(default_factory=dict)


def child_env(cache_dir: str | None = None) -> dict:
    env = dict(os.environ)
    # as a user runs it: Python writes and reuses the bytecode of the modules it imports (a
    # sandbox may set PYTHONDONTWRITEBYTECODE, which recompiles every insgnss module each run)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = os.pathsep.join([str(CODE), *filter(None, [env.get("PYTHONPATH")])])
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    return env


def run_child(argv: list[str], env: dict, cwd: str | os.PathLike
              ) -> tuple[float, float, int, str, float]:
    """Run ``python argv`` in ``cwd`` and return (wall s, peak RSS MiB, exit code, stderr tail,
    CPU s). The CPU time (user + system, the child's and its reaped workers') depends much less
    on the load of a shared machine than the wall time.

    ``cwd`` must not hold an ``insgnss`` folder: ``python -c`` puts the current folder first on
    ``sys.path``, so a checkout there would be imported instead of ``CODE``.
    """
    with tempfile.TemporaryFile("w+") as err, open(os.devnull, "w") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, *argv], stdout=out, stderr=err, env=env,
                                cwd=cwd)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        tail = err.read()[-2000:]
    cpu = usage.ru_utime + usage.ru_stime
    return wall, usage.ru_maxrss / 1024.0, proc.returncode, tail, cpu  # ru_maxrss: KiB


def process(job: Path, *, cold: bool = False, report: bool = True, stages: bool = False
            ) -> Run:
    """One ``insgnss process`` run into a temporary folder."""
    with tempfile.TemporaryDirectory(prefix="bench-process-") as tmp:
        out = Path(tmp) / "out"
        cache = Path(tmp) / "numba-cache" if cold else None
        marks = Path(tmp) / "marks.json"
        argv = ["-c", CHILD, "process", str(job), "-o", str(out), "--no-progress"] + \
            ([] if report else ["--no-report"])
        env = child_env(None if cache is None else str(cache))
        env["BENCH_MARKS"] = str(marks)
        if cold:
            env["BENCH_COMPILE"] = "1"
        if stages:
            env["BENCH_STAGES"] = "1"
        wall, rss, code, err, cpu = run_child(argv, env, cwd=tmp)
        marks = json.loads(marks.read_text()) if marks.exists() else {}
        summary = {}
        if (out / "summary.json").exists():
            summary = json.loads((out / "summary.json").read_text())
        size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) if out.exists() else 0
    return Run(wall, rss, code, cpu, summary, size / 1e6, err, marks)


def simulated_job(data: Path, hours: float) -> Path:
    """Simulate the drive once (``insgnss simulate``) and write the job beside the files."""
    folder = data / f"sim_{hours:g}h"
    meta = folder / "metadata.json"
    samples = round(3600 * hours * 200) + 1
    if not (meta.exists() and json.loads(meta.read_text())["time"]["samples"] == samples):
        print(f"simulating {hours:g} h at 200 Hz into {folder} (once) ...", flush=True)
        data.mkdir(parents=True, exist_ok=True)
        argv = ["-m", "insgnss.cli", "simulate", str(SCENARIO), "-o", str(folder),
                "--duration", str(3600.0 * hours)]
        r = subprocess.run([sys.executable, *argv], env=child_env(), capture_output=True,
                           text=True, cwd=data)
        if r.returncode:
            raise SystemExit(f"insgnss simulate failed:\n{r.stderr[-2000:]}")
    job = folder / "job.toml"
    job.write_text(SIM_JOB.format(hours=hours))
    return job


def fixed_noise_job(job: Path, folder: Path) -> Path:
    """A copy of ``job`` in ``folder`` with ``filter.autotune = false`` (the input paths made
    absolute, since they are relative to the job file)."""
    import tomllib

    text = job.read_text()
    for src in tomllib.loads(text).get("inputs", {}).values():
        for key in ("path", "tag"):
            if isinstance(src, dict) and isinstance(src.get(key), str):
                absolute = (job.parent / src[key]).resolve()
                text = text.replace(f'"{src[key]}"', f'"{absolute}"')
    if "\n[filter]\n" not in text:
        text += "\n[filter]\n"
    text = text.replace("\n[filter]\n", "\n[filter]\nautotune = false\n", 1)
    out = folder / f"{job.stem}_fixed_noise.toml"
    out.write_text(text)
    return out


def describe(name: str, mode: str, runs: list[Run]) -> dict:
    ok = [r for r in runs if r.code in (0, 3)]
    if not ok:
        print(f"{name}: {mode} run failed (exit {runs[0].code}):\n{runs[0].stderr}")
        return {}
    walls = [r.wall for r in ok]
    best = min(ok, key=lambda r: abs(r.wall - statistics.median(walls)))
    s = best.summary
    n = int(s.get("imu_samples", 0))
    segments = s.get("imu", {}).get("segments") or []
    duration = sum(b - a for a, b in segments)  # seconds of data processed
    row = {"name": name, "mode": mode, "wall": statistics.median(walls), "min": min(walls),
           "max": max(walls), "rss": max(r.rss_mib for r in ok), "samples": n,
           "cpu": statistics.median(r.cpu for r in ok),
           "duration": duration, "written": best.written_mb, "timing": s.get("timing_s", {}),
           "marks": best.marks, "runs": len(ok)}
    return row


def print_table(rows: list[dict]) -> None:
    print(f"\n{'data':10s} {'mode':10s} {'runs':>4s} {'wall s':>8s} {'(min-max)':>13s} "
          f"{'CPU s':>7s} {'peak RSS':>9s} {'samples/s':>11s} {'x real':>7s} {'written':>9s}")
    for r in rows:
        if not r:
            continue
        rate = r["samples"] / r["wall"] if r["wall"] else 0.0
        real = r["duration"] / r["wall"] if r["wall"] else 0.0
        print(f"{r['name']:10s} {r['mode']:10s} {r['runs']:4d} {r['wall']:8.2f} "
              f"{r['min']:6.2f}-{r['max']:<6.2f} {r['cpu']:7.2f} {r['rss']:6.0f} MiB {rate:11,.0f} "
              f"{real:7.0f} {r['written']:6.0f} MB")


def print_breakdown(warm: dict) -> None:
    """Where the wall time of the median warm run went (s)."""
    if not warm:
        return
    t, m = warm["timing"], warm["marks"]
    filt = t.get("total", 0.0) - t.get("smoother", 0.0)
    job_rest = t.get("job_total", 0.0) - t.get("read", 0.0) - t.get("total", 0.0)
    # the trajectories are written while the figures are drawn (inside the report's time)
    tables = m.get("tables", 0.0) if m.get("report", 0.0) else 0.0
    report = m.get("report", 0.0) - tables
    parts = [("start-up (imports)", m.get("import", 0.0)), ("read", t.get("read", 0.0)),
             ("filter (forward)", filt), ("smoother", t.get("smoother", 0.0)),
             ("rest of the job (init, evaluation)", job_rest),
             ("write (trajectories, logs, summary)", m.get("write_outputs", 0.0) - report),
             ("report (figures, beyond the writes)", report)]
    parts.append(("interpreter start and exit, job loading",
                  warm["wall"] - sum(v for _, v in parts)))
    print(f"\nbreakdown, {warm['name']} warm (median run, s):")
    for name, v in parts:
        print(f"  {name:42s} {v:6.2f}")
    inner = ", ".join(f"{k} {v:.2f}" for k, v in t.items()
                      if k in ("mechanization", "covariance", "updates", "output"))
    print(f"  (filter: {inner})")
    print(f"  {'wall':42s} {warm['wall']:6.2f}")


def print_compile(cold: dict, top: int = 15) -> None:
    """Compile time per kernel of the cold run (wall s, exclusive of the callees compiled
    meanwhile; numba's ``numba:compile`` events), largest first; ``xN``: specialisations."""
    marks = (cold or {}).get("marks", {})
    comp = marks.get("compile") or {}
    if not comp:
        if cold and "compile" in marks:
            print(f"\ncompile, {cold['name']} cold: nothing compiled (numba "
                  f"{'imported' if marks.get('numba_loaded') else 'not even imported'})")
        return
    total = sum(v[0] for v in comp.values())
    print(f"\ncompile, {cold['name']} cold: {total:.1f} s in {len(comp)} functions "
          f"(wall, exclusive); the largest:")
    for name, (sec, n) in sorted(comp.items(), key=lambda kv: -kv[1][0])[:top]:
        print(f"  {sec:6.2f} s  x{n}  {name}")
def print_stages(name: str, run: Run) -> None:
    """Peak resident memory of each stage of one run (``--stages``; sampled every 4 ms in
    the child, the stage being the innermost one running)."""
    stages = run.marks.get("stages") or []
    print(f"\npeak resident memory per stage, {name} (MiB; peak RSS of the run "
          f"{run.rss_mib:.0f} MiB, wall {run.wall:.2f} s, CPU {run.cpu:.2f} s):")
    for stage, peak in stages:
        print(f"  {stage:42s} {peak:7.0f}")


def kfgins_baseline() -> None:
    exe = shutil.which("KF-GINS") or shutil.which("kf-gins")
    if exe is None:
        print("\nKF-GINS: not available on this machine (no KF-GINS executable on PATH).")
    else:  # a user's own configuration is needed; report where it is
        print(f"\nKF-GINS found at {exe}: run it on the same data with its YAML configuration "
              "to compare (not automated here).")
    print(ISSUE_FIGURES)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="warm runs per data set (median)")
    ap.add_argument("--only", choices=["sim", "drive"], help="one data set")
    ap.add_argument("--hours", type=float, default=1.0, help="length of the simulated log")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA,
                    help=f"folder for the simulated log (default {DEFAULT_DATA})")
    ap.add_argument("--no-cold", action="store_true", help="skip the cold-cache runs")
    ap.add_argument("--no-autotune", action="store_true",
                    help="the drive with filter.autotune = false (no self-tuning runs)")
    ap.add_argument("--code", type=Path, default=REPO,
                    help="checkout whose insgnss is timed (e.g. another branch; default this "
                    "one); the jobs and the scenario are this checkout's")
    ap.add_argument("--stages", action="store_true",
                    help="only one warm run per data set with the resident memory sampled per "
                    "stage (read, forward filter, smoother, output tables, evaluation, write)")
    args = ap.parse_args()
    global CODE
    CODE = args.code.resolve()

    print(f"insgnss {CODE}; python {sys.version.split()[0]}; {os.cpu_count()} cores; "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    aot = subprocess.run([sys.executable, "-c", "import insgnss.aot as a; print(a.status())"],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(CODE)})
    print(f"ahead-of-time kernels (insgnss._aot, a cold run needs none of those compiled): "
          f"{aot.stdout.strip() or aot.stderr.strip()[-300:]}")
    jobs = []
    if args.only in (None, "drive"):
        data = REPO.parent / "shared" / "data" / "gnss-imu-rtklibexplorer" / "drive_0708"
        if data.exists():
            if args.no_autotune:
                folder = Path(tempfile.mkdtemp(prefix="bench-process-job-"))
                atexit.register(shutil.rmtree, folder, ignore_errors=True)
                jobs.append(("drive fixed", fixed_noise_job(DRIVE_JOB, folder)))
            else:
                jobs.append(("drive", DRIVE_JOB))
        else:
            print(f"drive: skipped, no data at {data}")
    if args.only in (None, "sim"):
        jobs.append((f"sim {args.hours:g} h", simulated_job(args.data, args.hours)))
    rows = []
    for name, job in jobs:
        first = process(job)  # fills the package's numba cache: the warm runs load it
        if first.code not in (0, 3):
            print(f"{name}: failed (exit {first.code}):\n{first.stderr}")
            continue
        if args.stages:
            print_stages(name, process(job, stages=True))
            continue
        warm = describe(name, "warm", [process(job) for _ in range(args.repeat)])
        noreport = describe(name, "no report", [process(job, report=False)])
        cold = {} if args.no_cold else describe(name, "cold", [process(job, cold=True)])
        rows += [warm, noreport, cold]
        print_table([warm, noreport, cold])
        print_breakdown(warm)
        print_compile(cold)
    print("\nall runs:")
    print_table(rows)
    print(f"load average at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    kfgins_baseline()


if __name__ == "__main__":
    main()
