"""Run the bundled demo: a simulated car drive (consumer MEMS IMU, GNSS with two 30 s outages,
stops) processed end to end with the error-state filter and the RTS smoother, evaluated against
the simulated truth; writes trajectories, logs, a JSON summary and report.html.

The demo job file is insgnss/data/demo_car.toml (copy it to start your own).
"""

from __future__ import annotations

import argparse
from importlib import resources
from pathlib import Path

from ._outputs import add_wait_argument, output_folder

NAME = "demo"
HELP = "simulate a car drive and process it end to end (no data needed)"


def demo_job_path() -> Path:
    return Path(str(resources.files("insgnss") / "data" / "demo_car.toml"))


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", type=Path, default=Path("out/demo"),
                   help="output folder, relative to the current folder (default: out/demo)")
    p.add_argument("--seed", type=int, help="simulation seed")
    p.add_argument("--no-progress", action="store_true")
    add_wait_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..compile_ahead import compile_ahead
    from ..config import load_job
    from ..job.processes import process_name
    from ..pipeline import run_job, write_outputs
    from .process import output_names, print_summary

    job = load_job(demo_job_path())
    with output_folder(args, args.output, protect=job.input_paths(), names=output_names()), \
            compile_ahead(process_name(job)):  # on a cold numba cache only
        res = run_job(job, progress=False if args.no_progress else None, seed=args.seed)
        paths = write_outputs(res, args.output)
    print_summary(res)
    print(f"wrote {len(paths)} files to {args.output}; open {args.output / 'report.html'}")
    return 0 if res.filter.complete else 3
