"""Monte Carlo study of a scenario job: N simulations with seeds drawn from one master seed, each
processed by the job's filter and smoother, aggregated per epoch (mean, RMS, 68/95/99
percentiles of the error; NEES/NIS with chi-square bounds; the filter's 3-sigma against the
99th percentile). Writes montecarlo.parquet (tidy, one row per run/solution/quantity/epoch),
statistics.parquet, summary.json, envelopes.png and consistency.png (docs/montecarlo.md).

Back-ends: in-process (default), --workers K (local process pool), --local-cluster K (Dask
LocalCluster) or --scheduler ADDRESS (an existing Dask cluster; the workers need the same
insgnss version).

Examples:
  insgnss montecarlo scenarios/mc_car_outages.toml --runs 200 --workers 2 -o out/mc_car
  insgnss montecarlo scenarios/mc_car_outages.toml --runs 500 --scheduler tcp://head:8786 -o out/mc

Exit status: 0 all runs succeeded, 3 some runs failed (reported; the others are aggregated),
1 no run succeeded, 2 bad job or arguments.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ._outputs import add_wait_argument, output_folder

NAME = "montecarlo"
HELP = "Monte Carlo study of a scenario job (local processes or a Dask cluster)"


def add_backend_arguments(p: argparse.ArgumentParser) -> None:
    """``--workers | --scheduler | --local-cluster`` (shared with ``insgnss batch``)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, metavar="K",
                   help="local process pool of K workers (default: run in this process)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler address of an existing cluster, e.g. tcp://host:8786")
    g.add_argument("--local-cluster", type=int, metavar="K",
                   help="start a Dask LocalCluster of K single-threaded worker processes")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_wait_argument(p)


def make_backend(args: argparse.Namespace):
    from ..errors import ConfigError
    from ..executors import make_executor

    for key in ("workers", "local_cluster"):
        v = getattr(args, key)
        if v is not None and v < 1:
            raise ConfigError("must be at least 1", column=f"--{key.replace('_', '-')}", found=v)
    return make_executor(workers=args.workers, scheduler=args.scheduler,
                         local_cluster=args.local_cluster)


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", metavar="SCENARIO", type=Path,
                   help="scenario + job TOML file (with an optional [montecarlo] table)")
    p.add_argument("--runs", type=int, help="number of runs (overrides [montecarlo] runs)")
    p.add_argument("--seed", type=int, help="master seed (overrides [montecarlo] seed)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DIR",
                   help="output folder")
    p.add_argument("--no-figures", action="store_true", help="do not draw the figures")
    add_backend_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..montecarlo import run_montecarlo

    with output_folder(args, args.output, protect=[args.scenario]):
        with make_backend(args) as ex:
            res = run_montecarlo(args.scenario, runs=args.runs, seed=args.seed, executor=ex,
                                 progress=not args.no_progress)
        paths = res.write(args.output, figures=not args.no_figures)
    print_report(res)
    print(f"wrote {len(paths)} files to {args.output}")
    s = res.summary
    if s["runs_ok"] == 0:
        return 1
    return 3 if s["runs_failed"] else 0


def print_report(res) -> None:
    import pandas as pd

    s = res.summary
    ex = s["executor"]
    print(f"{s['scenario']}: {s['runs_ok']}/{s['runs_requested']} runs ok, master seed "
          f"{s['master_seed']}, {ex['backend']} ({ex['workers']} workers), "
          f"{s['elapsed_s']:.1f} s, {s['runs_per_minute']:.1f} runs/min")
    for f in s["failures"]:
        print(f"  FAILED run {f['run']} (seed {f['seed']}): {f['error']}: {f['message']}")
    if s["percentile_table"]:
        t = pd.DataFrame(s["percentile_table"])
        with pd.option_context("display.width", 160, "display.max_columns", 30,
                               "display.float_format", "{:.3f}".format):
            print("error percentiles (absolute error; angles in degrees):")
            print(t.drop(columns=["n"]).to_string(index=False))
    for kind in ("nees", "nis"):
        for sol, blocks in s[kind].items():
            for b, d in blocks.items():
                print(f"  {kind.upper()} {sol:8s} {b:9s}: mean {d['mean']:6.2f} (dof {d['dof']:g}), "
                      f"inside the {100 * res.settings.confidence:g} % bounds at "
                      f"{100 * d['inside_fraction']:5.1f} % of {d['epochs']} epochs "
                      f"(above {100 * d['above_fraction']:.1f} %)")
    c = s.get("coverage_check")
    if c:
        print(f"coverage check: {c['statement']}")
        for sol, qs in s["coverage"].items():
            v = c["solutions"][sol]
            print(f"  {sol:8s} {'PASSED' if v['passed'] else 'FAILED'} (worst "
                  f"{v['worst']['quantity']} {100 * v['worst']['fraction']:.1f} %): "
                  + ", ".join(f"{q} {100 * x['fraction']:.1f}" for q, x in qs.items()))
