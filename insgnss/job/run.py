"""Running a job: read the inputs, prepare them (the processing window ``[job] start`` /
``end``, IMU table policies, outage windows, IMU time offset), then run the job's process
(:mod:`.processes`) - once, or once per IMU segment in split mode (:mod:`.segments`, which
gets :func:`run_job` passed in) - and (:func:`process`) write its outputs."""

from __future__ import annotations

import time
from pathlib import Path

from ..config import Job, check_job_against_data
from ..errors import InvalidValueError
from ..policies import apply_spike_policy, check_imu_table, gap_policy, shift_report
from ..preprocess import (
    TimeCorrection,
    estimate_time_correction,
    estimate_velocity_lag,
    shift_time,
)
from ..validate import warn
from .context import RunContext
from .inputs import Inputs, imu_model, load_inputs
from .outputs import write_outputs
from .processes import run_process
from .result import JobResult
from .segments import run_segments
from .span import cut_inputs, processing_window
from .summary import checksums_beside, provenance
from .windows import outage_windows


def prepare(job: Job, *, progress: bool | None = None, seed: int | None = None,
            inputs: Inputs | None = None, spill_dir: str | Path | None = None) -> RunContext:
    """Read the inputs (unless given) and prepare them for a process: the IMU table policies
    (:func:`insgnss.policies.check_imu_table`), the outage windows and, when asked, the
    estimated IMU-GNSS time offset (``inputs.imu.estimate_time_offset``) and GNSS velocity lag
    (``inputs.gnss.estimate_velocity_lag``, kept in ``inputs.gnss.attrs["velocity_lag"]``).
    ``inputs.imu`` is replaced by the prepared table. ``spill_dir``: where the smoother's
    node store is memory-mapped beyond ``filter.store_memory_mb`` (default: the system's
    temporary folder)."""
    t_start = time.perf_counter()
    inputs = load_inputs(job, seed, spill_dir) if inputs is None else inputs
    t_read = time.perf_counter() - t_start
    all_gnss = inputs.gnss  # outage windows follow the whole recording (span.py)
    window = processing_window(job, inputs.imu)
    if window is not None:  # [job] start / end
        inputs = cut_inputs(inputs, window)
    # duplicates, gaps and segments of the table actually processed (policies.py)
    inputs.imu, imu_report = check_imu_table(inputs.imu, gap_policy(job),
                                             job["inputs"]["imu"]["duplicates"])
    inputs.imu, spikes = apply_spike_policy(inputs.imu, job["inputs"]["imu"]["spike_policy"])
    if spikes:
        imu_report["spikes"] = spikes
    check_job_against_data(job, imu_report["nominal_dt"],  # intervals, start time (config.py)
                           (float(inputs.imu.index[0]), float(inputs.imu.index[-1])))
    model = inputs.imu_model or imu_model(job, None)
    windows = outage_windows(job, all_gnss)
    preprocessing = {} if window is None else {"processing_window": list(window)}
    if job["inputs"]["imu"]["estimate_time_offset"] and inputs.gnss is not None:
        corr, info = _time_offset(job, inputs, windows)
        inputs.imu = shift_time(inputs.imu, corr)
        imu_report = shift_report(imu_report, corr)
        inputs.imu.attrs.update({k: imu_report[k] for k in ("gaps", "segments",
                                                            "dropped_duplicates")})
        preprocessing["imu_time_offset_estimated_s"] = corr.offset
        if corr.drift:
            preprocessing["imu_time_drift_ppm"] = corr.drift * 1e6
            preprocessing["imu_time_offset_reference_s"] = corr.t_ref
        preprocessing["imu_time_offset_info"] = info
    g = inputs.gnss
    if job["inputs"]["gnss"]["estimate_velocity_lag"] and g is not None and "vel_e" in g.columns \
            and "velocity_lag" not in g.attrs:
        lag, info = estimate_velocity_lag(g, windows)
        g.attrs["velocity_lag"] = lag  # the velocities belong to tag - lag (aiding.py)
        preprocessing["gnss_velocity_lag_s"] = lag
        preprocessing["gnss_velocity_lag_info"] = info
    show = job["outputs"]["progress"] if progress is None else progress
    return RunContext(job=job, inputs=inputs, model=model, windows=windows,
                      imu_report=imu_report, t_start=t_start, preprocessing=preprocessing,
                      timing={"read": t_read}, progress=bool(show),
                      spill_dir=None if spill_dir is None else Path(spill_dir))


def _time_offset(job: Job, inputs: Inputs, windows) -> tuple[TimeCorrection, dict]:
    """IMU-GNSS time offset and its drift (:func:`insgnss.preprocess.
    estimate_time_correction`). A job that asks for the estimate itself gets the error when the
    data cannot support one (too little motion or turning); when the request comes from the
    platform profile, the run warns and keeps the recorded time tags (offset 0), as the
    velocity-lag estimate does without evidence."""
    key = "inputs.imu.estimate_time_offset"
    i = job["inputs"]["imu"]
    try:
        return estimate_time_correction(inputs.imu, inputs.gnss, windows,
                                        min_speed=i["time_offset_min_speed"],
                                        drift=i["estimate_time_drift"])
    except InvalidValueError as e:
        if key in job.given:
            raise
        warn(f"the platform profile's IMU-GNSS time-offset estimate is skipped and the time "
             f"tags are kept: {e}", file=job.path, column=key)
        return TimeCorrection(), {"applied": False, "reason": str(e)}


def run_job(job: Job, *, progress: bool | None = None, seed: int | None = None,
            inputs: Inputs | None = None, spill_dir: str | Path | None = None) -> JobResult:
    """Run a validated job in memory (no result files written; beyond ``filter.
    store_memory_mb`` the smoother's node store is memory-mapped in ``spill_dir``, default
    the system's temporary folder, :mod:`insgnss.io.spill`)."""
    checksums = checksums_beside(job)
    ctx = prepare(job, progress=progress, seed=seed, inputs=inputs, spill_dir=spill_dir)
    if len(ctx.imu_report["segments"]) > 1:  # gap_policy = "split" and long gaps
        res = run_segments(ctx, lambda seg_job, seg_inputs: run_job(
            seg_job, progress=progress, inputs=seg_inputs, spill_dir=spill_dir))
    else:
        res = run_process(ctx)
    res.summary.update(provenance(job, checksums))  # version, resolved job, input checksums
    return res


def process(job: Job, out_dir: str | Path | None = None, *, progress: bool | None = None
            ) -> tuple[JobResult, dict[str, Path]]:
    """Run a job and write its outputs; returns the result and the written paths by name."""
    res = run_job(job, progress=progress, spill_dir=out_dir)
    return res, write_outputs(res, out_dir)


__all__ = ["prepare", "process", "run_job"]
