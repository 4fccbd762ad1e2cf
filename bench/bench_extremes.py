"""Every job value at its documented extreme: complete, or refuse cleanly.

A simulated car drive (default 5 minutes: static start, turns, a stop; consumer MEMS IMU at
100 Hz, 1 Hz GNSS position and velocity, 10 Hz odometer) is processed with every number the
job reads set to one end of its valid range in the schema (``insgnss.config``, docs/jobs.md
"valid values"), all at once:

- ``low``: closed lower bounds, ``OPEN_STEP`` above open ones, and at least the IMU intervals
  a key must span: ``filter.epoch_interval`` and ``aiding.nhc_interval`` one IMU interval,
  periodic outages one IMU interval long every IMU interval (15,000 windows in 5 minutes),
  the smallest sigmas;
- ``high``: closed upper bounds, just below open ones, ``BIG`` where the range is unbounded;
- ``work``: only the keys that set the amount of work and memory (:data:`WORK_KEYS`) at their
  low end, so that the run goes through them instead of stopping at the first refusal (the
  static-window limits at their low end stop ``low`` at the alignment, by design; the
  periodic outages start at 40 s, so that the initialization has GNSS);

for the strapdown and the RISS process model, each ``insgnss process`` run in its own process
under an address-space limit (``prlimit --as``, default 4 GiB). ``--each`` also runs every key
alone at each end (the others at their defaults). A run passes when it completes (exit 0),
stops with a located error (exit 2) or a filter health stop with its partial outputs (exit 3),
without a traceback. Prints, per run: exit status, wall time, peak resident memory and the
first line of the message.

    python bench/bench_extremes.py [--duration 300] [--limit 4G] [--each] [--keep DIR]
"""

from __future__ import annotations

import argparse
import copy
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from insgnss.config import _is_table_spec, iter_schema, load_job_dict  # noqa: E402
from insgnss.errors import ConfigError  # noqa: E402

#: the smallest step above an open lower bound (a sigma, an interval, a duration) [SI]
OPEN_STEP = 1e-6
#: the value used where a range has no upper bound: far beyond any physical one
BIG = 1e9
IMU_RATE = 100.0
#: the keys whose low end sets the amount of work and memory of a run
WORK_KEYS = ("filter.epoch_interval", "filter.propagation_interval", "aiding.nhc_interval",
             "aiding.zupt_interval", "outages.windows", "outages.periodic.length",
             "outages.periodic.gap", "inputs.imu.max_gap")

SCENARIO = """
[scenario]
name = "extremes"
seed = 12
imu_rate = {rate}
duration = {duration}

[trajectory]
vehicle = "land"
lat = 45.0
lon = 7.6
height = 250.0
heading = 30.0
segments = [
  {{ type = "static", duration = 30.0 }},
  {{ type = "accelerate", speed = 14.0, acceleration = 1.5 }},
  {{ type = "hold", duration = 20.0 }},
  {{ type = "turn", angle = 90.0, rate = 10.0 }},
  {{ type = "hold", duration = 30.0 }},
  {{ type = "decelerate", speed = 0.0, acceleration = 2.0 }},
  {{ type = "static", duration = 15.0 }},
  {{ type = "accelerate", speed = 12.0, acceleration = 1.5 }},
  {{ type = "turn", angle = -120.0, rate = 8.0 }},
  {{ type = "hold", duration = 400.0 }},
]

[imu]
grade = "consumer"

[gnss]
rate = 1.0
horizontal_std = 1.0
vertical_std = 2.0
velocity = true
velocity_std = 0.05
lever_arm = [0.0, 0.5, 1.2]
q = 5

[odometer]
rate = 10.0
output = "speed"
"""

#: settings that switch on every aiding source and schedule a simulated job can use
BASE = {
    "initialization": {"method": "static", "static_duration": 20.0},
    "aiding": {"gnss_position": True, "gnss_velocity": True, "zupt": True, "zaru": True,
               "nhc": True, "odometer": True, "q_scale": {"5": 1.0},
               "static_intervals": [[0.0, 20.0]]},
    "outages": {"windows": [[100.0, 110.0]],
                "periodic": {"start": 40.0, "length": 15.0, "gap": 30.0}},
    "filter": {"imu_grade": "consumer", "scale_factors": True},
    "outputs": {"report": True, "formats": ["csv", "nav", "kml", "geojson", "eval"]},
}


def _bump(x: float, up: bool) -> float:
    return x + OPEN_STEP if up else x - 1e-9 * max(1.0, abs(x))


def extreme_number(rule, side: str, min_span: float) -> float | None:
    """The documented extreme of a numeric rule at ``side`` (None: no documented one)."""
    lo, hi, lo_open, hi_open = rule.bounds
    if side == "low":
        if lo is None:
            return None
        v = _bump(lo, True) if lo_open else float(lo)
        return max(v, min_span) if min_span > 0 else v
    if hi is None:
        return BIG if lo is not None else None
    return _bump(hi, False) if hi_open else float(hi)


def extreme_value(spec: dict, side: str, dt: float, current):
    """The extreme of one key (None: the key has no documented extreme)."""
    rule = spec["check"]
    if rule is None:
        return None
    span = spec["min_imu_intervals"] * dt
    if rule.bounds is not None:
        v = extreme_number(rule, side, span)
        return int(min(v, 2 ** 31)) if spec["type"] is int and v is not None else v
    if rule.item is None or rule.item.bounds is None:
        return None
    if rule.length is None:  # windows: one of the shortest allowed, or one over everything
        if side == "low":
            a = float(current[0][0]) if current else 0.0
            return [[a, a + max(span, dt)]]
        return [[-BIG, BIG]]
    v = extreme_number(rule.item, side, 0.0)
    if v is None:
        return None
    if rule.length == 0:  # flag table (q_scale): every listed flag
        return {k: v for k in (current or {"5": 1.0})}
    return [v] * rule.length


def _set(d: dict, key: str, value) -> None:
    parts = key.split(".")
    for p in parts[:-1]:
        d = d.setdefault(p, {})
    d[parts[-1]] = value


def job_data(side: str | None, *, process_model: str = "strapdown", duration: float = 300.0,
             only: str | tuple[str, ...] | None = None) -> dict:
    """The job dict: the scenario, :data:`BASE` and the extremes of ``side`` (``"low"``,
    ``"high"``, or ``"work"``: :data:`WORK_KEYS` low) of every key the job reads (or of the
    ``only`` keys); ``side=None``: no extremes."""
    if side == "work":
        side, only = "low", WORK_KEYS
    if isinstance(only, str):
        only = (only,)
    data = tomllib.loads(SCENARIO.format(rate=IMU_RATE, duration=duration))
    base = copy.deepcopy(BASE)
    if process_model == "riss":
        base["aiding"]["odometer"] = False
        base["filter"]["process_model"] = "riss"
    data.update(base)
    if side is None:
        return data
    dt = 1.0 / IMU_RATE
    job = load_job_dict(data)
    for key, spec in read_keys(job):
        if only is not None and key not in only:
            continue
        cur = job.settings
        for p in key.split("."):
            cur = cur[p]
        v = extreme_value(spec, side, dt, cur)
        if v is not None:
            _set(data, key, v)
    for _ in range(100):  # an extreme can switch another key off (nis_window = 0: nis_bound)
        try:
            load_job_dict(data)
            break
        except ConfigError as exc:
            if "is not used by this job" not in exc.message:
                raise
            _unset(data, exc.column)
    return data


def read_keys(job):
    """``(key, spec)`` of every key the job reads (its conditions hold)."""
    sim = job.simulation if job.simulated else None
    return [(k, s) for k, s in iter_schema()
            if not _is_table_spec(s) and all(c.test(job.settings, sim) for c in s["when"])]


def _unset(d: dict, key: str) -> None:
    parts = key.split(".")
    for p in parts[:-1]:
        d = d[p]
    del d[parts[-1]]


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if value == value and abs(value) != float("inf") else "nan"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f'"{k}" = {_toml(v)}' for k, v in value.items()) + " }"
    raise TypeError(value)


def to_toml(data: dict) -> str:
    """A TOML document of a job dict (tables and inline values)."""
    lines: list[str] = []

    def table(d: dict, name: str) -> None:
        subs = {k: v for k, v in d.items() if isinstance(v, dict)}
        if name:
            lines.append(f"\n[{name}]")
        for k, v in d.items():
            if k not in subs:
                lines.append(f'"{k}" = {_toml(v)}')
        for k, v in subs.items():
            table(v, f'{name}."{k}"' if name else f'"{k}"')

    table(data, "")
    return "\n".join(lines) + "\n"


def run_one(data: dict, folder: Path, limit: int, timeout: float = 1800.0) -> dict:
    """``insgnss process`` of ``data`` under ``prlimit --as=limit``: exit status, time, peak
    memory [MiB], the first error line, and whether it is clean (module docstring)."""
    folder.mkdir(parents=True, exist_ok=True)
    job = folder / "job.toml"
    job.write_text(to_toml(data))
    cmd = [sys.executable, "-m", "insgnss.cli", "process", str(job), "-o", str(folder / "out"),
           "--no-progress"]
    if shutil.which("prlimit"):
        cmd = ["prlimit", f"--as={limit}", "--"] + cmd
        pre = None
    else:  # pragma: no cover - the same limit from Python
        import resource

        def pre():
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with open(folder / "stdout.txt", "w") as out, open(folder / "stderr.txt", "w") as err:
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=err, env=env, preexec_fn=pre)
        deadline = t0 + timeout
        while True:
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                p.kill()
                pid, status, usage = os.wait4(p.pid, 0)
                break
            time.sleep(0.05)
        wall = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    stderr = (folder / "stderr.txt").read_text()
    lines = [ln for ln in stderr.splitlines() if "error" in ln or "INCOMPLETE" in ln]
    clean = p.returncode in (0, 2, 3) and "Traceback" not in stderr
    if p.returncode == 2:
        clean = clean and any(ln.startswith("insgnss process: error:") for ln in lines)
    last = stderr.strip().splitlines()[-1:] or [""]
    return {"exit": p.returncode, "wall_s": wall, "peak_mib": usage.ru_maxrss / 1024.0,
            "message": (lines[0] if lines else last[0])[:200], "clean": clean,
            "stderr": stderr}


def _limit(text: str) -> int:
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    return int(float(text[:-1]) * units[text[-1].upper()]) if text[-1].upper() in units \
        else int(text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=300.0, help="simulated seconds (300)")
    ap.add_argument("--limit", default="4G", help="address-space limit per run (4G)")
    ap.add_argument("--each", action="store_true", help="also every key alone at each end")
    ap.add_argument("--keep", type=Path, help="keep the runs in this folder")
    args = ap.parse_args(argv)
    limit = _limit(args.limit)
    root = args.keep or Path(tempfile.mkdtemp(prefix="insgnss-extremes-"))
    runs = [(f"{pm} {side}", job_data(side, process_model=pm, duration=args.duration))
            for pm in ("strapdown", "riss") for side in ("low", "high", "work")]
    if args.each:
        for side in ("low", "high"):
            base = job_data(None, duration=args.duration)
            for key, _spec in read_keys(load_job_dict(base)):
                d = job_data(side, duration=args.duration, only=key)
                if d != base:
                    runs.append((f"{key} {side}", d))
    print(f"{len(runs)} runs of {args.duration:g} s simulated at {IMU_RATE:g} Hz under "
          f"--as={args.limit} (machine load: {os.getloadavg()[0]:.1f})")
    bad = 0
    for i, (name, data) in enumerate(runs):
        try:
            load_job_dict(data)
        except ConfigError as exc:  # the bench itself must only build valid jobs
            print(f"{name}: the bench built an invalid job: {exc}")
            return 1
        r = run_one(data, root / f"run{i:03d}", limit)
        bad += not r["clean"]
        print(f"{name:44s} exit {r['exit']:3d} {r['wall_s']:7.1f} s {r['peak_mib']:7.0f} MiB "
              f"{'ok ' if r['clean'] else 'BAD'} {r['message']}")
    print(f"{len(runs) - bad}/{len(runs)} clean; runs in {root}")
    if not args.keep and not bad:
        shutil.rmtree(root, ignore_errors=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
