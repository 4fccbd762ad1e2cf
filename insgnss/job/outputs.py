"""Outputs of a run (``[outputs]``, docs/jobs.md): forward and smoothed trajectories in the
requested formats, innovation and rejection logs, outage tables, ``summary.json`` and the HTML
report, written as one file set (:class:`insgnss.io.outputset.OutputSet`)."""

from __future__ import annotations

import json
from pathlib import Path

from ..evaluate import move_point
from ..filter.store import select_rows, solution_table
from ..io.native import (
    atomic_write,
    atomic_write_text,
    decimation_rows,
    jsonable,
    select_output_columns,
    write_parquet,
    write_table,
)
from ..io.outputset import MARKER, OutputSet
from ..io.spill import trim_heap
from ..report_data import REPORT_FILES
from .result import JobResult
from .summary import incomplete_reason

#: every file name write_outputs may produce (a previous run's files that a new run does not
#: produce are removed when the new set is committed, so a folder never mixes two runs)
OUTPUT_NAMES = tuple(
    [f"{t}{ext}" for t in ("forward", "smoothed")
     for ext in (".csv", ".parquet", ".nav", ".kml", ".geojson", "_eval.csv")]
    + ["innovations.csv", "rejected.csv", "outages_forward.csv", "outages_smoothed.csv",
       "summary.json", "report.html"] + list(REPORT_FILES))


def write_outputs(result: JobResult, out_dir: str | Path | None = None) -> dict[str, Path]:
    """Write trajectories, logs, summary and report of a run; returns the paths by name.

    The files form one set (:class:`insgnss.io.outputset.OutputSet`): they are written into a
    hidden staging folder and moved onto their final names together at the end, so an
    interrupted run leaves the previous outputs complete, or (interrupted during the final
    renames) a set marked by an ``INCOMPLETE`` file. A run whose filter stopped early writes
    what it computed and keeps ``INCOMPLETE`` (with the reason; ``summary.json`` has
    ``"complete": false``, the error and ``"stopped_at"``); so does a run that went to its end
    but applied nothing of an aiding source it asks for (``result.failure``). No output may
    overwrite an input.
    """
    job = result.job
    out = Path(out_dir) if out_dir is not None else job.output_dir
    complete = bool(result.summary.get("complete", result.filter.complete))
    with OutputSet(out, protect=job.input_paths(), stale=OUTPUT_NAMES + (MARKER,)) as outs:
        dest = outs.path
        if job["outputs"]["report"]:  # report.html, report_interactive.html, fig_* files
            from ..report import write_report

            # the figures are drawn by other processes while this one writes the tables
            write_report(result, dest("report.html"), dest=dest,
                         figures=job["outputs"].get("figures", ()),
                         while_drawing=lambda: write_tables(result, dest))
        else:
            write_tables(result, dest)
        summary = dict(result.summary)
        summary["files"] = sorted(outs.names + ["summary.json"]
                                  + ([] if complete else [MARKER]))
        atomic_write_text(dest("summary.json"), json.dumps(jsonable(summary), indent=2) + "\n")
        reason = incomplete_reason({**summary, "complete": complete})
        return outs.commit(complete=complete, reason=reason)


def write_tables(result: JobResult, dest) -> None:
    """The forward and smoothed trajectories in the job's formats, the innovation and
    rejection logs and the outage tables; ``dest(name)`` is the path of an output."""
    job = result.job
    # [outputs] rate_hz: the samples around the aiding epochs stay (the forward solution
    # jumps there; insgnss.columns)
    epochs = [x.index for x in (result.inputs.gnss, result.inputs.control_points)
              if x is not None]
    rate, preset = job["outputs"]["rate_hz"], job["process"]["preset"]

    def rows_of(t):
        return decimation_rows(t, rate, epochs, preset)

    for name in ("forward", "smoothed"):
        # the kept rows only, read in blocks from the engine's arrays (possibly memory-mapped:
        # no whole-log DataFrame is built; docs/filter.md, Memory), one solution at a time
        sol = select_rows(solution_table(result.filter, name), rows_of)
        if sol is not None:
            write_solution(result, name, sol, dest)
        sol = None
        trim_heap()  # the written table's rows go back to the system
    for name in ("innovations", "rejected"):
        log = getattr(result.filter, name)
        write_table(log.set_index("time") if "time" in log.columns else log,
                    dest(f"{name}.csv"))
    for name, ev in result.evaluation.items():
        if len(ev["outages"]):
            table = ev["outages"]
            atomic_write(dest(f"outages_{name}.csv"),
                         lambda p, table=table: table.to_csv(p, index=False))


def write_solution(result: JobResult, name: str, sol, dest) -> None:
    """One solution's rows ``sol`` (at the IMU) in each of the job's trajectory formats, at
    the job's output point."""
    job = result.job
    formats = job["outputs"]["formats"]
    df = move_point(sol, result.inputs.lever_arm) if job["outputs"]["point"] == "antenna" \
        else sol
    table = select_output_columns(df, job["outputs"]["columns"])  # csv, parquet
    if "csv" in formats:
        write_table(table, dest(f"{name}.csv"))
    if "parquet" in formats:
        write_parquet(table, dest(f"{name}.parquet"))
    table = None
    # the time base of the data, for the UTC time stamps of the KML / GeoJSON tracks
    base = result.inputs.imu.attrs.get("time_base")
    clock = {"time_base": job["job"]["time_base"] if base in (None, "unspecified") else base,
             "week": result.inputs.imu.attrs.get("gps_week")}
    if "nav" in formats:
        from ..io.kfgins import write_kfgins_nav

        write_kfgins_nav(df, dest(f"{name}.nav"))
    if "kml" in formats:
        from ..io.tracks import write_kml

        write_kml({name: df}, dest(f"{name}.kml"), **clock)
    if "geojson" in formats:
        from ..io.tracks import write_geojson

        write_geojson({name: df}, dest(f"{name}.geojson"), **clock)
    if "eval" in formats:
        from ..io.tracks import write_eval_csv

        write_eval_csv(move_point(sol, result.inputs.lever_arm), dest(f"{name}_eval.csv"))


__all__ = ["OUTPUT_NAMES", "write_outputs", "write_solution", "write_tables"]
