#!/usr/bin/env python3
"""Foot-mounted ZUPT INS on the PyShoe Vicon trials with ONE fixed configuration.

Runs :func:`insgnss.foot.run_foot_ins` with the foot preset (or a ``[foot]`` table from a
TOML file, e.g. ``scenarios/foot_mounted.toml``) on every trial of DATA_DIR, writes
``<trial>.csv`` with columns ``x y z`` (one row per IMU sample) into OUT_DIR, then scores the
directory with the shared scorer (``python pyshoe_armse.py DATA_DIR OUT_DIR --json``, run from
its own path, never copied) and prints the per-trial table and the mean 2-D ARMSE.

No truth and no stored labels are used by the navigation: only ``ts`` and ``imu`` are read for
it; ``gt`` is read by the scorer alone.

Output frame: x = north, y = east, z = down (NED, metres from the start). The Vicon frame of
this dataset matches PyShoe's z-down navigation frame up to a yaw rotation, and PyShoe's own
output reproduces its stored errors through the scorer; an east-north-up solution is the mirror
image of it in the horizontal plane, which the scorer's yaw-only alignment cannot undo.

Usage::

    run_pyshoe.py [--data DATA_DIR] [--out OUT_DIR] [--config scenarios/foot_mounted.toml]
                  [--forward] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import convert  # noqa: E402  (the dataset reader beside this script)

from insgnss.foot import FootConfig, run_foot_ins  # noqa: E402
from insgnss.io.native import atomic_write  # noqa: E402

REPO = HERE.parents[1]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "pyshoe-vicon"
DEFAULT_SCORER = REPO.parent / "shared" / "eval" / "pyshoe_armse.py"


def load_config(path: str | Path | None) -> FootConfig:
    """The foot preset, or the ``[foot]`` table (with ``[foot.detector]``) of a TOML job."""
    if path is None:
        return FootConfig()
    with open(path, "rb") as fh:
        doc = tomllib.load(fh)
    return FootConfig.from_dict(doc.get("foot", {}))


def solution_ned(traj: pd.DataFrame) -> pd.DataFrame:
    """``x y z`` = north, east, down [m] from the start (see the module docstring)."""
    enu = convert.solution_xyz(traj).to_numpy()
    return pd.DataFrame({"x": enu[:, 1], "y": enu[:, 0], "z": -enu[:, 2]})


def run_trial(mat: Path, config: FootConfig, forward: bool = False):
    """Navigate one trial; returns (solution x y z, FootResult, number of samples)."""
    imu, _truth = convert.to_insgnss(mat)
    lat, lon, h = convert.TORONTO
    res = run_foot_ins(imu, config, lat=lat, lon=lon, height=h)
    traj = res.forward if forward else res.trajectory
    return solution_ned(traj), res, len(imu)


def run_all(data_dir: Path, out_dir: Path, config: FootConfig, forward: bool = False):
    """Run every trial, write the solution CSVs; returns per-trial rows and total run time."""
    rows = []
    t_nav = 0.0
    out_dir.mkdir(parents=True, exist_ok=True)
    for mat in sorted(data_dir.glob("*.mat")):
        t0 = time.perf_counter()
        sol, res, n = run_trial(mat, config, forward)
        t_nav += time.perf_counter() - t0
        atomic_write(out_dir / f"{mat.stem}.csv",
                     lambda p, s=sol: s.to_csv(p, index=False, float_format="%.6f"))
        rows.append({"trial": mat.stem, "samples": n, "still": res.stillness.fraction,
                     "updates": res.n_updates})
    return rows, t_nav


def score(data_dir: Path, out_dir: Path, scorer: Path = DEFAULT_SCORER) -> dict:
    """Run the shared scorer (``pyshoe_armse.py DATA_DIR OUT_DIR --json``) and return its
    per-trial results keyed by trial name."""
    proc = subprocess.run([sys.executable, str(scorer), str(data_dir), str(out_dir), "--json"],
                          capture_output=True, text=True, check=True)
    doc = json.loads(proc.stdout)
    return {r["trial"]: r for r in doc["trials"]}


#: where the data comes from (said when the folder is missing)
DATA_SOURCE = ("the PyShoe foot-mounted dataset (University of Toronto STARS Lab; Wagstaff, "
               "Peretroukhin & Kelly, IEEE Sensors J. 20(2), 2019; open access on IEEE DataPort, "
               "doi:10.21227/v1z6-9z84): download it and give the folder of its processed Vicon "
               "trials (data/vicon/processed/*.mat) with --data")


def check_paths(a) -> str | None:
    """What is wrong with the paths of the command line (None: nothing)."""
    if not a.data.is_dir():
        return f"no data folder {a.data}: the trials are {DATA_SOURCE}"
    if not any(a.data.glob("*.mat")):
        return f"no .mat trial in {a.data}: expected {DATA_SOURCE}"
    if a.config is not None and not a.config.is_file():
        return f"no configuration file {a.config} (a TOML file with a [foot] table, e.g. " \
               "scenarios/foot_mounted.toml)"
    if not a.scorer.is_file():
        return (f"no scorer {a.scorer}: the trials are scored by pyshoe_armse.py (the shared "
                "evaluation scripts beside the repository, ../shared/eval/); give its path "
                "with --scorer")
    return None


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA,
                   help="folder of the PyShoe Vicon trials (*.mat; default ../shared/data/"
                   "pyshoe-vicon)")
    p.add_argument("--out", type=Path, default=Path("pyshoe_out"))
    p.add_argument("--config", type=Path, default=None, help="TOML with a [foot] table")
    p.add_argument("--scorer", type=Path, default=DEFAULT_SCORER)
    p.add_argument("--forward", action="store_true", help="score the forward filter, not the "
                   "smoothed trajectory")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    problem = check_paths(a)
    if problem:
        print(f"run_pyshoe.py: error: {problem}", file=sys.stderr)
        return 2
    cfg = load_config(a.config)
    rows, t_nav = run_all(a.data, a.out, cfg, a.forward)
    scores = score(a.data, a.out, a.scorer)
    n = sum(r["samples"] for r in rows)
    for r in rows:
        r.update(scores[r["trial"]])
    ours = np.array([r["ours"] for r in rows])
    summary = {
        "trials": len(rows), "samples": n, "mean_armse_m": float(ours.mean()),
        "median_armse_m": float(np.median(ours)), "max_armse_m": float(ours.max()),
        "pyshoe_shoe_oracle_mean": float(np.mean([r["pyshoe_shoe_oracle"] for r in rows])),
        "pyshoe_best_oracle_mean": float(np.mean([r["pyshoe_best_oracle"] for r in rows])),
        "run_time_s": t_nav, "samples_per_s_end_to_end": n / t_nav,
        "smoothed": not a.forward,
    }
    if a.json:
        print(json.dumps({"summary": summary, "trials": rows}, indent=1))
        return 0
    print(f"{'trial':21s} {'N':>6s} {'still':>6s} {'ARMSE':>7s} {'pyshoe':>7s} {'best':>7s}")
    for r in rows:
        print(f"{r['trial']:21s} {r['samples']:6d} {r['still']:6.2f} {r['ours']:7.3f} "
              f"{r['pyshoe_shoe_oracle']:7.3f} {r['pyshoe_best_oracle']:7.3f}")
    print(f"mean 2-D ARMSE over {len(rows)} trials: {summary['mean_armse_m']:.4f} m "
          f"(median {summary['median_armse_m']:.4f}, max {summary['max_armse_m']:.3f}); "
          f"PyShoe per-trial oracle: SHOE {summary['pyshoe_shoe_oracle_mean']:.3f}, "
          f"best {summary['pyshoe_best_oracle_mean']:.3f}")
    print(f"{n} samples in {t_nav:.2f} s end to end (read + detect + filter + smoother): "
          f"{n / t_nav:,.0f} samples/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
