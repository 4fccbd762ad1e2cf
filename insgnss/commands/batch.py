"""Process many job files with the same settings and write one summary table.

Each JOB_GLOB is a job file or a pattern (quote it: "logs/*/job.toml", "campaign/**/*.toml").
With --settings BASE.toml the job files only need what differs (usually [inputs] and [job]
name); their keys override the base. Per job the usual outputs go to DIR/<job name>/ (unless
--summary-only), and DIR/batch.csv, batch.parquet and batch.json hold one row per job (status,
error, timing, evaluation metrics when the job has a reference). A failed job is reported and
the others go on (docs/montecarlo.md, "Batch processing").

Examples:
  insgnss batch "campaign/*.toml" --settings lab_defaults.toml -o out/campaign --workers 2
  insgnss batch "campaign/**/job.toml" --scheduler tcp://head:8786 -o /shared/out/campaign

Settings-only files and jobs whose data is not present are skipped with a one-line note.

Exit status: 0 every job that ran is ok, 3 some jobs failed or stopped early, 2 bad arguments.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ._outputs import output_folder
from .montecarlo import add_backend_arguments, make_backend

NAME = "batch"
HELP = "process many job files with the same settings; one summary table"


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("jobs", nargs="+", metavar="JOB_GLOB", help="job files or glob patterns")
    p.add_argument("--settings", type=Path, metavar="BASE",
                   help="base job file whose settings every job shares (job keys win)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DIR",
                   help="output folder (summary table; per-job folders)")
    p.add_argument("--summary-only", action="store_true",
                   help="write only the summary table, not each job's outputs")
    p.add_argument("--report", action="store_true", help="also write each job's report.html")
    add_backend_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from ..batch import expand_jobs, run_batch

    files, _ = expand_jobs(list(args.jobs))
    with output_folder(args, args.output, protect=[args.settings, *files]):
        with make_backend(args) as ex:
            res = run_batch(args.jobs, settings=args.settings, out_dir=args.output,
                            executor=ex, write_outputs=not args.summary_only,
                            report=args.report, progress=not args.no_progress)
        paths = res.write(args.output)
    s = res.summary
    for pat in s["unmatched_patterns"]:
        print(f"warning: no file matched {pat!r}")
    cols = ["job", "status", "imu_samples", "total_s", "forward_rms_h_m", "smoothed_rms_h_m",
            "forward_end_h_err_m_max"]
    with pd.option_context("display.width", 160, "display.max_columns", 20,
                           "display.float_format", "{:.3f}".format):
        print(res.table[cols].to_string(index=False))
    for k in s["skipped"]:
        print(f"skipped {k['file']}: {k['reason']}")
    for f in res.failures:
        print(f"FAILED {f['job']} ({f['file']}): {f['error']}: {f['message']}")
    print(f"{s['jobs']} jobs: {s['ok']} ok, {s['incomplete']} incomplete, {s['failed']} failed, "
          f"{len(s['skipped'])} skipped in {s['elapsed_s']:.1f} s ({s['executor']['backend']}); "
          f"wrote {', '.join(p.name for p in paths.values())} to {args.output}")
    return 0 if s["ok"] == s["jobs"] - len(s["skipped"]) else 3
