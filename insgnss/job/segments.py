"""Split runs (``[inputs.imu] gap_policy = "split"``): one run per contiguous IMU segment,
merged into one result.

The first segment uses the job's initialization; each later one starts at its first sample
(or the first usable GNSS epoch after it) with the job's method and falls back to
``gnss_velocity`` (GNSS position, velocity and course over ground) when that fails (a static
alignment while the vehicle moves); moving at the segment start (GNSS speed above
``initialization.min_speed``), ``gnss_velocity`` is tried first. A segment that cannot be
initialized (the first one too), or has fewer than :data:`MIN_SEGMENT_SAMPLES` samples, is
skipped with a warning and recorded; when no segment can be processed, the first segment's
error stops the run. The outputs hold the segments one after the other, with a ``segment``
column; the filter state and the smoother never cross a long gap.

What belongs to the sensor rather than to a segment carries over: the IMU time offset (applied
once to the whole table) and the IMU noise measured in a static window
(``filter.noise_from_static``): a later segment that starts moving cannot measure it and
would otherwise run with the datasheet noise, overconfident on a vibrating vehicle. The outage
windows of the whole run hold in every segment, for its initialization as for its aiding.

This module does not run a segment itself: the caller (:mod:`.run`) passes the single-run
function in, so that the segment logic does not depend on the step that calls it.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pandas as pd

from ..config import Job
from ..errors import InsgnssError
from ..validate import time_slice, warn
from .context import RunContext
from .evaluation import evaluate_result
from .initialization import MAX_INTERPOLATION
from .inputs import Inputs
from .result import JobResult
from .summary import add_counts
from .windows import outside_windows

#: fewest IMU samples a split segment needs to be processed
MIN_SEGMENT_SAMPLES = 100

#: runs one segment: (segment job, segment inputs) -> result
SegmentRunner = Callable[[Job, Inputs], JobResult]


def segment_job(job: Job, windows, start: float | None, method: str | None) -> Job:
    """The job of one segment: starts at ``start`` with ``method`` (None: the job's), the
    outage windows of the whole run as absolute windows, no long gap and no time offset left
    to handle (both were dealt with on the whole table)."""
    s = copy.deepcopy(job.settings)
    if start is not None:
        s["initialization"]["start_time"] = float(start)
    if method is not None:
        s["initialization"]["method"] = method
    s["inputs"]["imu"]["estimate_time_offset"] = False  # applied once to the whole table
    s["inputs"]["imu"]["gap_policy"] = "bridge"  # the segment has no long gap left
    s["outages"] = {"windows": [[float(a), float(b)] for a, b in windows],
                    "relative_to": "absolute",
                    "keep_satellites": job.settings["outages"]["keep_satellites"],
                    "periodic": {"start": None, "length": None, "gap": None,
                                 "stop_before_end": 0.0}}
    return Job(settings=s, path=job.path, simulation=job.simulation)


def run_segments(ctx: RunContext, run_one: SegmentRunner) -> JobResult:
    """Run the job on each contiguous IMU segment (``ctx.imu_report["segments"]``) with
    ``run_one`` and merge the results (module docstring).

    Returns a :class:`JobResult` whose ``filter`` holds the segments one after the other
    (``segment`` column in the trajectories and logs) and whose summary lists the segments
    (``"segments"``: start, end, initialization, complete, error or skip reason).
    """
    job, inputs, windows = ctx.job, ctx.inputs, ctx.windows
    imu = inputs.imu
    t = np.asarray(imu.index, float)
    results, info = [], []
    model = inputs.imu_model  # the IMU error model; later segments get the one segment 0 used
    first_error = None
    for k, (a, b) in enumerate(ctx.imu_report["segments"]):
        i0, i1 = np.searchsorted(t, a, "left"), np.searchsorted(t, b, "right")
        rec = {"segment": k, "start": float(a), "end": float(b), "samples": int(i1 - i0)}
        info.append(rec)
        if i1 - i0 < MIN_SEGMENT_SAMPLES:
            rec["skipped"] = f"fewer than {MIN_SEGMENT_SAMPLES} IMU samples"
            warn(f"IMU segment {k} ({a!r} to {b!r} s) skipped: {rec['skipped']}",
                 file=imu.attrs.get("source"))
            continue
        seg_imu = imu.iloc[i0:i1]
        gnss = inputs.gnss
        if gnss is not None:
            # from MAX_INTERPOLATION before the segment: the initial position at its first
            # sample is interpolated between GNSS epochs around it (the aiding takes only the
            # epochs inside the segment)
            gt = np.asarray(gnss.index, float)
            gnss = gnss.iloc[np.searchsorted(gt, a - MAX_INTERPOLATION, "left"):
                             np.searchsorted(gt, b, "right")]
        seg_inputs = replace(inputs, imu=seg_imu, gnss=gnss, imu_model=model)
        start = None if k == 0 else float(a)
        methods = [None]
        if k > 0 and job["initialization"]["method"] != "gnss_velocity" and gnss is not None \
                and "vel_e" in gnss.columns and len(gnss):
            # moving at the segment start (GNSS speed): start from GNSS position, velocity and
            # course; standing: the job's own method (e.g. a static alignment) first
            g0 = outside_windows(time_slice(gnss, a), windows)  # usable GNSS only
            moving = len(g0) and float(np.hypot(g0["vel_e"].iloc[0], g0["vel_n"].iloc[0])) > \
                job["initialization"]["min_speed"]
            methods = ["gnss_velocity", None] if moving else [None, "gnss_velocity"]
        res, errors = None, []
        for m in methods:
            try:
                res = run_one(segment_job(job, windows, start, m), replace(seg_inputs))
                break
            except InsgnssError as exc:
                first_error = first_error or exc
                errors.append(f"{m or job['initialization']['method']}: {exc}")
        if res is None:
            rec["skipped"] = "; ".join(errors)
            warn(f"IMU segment {k} ({a!r} to {b!r} s) skipped: cannot initialize: "
                 f"{rec['skipped']}", file=imu.attrs.get("source"))
            continue
        rec.update(initialization=res.summary["initialization"]["method"],
                   init_time=res.summary["initialization"]["time"],
                   complete=res.summary["complete"], error=res.summary["error"],
                   stopped_at=res.summary.get("stopped_at"),
                   evaluation={n: {key: e.get(key) for key in ("rms_h_m", "max_h_m", "n_covered")}
                               for n, e in res.summary["evaluation"].items()})
        results.append((k, res))
        model = res.model or model
    if not results:  # the first segment's error says why (a job or data problem)
        raise first_error or InsgnssError("no IMU segment could be processed",
                                          file=imu.attrs.get("source"))
    first = results[0][1]
    merged = merge_filter_results([(k, r.filter) for k, r in results])
    out = evaluate_result(JobResult(job, inputs, first.init, list(windows), merged))
    # the first segment that did not finish, or finished unusable, is the run's status
    bad = next(((k, r) for k, r in results if not r.summary["complete"]), None)
    out.failure = None if bad is None else bad[1].failure
    summary = dict(first.summary)
    summary.update(
        complete=bad is None,
        error=None if bad is None else f"IMU segment {bad[0]}: {bad[1].summary['error']}",
        stopped_at=None if bad is None else bad[1].summary.get("stopped_at"),
        imu_samples=int(sum(r.summary["imu_samples"] for _, r in results)),
        measurements=add_counts([r.summary["measurements"] for _, r in results]),
        aiding_warnings=[f"IMU segment {k}: {n}" for k, r in results
                         for n in r.summary.get("aiding_warnings", [])],
        heading_reinitialisations=list(merged.heading_reinits),
        outages=[list(w) for w in windows], segments=info, imu=ctx.imu_report,
        preprocessing=dict(ctx.preprocessing),
        evaluation={k: v["summary"] for k, v in out.evaluation.items()})
    summary["timing_s"] = {key: float(sum(r.summary["timing_s"].get(key, 0.0)
                                          for _, r in results))
                           for key in first.summary["timing_s"]}
    out.summary = summary
    return out


def merge_filter_results(parts):
    """One FilterResult holding several segments' results ``[(segment, result), ...]`` in time
    order."""

    def cat(name, seg_col=True):
        frames = []
        for k, f in parts:
            df = getattr(f, name)
            if df is None:
                return None
            if seg_col:
                df = df.copy()
                df["segment"] = k
            frames.append(df)
        out = pd.concat(frames)
        return out.reset_index(drop=True) if name in ("innovations", "rejected") else out

    fs = [f for _, f in parts]
    err = next((f.error for f in fs if f.error is not None), None)
    same = all(f.P_filtered.shape[1:] == fs[0].P_filtered.shape[1:] for f in fs)

    def stack(name):
        arrs = [getattr(f, name) for f in fs]
        if not same or any(a is None for a in arrs):
            return None
        return np.concatenate(arrs)

    timing = {k: float(sum(f.timing.get(k, 0.0) for f in fs)) for k in fs[0].timing}
    merged = replace(fs[0], forward_table=cat("forward"), smoothed_table=cat("smoothed"),
                     log=None, complete=all(f.complete for f in fs), error=err, timing=timing,
                     epoch_times=np.concatenate([f.epoch_times for f in fs]),
                     P_filtered=stack("P_filtered"), P_predicted=stack("P_predicted"),
                     feedback=stack("feedback"), P_smoothed=stack("P_smoothed"),
                     params=stack("params"), final=fs[-1].final,
                     heading_reinits=[dict(ev, segment=k) for k, f in parts
                                      for ev in getattr(f, "heading_reinits", [])])
    # the segments' innovation logs number their types apart: the merged tables are kept
    # built (with their segment column) instead of one merged log
    merged.__dict__["_innov"] = (cat("innovations"), cat("rejected"))
    return merged


__all__ = ["MIN_SEGMENT_SAMPLES", "merge_filter_results", "run_segments", "segment_job"]
