"""The summary of a run (``summary.json``, docs/jobs.md): what ran and with what
(:func:`provenance`: insgnss version, the resolved job, the input files' SHA-256), how it was
initialized,
the measurements (offered, applied, rejected, recovered, unusable per type; see
:mod:`.aiding`), the outage windows, timing and the evaluation figures; whether the run is
complete and, if not, why (:func:`incomplete_reason`)."""

from __future__ import annotations

import hashlib
import time
from pathlib import Path

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
    """Method, heading source, time and Euler angles [deg] of the initial state, its sigmas
    and (static) how the static window was found (``static_window``)."""
    r, p, h = init.state.euler
    out = {"method": method or init.method, "heading_source": heading_source or
           init.heading_source, "time": init.state.time, "roll_deg": float(np.degrees(r)),
           "pitch_deg": float(np.degrees(p)), "heading_deg": float(np.degrees(h)),
           "attitude_std_deg": [float(np.degrees(v)) for v in np.broadcast_to(init.att_std, 3)]}
    if init.static_info is not None:
        out["static_window"] = dict(init.static_info)
    return out


def platform_summary(job: Job) -> dict:
    """The platform profile of a job and the values it provided (``summary.json``
    ``"platform"``): what ran is the job file's keys over these over the schema defaults."""
    return {"name": job.platform, "from_profile": dict(job.from_profile)}


def stopped_at(res) -> float | None:
    """Time [s] at which a filter that stopped early stopped (None when complete)."""
    final = getattr(res, "final", None)
    return None if res.complete or final is None else float(final.time)


def status(out: JobResult) -> dict:
    """``complete``, ``error``, ``stopped_at`` of a run: incomplete when the filter stopped
    early (its health error) or when an aiding source was not applied at all
    (``out.failure``)."""
    res = out.filter
    err = res.error if res.error is not None else out.failure
    return {"complete": bool(res.complete) and out.failure is None,
            "error": None if err is None else str(err), "stopped_at": stopped_at(res)}


def incomplete_reason(summary: dict) -> str:
    """Why a run is incomplete, for the ``INCOMPLETE`` marker and the command line ("" when
    complete)."""
    if summary.get("complete", True):
        return ""
    t = summary.get("stopped_at")
    if t is not None:
        return (f"The filter stopped early at t = {t:.3f} s: {summary.get('error')}\n"
                'The trajectories and logs end there (summary.json has "complete": false).')
    return (f"The run is not usable: {summary.get('error')}\nThe trajectories and logs are "
            'written for inspection (summary.json has "complete": false).')


def filter_summary(out: JobResult, counts: dict, notes: list[str], model_name: str,
                   n_imu: int, t_start: float, timing: dict, extra: dict) -> dict:
    """Summary of a run of the filter engine (strapdown or RISS process model); ``counts``
    are the measurement counts, ``notes`` the aiding warnings."""
    job, res = out.job, out.filter
    return {
        "job": job_name(job), "description": job["job"]["description"],
        "source": out.inputs.source, "seed": out.inputs.seed,
        "process_model": job["filter"]["process_model"],
        "platform": platform_summary(job),
        **status(out),
        "imu_samples": int(n_imu), "initialization": initialization_summary(out.init),
        "measurements": counts,
        "aiding_warnings": list(notes),
        "heading_reinitialisations": list(getattr(res, "heading_reinits", None) or []),
        "outages": [list(w) for w in out.windows],
        "imu_model": model_name,
        **extra,
        "timing_s": {**res.timing, **timing, "job_total": time.perf_counter() - t_start},
        "evaluation": {k: v["summary"] for k, v in out.evaluation.items()},
    }


def file_checksum(path: Path, chunk: int = 1 << 20) -> dict:
    """``{"path", "bytes", "sha256"}`` of a file (read in chunks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return {"path": str(path), "bytes": path.stat().st_size, "sha256": h.hexdigest()}


def input_checksums(job: Job) -> list[dict]:
    """:func:`file_checksum` of every input file of ``job`` that exists (the job file
    included)."""
    return [file_checksum(p) for p in job.input_paths() if p.is_file()]


def checksums_beside(job: Job):
    """Start :func:`input_checksums` in a thread beside the run (``hashlib`` and file reads
    release the GIL: on a second core the 170 MB of a 1 h / 200 Hz log cost the run no time);
    returns a function that waits for them, the list (``None`` if a file could not be read:
    :func:`provenance` then reads again and reports it)."""
    import threading

    out: list = []

    def work():
        try:
            out.append(input_checksums(job))
        except OSError:
            out.append(None)

    th = threading.Thread(target=work, name="insgnss-checksums", daemon=True)
    th.start()

    def result() -> list[dict] | None:
        th.join()
        return out[0] if out else None

    return result


def provenance(job: Job, checksums=None) -> dict:
    """What reproduces a run: the insgnss ``version``, the fully resolved job
    (``job_resolved``: every key with its default filled in, and the simulation tables of a
    simulated job) and the SHA-256 of every input file, the job file included
    (``input_files``; ``checksums``: the waiting function of :func:`checksums_beside`)."""
    from .._version import __version__

    resolved = dict(job.settings)
    if job.simulation:
        resolved["simulation"] = dict(job.simulation)
    files = checksums() if checksums is not None else None
    return {"version": __version__, "job_resolved": resolved,
            "input_files": input_checksums(job) if files is None else files}


def measurement_rows(summary: dict) -> list[str]:
    """One line per measurement type of ``summary["measurements"]``, e.g. ``"gnss_pos: 1510 of
    1524 offered applied (14 rejected, 0 recovered by the gate recovery, 0 unusable)"``, then
    the aiding warnings; for reports and printouts."""
    rows = []
    for kind, c in (summary.get("measurements") or {}).items():
        if not isinstance(c, dict):  # a summary written before the counts had fields
            rows.append(f"{kind}: {c}")
            continue
        rows.append(f"{kind}: {c.get('applied', 0)} of {c.get('offered', 0)} offered applied "
                    f"({c.get('rejected', 0)} rejected, {c.get('recovered', 0)} recovered by "
                    f"the gate recovery, {c.get('unusable', 0)} unusable)")
    rows += [f"warning: {n}" for n in summary.get("aiding_warnings") or []]
    return rows


def add_counts(parts: list[dict]) -> dict:
    """Measurement counts of several runs (segments) added per type and field."""
    out: dict = {}
    for counts in parts:
        for kind, c in counts.items():
            tot = out.setdefault(kind, dict.fromkeys(c, 0))
            for k, v in c.items():
                tot[k] = tot.get(k, 0) + int(v)
    return out


__all__ = ["add_counts", "file_checksum", "filter_summary", "incomplete_reason",
           "initialization_summary", "job_name", "measurement_rows", "platform_summary",
           "provenance", "status", "stopped_at"]
