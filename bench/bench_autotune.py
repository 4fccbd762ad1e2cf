"""Benchmark: the self-tuning (``[filter] autotune``) on the real recordings.

For each job (``scenarios/drive_0708.toml``, ``scenarios/walk_0827.toml``; skipped when the
shared data is absent) the job runs in this process as ``insgnss process`` runs it, and the
bench prints: the self-tuning's wall time and filter runs (``summary.json`` ``"autotune"``:
``seconds``, ``evaluations``, ``one_step_evaluations``), the whole job's time, the tuned values
and the shared scorer's outage figures (``../shared/eval/drive_outage.py``: forward
end-of-outage mean, smoothed in-outage RMS mean, forward non-outage RMS). ``--no-autotune``
adds the same job without the self-tuning for comparison.

Run: ``python bench/bench_autotune.py [--only drive|walk] [--no-autotune]``. Prints numbers;
not a timed test. The machine has 2 cores shared with other work: the load average before and
after each run is printed; quote it with the times.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SCORER = SHARED / "eval" / "drive_outage.py"
DATA = SHARED / "data" / "gnss-imu-rtklibexplorer"
JOBS = {
    "drive": (REPO / "scenarios" / "drive_0708.toml", DATA / "drive_0708" / "gnss_1934_sf.pos"),
    "walk": (REPO / "scenarios" / "walk_0827.toml", DATA / "walk_0827" / "gnss_1730_sf.pos"),
}


def _score(path: Path, ref: Path) -> dict:
    r = subprocess.run([sys.executable, str(SCORER), str(path), "--ref", str(ref), "--json"],
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def run_one(name: str, autotune: bool) -> dict:
    from insgnss.config import load_job
    from insgnss.pipeline import run_job, write_outputs

    job_file, ref = JOBS[name]
    job = load_job(job_file)
    job.settings["filter"]["autotune"] = autotune
    job.settings["outputs"]["formats"] = ["csv", "eval"]
    job.settings["outputs"]["report"] = False
    load0 = os.getloadavg()[0]
    c0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(job, progress=False)
    total = time.perf_counter() - c0
    out = Path(tempfile.mkdtemp(prefix=f"insgnss_bench_autotune_{name}_"))
    paths = write_outputs(res, out)
    fwd = _score(paths["forward_eval.csv"], ref)
    smo = _score(paths["smoothed_eval.csv"], ref)
    at = res.summary.get("autotune") or {}
    return {"job": name, "autotune": autotune, "load": (load0, os.getloadavg()[0]),
            "job_s": total, "autotune_s": at.get("seconds"),
            "evaluations": at.get("evaluations"),
            "one_step_evaluations": at.get("one_step_evaluations"),
            "values": {k: v["value"] for k, v in (at.get("parameters") or {}).items()},
            "observable": {k: v["observable"] for k, v in (at.get("parameters") or {}).items()},
            "fwd_end_mean_m": fwd["outage_summary"]["end_h_err_m"]["mean"],
            "smo_in_rms_mean_m": smo["outage_summary"]["rms_h_err_m"]["mean"],
            "fwd_non_outage_m": fwd["non_outage"]["rms_h_err_m"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=sorted(JOBS), action="append")
    ap.add_argument("--no-autotune", action="store_true",
                    help="also run each job without the self-tuning")
    ap.add_argument("--json", type=Path, help="write the rows to this file")
    args = ap.parse_args()
    rows = []
    for name in args.only or sorted(JOBS):
        job_file, ref = JOBS[name]
        if not ref.exists():
            print(f"{name}: shared data absent ({ref}), skipped")
            continue
        for on in (True, False) if args.no_autotune else (True,):
            r = run_one(name, on)
            rows.append(r)
            print(f"{name:6s} autotune={'on ' if on else 'off'} job {r['job_s']:7.1f} s"
                  + (f"  autotune {r['autotune_s']:7.1f} s  {r['evaluations']} filter runs "
                     f"({r['one_step_evaluations']} one-step)" if on else "")
                  + f"  load {r['load'][0]:.1f}/{r['load'][1]:.1f}")
            print(f"       forward end-of-outage mean {r['fwd_end_mean_m']:.3f} m, smoothed "
                  f"in-outage RMS {r['smo_in_rms_mean_m']:.4f} m, forward non-outage "
                  f"{r['fwd_non_outage_m']:.4f} m")
            for k, v in r["values"].items():
                print(f"       {k:24s} {v:.5g}{'' if r['observable'][k] else '  (prior)'}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
