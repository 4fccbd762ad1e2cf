"""Real car drive benchmark (rtklibexplorer drive_0708, 11 simulated 15 s GNSS outages).

Runs ``scenarios/drive_0708.toml`` (car profile, self-tuning on) through the pipeline, prints
the per-outage table and the summary for the forward (causal) filter and the RTS smoother, then
scores the written solutions with the project-independent scorer
``../shared/eval/drive_outage.py`` (run, not copied), and times ``insgnss process`` on the job
with a warm numba cache.

Run: ``python bench/bench_drive.py [--no-scorer] [--repeat N]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
JOB = REPO / "scenarios" / "drive_0708.toml"
SCORER = REPO.parent / "shared" / "eval" / "drive_outage.py"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--no-scorer", action="store_true")
    ap.add_argument("--repeat", type=int, default=1, help="timed runs of `insgnss process` (the "
                    "car profile self-tunes: minutes each)")
    args = ap.parse_args()
    import pandas as pd

    from insgnss.config import load_job
    from insgnss.pipeline import run_job, write_outputs

    job = load_job(JOB)
    job.settings["outputs"]["formats"] = ["csv", "eval"]
    job.settings["outputs"]["report"] = False
    t0 = time.perf_counter()
    res = run_job(job, progress=False)
    t_run = time.perf_counter() - t0
    out = Path(tempfile.mkdtemp(prefix="insgnss_drive_"))
    paths = write_outputs(res, out)
    pd.set_option("display.width", 140)
    print(f"preprocessing: {res.summary['preprocessing']}")
    for name in ("forward", "smoothed"):
        ev = res.evaluation[name]
        cols = ["outage", "n_epochs", "end_h_err_m", "max_h_err_m", "rms_h_err_m", "end_v_err_m"]
        print(f"\n=== {name} ===")
        print(ev["outages"][cols].to_string(index=False, float_format=lambda v: f"{v:.3f}"))
        s = ev["summary"]
        print(f"mean end-of-outage horizontal error {s['end_h_err_m_mean']:.3f} m, "
              f"mean in-outage RMS {s['rms_h_err_m_mean']:.3f} m, "
              f"non-outage horizontal RMS {s['non_outage_rms_h_m']:.3f} m")
    print(f"\nrun_job (in process, warm): {t_run:.2f} s; filter timing: "
          + ", ".join(f"{k} {v:.2f}" for k, v in res.filter.timing.items()))
    if not args.no_scorer and SCORER.exists():
        for name in ("forward", "smoothed"):
            print(f"\n--- shared scorer, {name} ---")
            r = subprocess.run([sys.executable, str(SCORER), str(paths[f"{name}_eval.csv"])],
                               capture_output=True, text=True)
            print(r.stdout.strip()[-1500:] or r.stderr[-1500:])
    times = [t_run] if not args.repeat else []
    for _ in range(args.repeat):
        t1 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "insgnss.cli", "process", str(JOB), "-o", str(out),
                        "--no-progress", "--no-report"], check=True, capture_output=True)
        times.append(time.perf_counter() - t1)
    print(f"\n`insgnss process drive_0708.toml --no-report` wall time (warm cache, incl. Python "
          f"start-up and writing): best {min(times):.2f} s of {args.repeat}")


if __name__ == "__main__":
    main()
