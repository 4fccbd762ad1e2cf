"""Monte Carlo of the tactical-MEMS car (scenarios/mc_car_tactical_mems.toml) processed
by the job the docs describe for a car, N runs with independent seeds.

Prints per run whether it completed, the heading source of the static start, the gate-recovery
acceptances of NHC (must be 0), and over all runs and outages: the end-of-outage horizontal error
against the filter's sigma (the ratio |e_h| / hypot(s_E, s_N), and the share inside the two-axis
3-sigma bound, chi-square 2 dof 99.73 %), forward and smoothed.

    PYTHONPATH=. python bench/bench_car_consistency.py [--runs 50] [--job FILE] [--seed N]

``--seed`` draws the run seeds from another root than the scenario's ``[montecarlo] seed``: a
model change is decided on one set of runs and reported on another.
"""

from __future__ import annotations

import argparse
import time
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from insgnss.config import load_job_dict
from insgnss.montecarlo import draw_seeds
from insgnss.pipeline import run_job

JOB = Path(__file__).resolve().parents[1] / "scenarios" / "mc_car_tactical_mems.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--job", type=Path, default=JOB)
    ap.add_argument("--seed", type=int, default=None,
                    help="root seed of the runs (default: the scenario's [montecarlo] seed)")
    args = ap.parse_args()
    data = tomllib.loads(args.job.read_text())
    job = load_job_dict(data, args.job)
    root = int(data["montecarlo"]["seed"]) if args.seed is None else args.seed
    seeds = draw_seeds(root, args.runs)
    tables, runs = [], []
    t0 = time.perf_counter()
    for i, seed in enumerate(seeds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = run_job(job, progress=False, seed=seed)
        inn = res.filter.innovations
        nhc = inn[inn.type == "nhc"]
        runs.append({"run": i, "complete": bool(res.filter.complete and res.failure is None),
                     "heading_source": res.summary["initialization"]["heading_source"],
                     "nhc_rejected": int((~nhc.accepted).sum()),
                     "nhc_recovered": int(nhc.recovered.sum()),
                     "gnss_recovered": int(inn[inn.type.str.startswith("gnss")].recovered.sum())})
        for sol in ("forward", "smoothed"):
            ev = res.evaluation.get(sol)
            if ev:
                tab = ev["outages"].copy()
                tab["run"], tab["solution"] = i, sol
                tables.append(tab)
    wall = time.perf_counter() - t0
    runs = pd.DataFrame(runs)
    out = pd.concat(tables, ignore_index=True)
    print(f"{args.runs} runs of {args.job.name} (root seed {root}) in {wall:.0f} s")
    print(f"complete: {int(runs.complete.sum())}/{len(runs)}; heading source: "
          f"{runs.heading_source.value_counts().to_dict()}; NHC rejected {runs.nhc_rejected.sum()}"
          f", NHC force-applied by the gate recovery {runs.nhc_recovered.sum()}, GNSS recovered "
          f"{runs.gnss_recovered.sum()}")
    print(f"{'solution':9s} {'outages':>7s} {'end err mean':>12s} {'p95':>6s} {'max':>6s} "
          f"{'ratio mean':>10s} {'ratio rms':>9s} {'ratio max':>9s} {'in 3 sigma':>10s}")
    for sol, g in out.groupby("solution", sort=False):
        e = g.end_h_err_m.to_numpy(float)
        r = g.end_h_err_sigma_ratio.to_numpy(float)
        w = g.end_within_3sigma.dropna().astype(float)
        print(f"{sol:9s} {len(g):7d} {np.nanmean(e):12.3f} {np.nanpercentile(e, 95):6.2f} "
              f"{np.nanmax(e):6.2f} {np.nanmean(r):10.3f} {np.sqrt(np.nanmean(r ** 2)):9.3f} "
              f"{np.nanmax(r):9.2f} {100 * w.mean():9.1f}%")


if __name__ == "__main__":
    main()
