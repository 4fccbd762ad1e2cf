"""Benchmark and study: Monte Carlo throughput with 1 and 2 local workers, and the 200-run study of
``scenarios/mc_car_outages.toml`` (5 min car, two 60 s GNSS outages, tactical IMU at 100 Hz).

Run: ``python bench/bench_montecarlo.py`` (prints the numbers; not a test). Options:
``--runs 200`` (study), ``--throughput-runs 40``, ``--skip-study``, ``--skip-throughput``,
``--dask`` (also time a 2-worker Dask LocalCluster), ``-o out/bench_montecarlo``.

Throughput: runs/minute of the same runs on an in-process back-end and on local process pools
of 1 and 2 workers. Each pool is warmed first (process start, imports, numba cache load: two
runs per worker, not timed), so the numbers are the steady state; the start-up is printed
separately. The machine's load average is printed too: on a shared 2-core machine the 2-worker
speed-up is bounded by what the other processes leave.

Study: the percentile table at the outage ends, NEES/NIS against the chi-square bounds, the
coverage check (the filter's 3 sigma against the 99th percentile of the absolute error at
>= 95 % of the epochs, per solution and quantity) and the envelope figure
(``envelopes.png``) written with the tables into the output folder.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "mc_car_outages.toml"


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def throughput(runs: int, dask: bool) -> None:
    from insgnss.executors import DaskCluster, InProcess, LocalPool
    from insgnss.montecarlo import run_montecarlo

    print(f"throughput: {runs} runs of {SCENARIO.name} per back-end (load average {_load()}, "
          f"{os.cpu_count()} CPUs)")
    results = {}
    backends = [("in-process", InProcess), ("pool-1", lambda: LocalPool(1)),
                ("pool-2", lambda: LocalPool(2))]
    if dask:
        backends.append(("dask-local-2", lambda: DaskCluster(n_workers=2, processes=True)))
    for name, make in backends:
        t0 = time.perf_counter()
        with make() as ex:
            run_montecarlo(SCENARIO, runs=2 * ex.workers, seed=1, executor=ex)  # warm up
            t_start = time.perf_counter() - t0
            res = run_montecarlo(SCENARIO, runs=runs, seed=2, executor=ex)
        s = res.summary
        rpm = 60.0 * s["runs_ok"] / s["elapsed_s"]
        results[name] = rpm
        per_run = sum(r["elapsed_s"] for r in s["runs"]) / len(s["runs"])
        cpu = sum(r["cpu_s"] for r in s["runs"]) / len(s["runs"])
        ideal = 60.0 * ex.workers / cpu
        print(f"  {name:12s}: {rpm:6.1f} runs/min ({s['elapsed_s']:.1f} s for {runs} runs; per "
              f"run in the worker {per_run:.2f} s wall, {cpu:.2f} s CPU -> {ideal:.0f} runs/min "
              f"on {ex.workers} free core(s); start-up + warm-up {t_start:.1f} s; load {_load()})")
    print(f"  speed-up 2 workers / 1 worker: {results['pool-2'] / results['pool-1']:.2f}x")


def study(runs: int, out: Path, workers: int) -> None:
    import pandas as pd

    from insgnss.commands.montecarlo import print_report
    from insgnss.executors import LocalPool
    from insgnss.montecarlo import run_montecarlo

    print(f"\nstudy: {runs} runs of {SCENARIO.name} on {workers} local workers "
          f"(load average {_load()})")
    with LocalPool(workers) as ex:
        res = run_montecarlo(SCENARIO, runs=runs, executor=ex, progress=True)
    paths = res.write(out)
    print_report(res)
    s = res.summary
    t = pd.DataFrame(s["percentile_table"])
    f = t[(t["quantity"] == "horizontal") & t["event"].str.startswith("outage")]
    print("\nhorizontal error at the outage ends [m]:")
    with pd.option_context("display.float_format", "{:.2f}".format, "display.width", 140):
        print(f[["solution", "event", "time", "mean", "rms", "p68", "p95", "p99", "sigma",
                 "3sigma"]].to_string(index=False))
    c = s["coverage_check"]
    print(f"\n3-sigma covers the 99th-percentile error at >= 95 % of the epochs: "
          f"{'YES' if c['passed'] else 'NO'}")
    for sol, v in c["solutions"].items():
        print(f"  {sol:8s}: {'yes' if v['passed'] else 'no '} (worst: {v['worst']['quantity']} "
              f"at {100 * v['worst']['fraction']:.1f} % of the epochs)")
    print(f"figures and tables: {', '.join(str(p) for p in paths.values())}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--throughput-runs", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2, help="workers of the study")
    ap.add_argument("--skip-study", action="store_true")
    ap.add_argument("--skip-throughput", action="store_true")
    ap.add_argument("--dask", action="store_true", help="also time a Dask LocalCluster")
    ap.add_argument("-o", "--output", type=Path, default=Path("out/bench_montecarlo"))
    a = ap.parse_args(argv)
    if not a.skip_throughput:
        throughput(a.throughput_runs, a.dask)
    if not a.skip_study:
        study(a.runs, a.output, a.workers)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
