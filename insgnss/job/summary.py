"""The summary of a run (``summary.json``, docs/jobs.md): what ran, how it was initialized,
the measurements, the outage windows, timing and the evaluation figures."""

from __future__ import annotations

import time

import numpy as np

from ..config import Job
from .initialization import Initialization
from .result import JobResult


def job_name(job: Job) -> str:
    """The run name: ``[job] name``, else a simulated scenario's name."""
    name = job["job"]["name"]
    if name == "job" and job.simulation.get("scenario", {}).get("name"):
        name = job.simulation["scenario"]["name"]
    return name


def initialization_summary(init: Initialization, method: str | None = None,
                           heading_source: str | None = None) -> dict:
    """Method, heading source, time and Euler angles [deg] of the initial state."""
    r, p, h = init.state.euler
    return {"method": method or init.method, "heading_source": heading_source or
            init.heading_source, "time": init.state.time, "roll_deg": float(np.degrees(r)),
            "pitch_deg": float(np.degrees(p)), "heading_deg": float(np.degrees(h))}


def rejected_counts(rejected) -> dict:
    """Rejections per measurement type from a rejection log."""
    return rejected.groupby("type").size().astype(int).to_dict() if len(rejected) else {}


def stopped_at(res) -> float | None:
    """Time [s] at which a filter that stopped early stopped (None when complete)."""
    final = getattr(res, "final", None)
    return None if res.complete or final is None else float(final.time)


def filter_summary(out: JobResult, meas: list, model_name: str, n_imu: int, t_start: float,
                   timing: dict, extra: dict) -> dict:
    """Summary of a run of the filter engine (strapdown or RISS process model)."""
    job, res = out.job, out.filter
    return {
        "job": job_name(job), "source": out.inputs.source, "seed": out.inputs.seed,
        "process_model": job["filter"]["process_model"],
        "complete": bool(res.complete), "error": None if res.error is None else str(res.error),
        "stopped_at": stopped_at(res),
        "imu_samples": int(n_imu), "initialization": initialization_summary(out.init),
        "measurements": {m.name: int(len(m)) for m in meas},
        "rejected": rejected_counts(res.rejected),
        "outages": [list(w) for w in out.windows],
        "imu_model": model_name,
        **extra,
        "timing_s": {**res.timing, **timing, "job_total": time.perf_counter() - t_start},
        "evaluation": {k: v["summary"] for k, v in out.evaluation.items()},
    }


__all__ = ["filter_summary", "initialization_summary", "job_name", "rejected_counts",
           "stopped_at"]
