"""Run a TOML job end to end: read the inputs (or simulate a scenario), initialize, run the
error-state filter and the RTS smoother with the job's aiding, evaluate against the reference,
and write the forward and smoothed trajectories, innovation and rejection logs, a JSON summary
and an HTML report (docs/jobs.md).

Exit status: 0 complete; 2 bad input or job (the error names file, row, column), or an aiding
source the job asks for of which nothing could be applied (every epoch removed by a quality
filter, an outage window, the IMU span or the innovation gate: when this is found after the
filter ran, the outputs are written for inspection and marked by an INCOMPLETE file); 3 the
filter stopped early (non-finite or non-positive-definite state, runaway NIS): the results up
to the stop are written and marked by an INCOMPLETE file; 130 interrupted (Ctrl-C): the
previous outputs are left as they were.

Example:
  insgnss process scenarios/drive_0708.toml -o out/drive
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._outputs import add_wait_argument, output_folder

NAME = "process"
HELP = "run a job file end to end (filter, smoother, evaluation, report)"
#: exit status of a run whose filter stopped early (partial outputs written, marked INCOMPLETE)
EXIT_INCOMPLETE = 3


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("job", type=Path, help="TOML job file")
    p.add_argument("-o", "--output", type=Path,
                   help="output folder, relative to the current folder (default: the job's "
                   "[outputs] dir, relative to the job file; docs/jobs.md, Paths)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-report", action="store_true", help="do not write report.html")
    p.add_argument("--seed", type=int, help="simulation seed (jobs that simulate a scenario)")
    add_wait_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..compile_ahead import compile_ahead
    from ..config import load_job
    from ..job.processes import process_name
    from ..pipeline import incomplete_reason, run_job, write_outputs

    job = load_job(args.job)
    if args.no_report:
        job.settings["outputs"]["report"] = False
    out = args.output or job.output_dir
    with output_folder(args, out, protect=job.input_paths(), names=output_names()), \
            compile_ahead(process_name(job)):  # on a cold numba cache only
        if job["outputs"]["report"]:
            # the report's figure workers import matplotlib on the other cores meanwhile
            from ..report import start_figure_workers

            start_figure_workers()
        try:
            res = run_job(job, progress=False if args.no_progress else None, seed=args.seed,
                          spill_dir=out)
            paths = write_outputs(res, out)
        finally:
            from ..report import stop_figure_workers

            stop_figure_workers()
    print_summary(res)
    print(f"wrote {len(paths)} files to {out}")
    if not res.summary["complete"]:
        print(f"insgnss process: INCOMPLETE: {incomplete_reason(res.summary).splitlines()[0]}\n"
              f"insgnss process: the results are in {out}, marked by the file INCOMPLETE and "
              f"\"complete\": false in summary.json", file=sys.stderr)
        if res.failure is not None:
            raise res.failure  # exit status 2 (cli.main)
        return EXIT_INCOMPLETE
    return 0


def output_names() -> tuple[str, ...]:
    """Every file name a job run may write or remove in its output folder."""
    from ..io.outputset import MARKER
    from ..pipeline import OUTPUT_NAMES

    return (*OUTPUT_NAMES, MARKER)


def print_summary(res) -> None:
    from ..pipeline import incomplete_reason

    s = res.summary
    if not s["complete"]:
        print(f"INCOMPLETE: {incomplete_reason(s).splitlines()[0]}")
    for note in s.get("aiding_warnings") or []:
        print(f"WARNING: {note}")
    imu = s.get("imu") or {}
    if imu.get("gaps") or imu.get("dropped_duplicates"):
        gaps = imu.get("gaps") or []
        longest = max((g["duration"] for g in gaps), default=0.0)
        print(f"IMU: {len(gaps)} gap(s) (longest {longest:.3f} s, "
              f"{sum(g['missing'] for g in gaps)} samples missing), "
              f"{len(imu.get('dropped_duplicates') or [])} duplicated sample(s) dropped, "
              f"{len(imu.get('segments') or [1])} segment(s)")
    for sp in imu.get("spikes") or []:
        unit = "deg/s" if sp["sensor"] == "gyro" else "m/s^2"
        print(f"IMU spike at t = {sp['time']:.3f} s (row {sp['row']}): {sp['sensor']} "
              f"{sp['value']:.4g} {unit} between {sp['neighbours']:.4g} {unit}, {sp['action']}")
    for ev in s.get("heading_reinitialisations") or []:
        print(f"heading re-initialised at t = {ev['time']:.3f} s: {ev['old_heading_deg']:.1f} -> "
              f"{ev['new_heading_deg']:.1f} deg (GNSS course, sigma "
              f"{ev['heading_std_deg']:.1f} deg): {ev['reason']}")
    t = s["timing_s"]
    print(f"{s['job']}: {s['imu_samples']:,} IMU samples, filter {t.get('total', 0):.2f} s, "
          f"job {t.get('job_total', 0):.2f} s")
    for name, e in s["evaluation"].items():
        line = f"  {name:9s} horizontal RMS {e['rms_h_m']:.3f} m, max {e['max_h_m']:.3f} m"
        if e.get("n_outages"):
            line += (f"; outages: end {e['end_h_err_m_mean']:.3f} m (mean), in-outage RMS "
                     f"{e['rms_h_err_m_mean']:.3f} m, non-outage RMS "
                     f"{e['non_outage_rms_h_m']:.3f} m")
        print(line)
