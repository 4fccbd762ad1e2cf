"""Batch processing: many recorded logs with the same settings, one summary table.

``insgnss batch JOB_GLOB... [--settings BASE.toml]`` expands the patterns (``*``, ``?``, ``[..]``
and ``**`` for sub-folders) into job files, sorted and without duplicates. Each job runs end to
end (:func:`insgnss.pipeline.run_job`) as one work unit on an
:mod:`insgnss.executors` back-end; the unit is self-contained (the job file's path, the parsed
settings and the output folder), so it runs unchanged on a Dask cluster whose workers see the
same paths (a shared file system).

Settings: every job file may be complete; with ``settings`` (a base job, e.g. the lab's
standard processing) each job file only needs what differs (typically ``[inputs]`` and
``[job] name``): the two are merged table by table, the job file's keys winning
(:func:`merge_settings`). Relative paths are resolved against the job file.

Per job the worker writes the usual outputs (trajectories, logs, summary, report) into
``OUT/<job name>/`` (``write_outputs=False``: none) and returns one summary row
(:data:`COLUMNS`): status (``ok``, ``incomplete`` when the filter stopped early, ``failed``
when the job raised), the error, IMU samples and span, the initialization, the measurement and
rejection counts, the timing and, with a reference, the evaluation metrics of the forward and
smoothed solutions (docs/jobs.md). A failed job is reported and does not stop the others.
Files that are not jobs to run are skipped with a one-line reason (:func:`skip_reason`,
status ``skipped``): settings-only files (for ``--settings``) and jobs whose data is not
present, so ``insgnss batch 'scenarios/*.toml'`` runs what it can.
The table is written as ``batch.csv`` and ``batch.parquet`` plus ``batch.json`` (failures with
tracebacks, back-end, timing); every file atomically.
"""

from __future__ import annotations

import glob
import json
import time as _time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from .config import load_job_dict
from .errors import ConfigError

__all__ = ["COLUMNS", "BatchResult", "expand_jobs", "merge_settings", "run_batch",
           "run_batch_job"]

#: evaluation metrics copied per solution into the table (``forward_<key>``, ``smoothed_<key>``)
METRICS = ("rms_h_m", "max_h_m", "non_outage_rms_h_m", "non_outage_rms_v_m", "n_outages",
           "end_h_err_m_mean", "end_h_err_m_max", "rms_h_err_m_mean")
COLUMNS = ["job", "file", "status", "error", "imu_samples", "start_s", "end_s", "duration_s",
           "initialization", "heading_source", "measurements", "rejected", "filter_s", "total_s",
           *[f"{s}_{m}" for s in ("forward", "smoothed") for m in METRICS], "output_dir"]


def expand_jobs(patterns: list[str] | tuple[str, ...]) -> tuple[list[Path], list[str]]:
    """Job files matched by the patterns (sorted, unique) and the patterns that matched
    nothing. A pattern without wildcards is taken as a path (kept even if it does not exist,
    so that the batch reports it)."""
    found: dict[Path, None] = {}
    empty = []
    for pat in patterns:
        if glob.has_magic(pat):
            hits = sorted(Path(p) for p in glob.glob(pat, recursive=True) if Path(p).is_file())
            if not hits:
                empty.append(pat)
        else:
            hits = [Path(pat)]
        for h in hits:
            found.setdefault(h.resolve(), None)
    return sorted(found), empty


def merge_settings(base: dict, job: dict) -> dict:
    """Deep merge of two parsed job dicts: tables are merged key by key, ``job`` wins."""
    out = dict(base)
    for k, v in job.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = merge_settings(out[k], v)
        else:
            out[k] = v
    return out


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError("job file not found", file=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=path) from None


def skip_reason(path: Path, data: dict | None, base: dict | None) -> str | None:
    """Why a matched file is not a job to run (None when it is): a settings-only file (no
    ``[inputs.imu] path`` and no simulation ``[scenario]``; meant for ``--settings``), or a
    job whose input files are not present (e.g. a bundled real-data job without the data).
    A file that cannot be read or validated is not skipped: its work unit reports it."""
    if data is None:
        return None
    merged = merge_settings(base, data) if base else data
    try:
        job = load_job_dict(merged, path)
    except ConfigError:
        return None
    if not job.simulation and job["inputs"]["imu"]["path"] is None:
        return ("settings only (no [inputs.imu] path and no [scenario]): use it with "
                "--settings")
    missing = [p for p in job.input_paths() if not p.exists()]
    if missing:
        more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
        return f"data not present: {missing[0]}{more}"
    return None


def _label(path: Path, data: dict) -> str:
    name = data.get("job", {}).get("name")
    return name if isinstance(name, str) and name and name != "job" else path.stem


def run_batch_job(path: str, base: dict | None = None, out_dir: str | None = None,
                  write_outputs: bool = True, report: bool = False) -> dict:
    """Process one job file (the work unit): returns its summary row (see :data:`COLUMNS`).

    Raises for a job that cannot run (bad file, bad settings, unreadable data): the executor
    reports it with the file as the label.
    """
    from .pipeline import run_job
    from .pipeline import write_outputs as write

    p = Path(path)
    data = _read_toml(p)
    merged = merge_settings(base, data) if base else data
    job = load_job_dict(merged, p)
    if not report:
        job.settings["outputs"]["report"] = False
    if write_outputs and out_dir is not None:  # before computing (insgnss.io.outputset)
        from .io.outputset import MARKER, check_output_location
        from .pipeline import OUTPUT_NAMES

        check_output_location(out_dir, protect=job.input_paths(), names=(*OUTPUT_NAMES, MARKER))
    res = run_job(job, progress=False)
    s = res.summary
    row = {"job": s["job"] if s["job"] != "job" else p.stem, "file": str(p),
           "status": "ok" if s["complete"] else "incomplete", "error": s["error"] or "",
           "imu_samples": s["imu_samples"]}
    fwd = res.filter.forward
    t = fwd.index.to_numpy(float) if fwd is not None and len(fwd) else None
    row.update(start_s=float(t[0]) if t is not None else float("nan"),
               end_s=float(t[-1]) if t is not None else float("nan"),
               duration_s=float(t[-1] - t[0]) if t is not None else float("nan"),
               initialization=s["initialization"]["method"],
               heading_source=s["initialization"]["heading_source"],
               measurements=json.dumps({k: c["applied"] for k, c in s["measurements"].items()},
                                       sort_keys=True),
               rejected=json.dumps({k: c["rejected"] for k, c in s["measurements"].items()
                                    if c["rejected"]}, sort_keys=True),
               filter_s=float(s["timing_s"].get("total", float("nan"))),
               total_s=float(s["timing_s"].get("job_total", float("nan"))))
    for sol in ("forward", "smoothed"):
        ev = s["evaluation"].get(sol, {})
        for m in METRICS:
            row[f"{sol}_{m}"] = float(ev[m]) if ev.get(m) is not None else float("nan")
    row["output_dir"] = ""
    if write_outputs and out_dir is not None:
        write(res, out_dir)
        row["output_dir"] = str(out_dir)
    return row


@dataclass
class BatchResult:
    """The summary table (one row per job, :data:`COLUMNS`), the failures and a JSON-ready
    summary."""

    table: pd.DataFrame
    failures: list = field(default_factory=list)
    summary: dict = field(default_factory=dict)

    def write(self, out_dir: str | Path) -> dict[str, Path]:
        """``batch.csv``, ``batch.parquet`` and ``batch.json`` in ``out_dir`` (atomically)."""
        from .io.native import atomic_write, atomic_write_text, jsonable
        from .montecarlo import write_tidy

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"csv": atomic_write(out / "batch.csv",
                                     lambda p: self.table.to_csv(p, index=False)),
                 "parquet": write_tidy(self.table, out / "batch.parquet")}
        summary = dict(self.summary)
        summary["failures"] = self.failures
        summary["files"] = sorted(p.name for p in paths.values()) + ["batch.json"]
        paths["json"] = atomic_write_text(out / "batch.json",
                                          json.dumps(jsonable(summary), indent=2) + "\n")
        return paths


def _unique_names(paths: list[Path], datas: list[dict | None]) -> list[str]:
    names, seen = [], {}
    for p, d in zip(paths, datas, strict=True):
        n = _label(p, d or {})
        k = seen.get(n, 0)
        seen[n] = k + 1
        names.append(n if k == 0 else f"{n}_{k + 1}")
    return names


def run_batch(patterns: list[str] | tuple[str, ...], *, settings: str | Path | dict | None = None,
              out_dir: str | Path | None = None, executor=None, write_outputs: bool = True,
              report: bool = False, progress: bool = False) -> BatchResult:
    """Process every job file the patterns match (see the module docstring).

    Per-job outputs go to ``out_dir/<job name>/`` (names made unique) when ``write_outputs``
    and ``out_dir`` are given. Returns the :class:`BatchResult` (not written).
    """
    from ._version import __version__
    from .executors import InProcess

    files, empty = expand_jobs(list(patterns))
    if not files:
        raise ConfigError("no job file matched", found=list(patterns))
    if isinstance(settings, str | Path):
        base = _read_toml(Path(settings))
        base_name = str(Path(settings).resolve())
    else:
        base, base_name = settings, None
    if base is not None:  # validate the shared settings once, here
        load_job_dict(base, base_name, complete=False)
    datas = []
    for f in files:  # names only; a broken file is reported by its work unit
        try:
            datas.append(_read_toml(f))
        except ConfigError:
            datas.append(None)
    names = _unique_names(files, datas)
    skipped = {f: r for f, d in zip(files, datas, strict=True)
               if (r := skip_reason(f, d, base)) is not None}
    run_files = [f for f in files if f not in skipped]
    run_names = [n for f, n in zip(files, names, strict=True) if f not in skipped]
    out = Path(out_dir) if out_dir is not None else None
    tasks = [(str(f), base, None if out is None else str(out / n), write_outputs, report)
             for f, n in zip(run_files, run_names, strict=True)]
    ex = executor if executor is not None else InProcess()
    t0 = _time.perf_counter()
    outcomes = ex.run(run_batch_job, tasks, labels=[str(f) for f in run_files],
                      progress=progress, desc="batch") if tasks else []
    elapsed = _time.perf_counter() - t0
    rows, failures = [], []
    for f, n in zip(files, names, strict=True):
        if f in skipped:
            rows.append({"job": n, "file": str(f), "status": "skipped", "error": skipped[f]})
    for o, f, n in zip(outcomes, run_files, run_names, strict=True):
        if o.ok:
            rows.append(o.value)
        else:
            rows.append({"job": n, "file": str(f), "status": "failed", "error": str(o.error)})
            failures.append({"job": n, "file": str(f), "error": o.error.type,
                             "message": o.error.message, "traceback": o.error.traceback})
    table = pd.DataFrame(rows).reindex(columns=COLUMNS)
    counts = table["status"].value_counts().to_dict()
    summary = {"insgnss_version": __version__, "created": _time.strftime("%Y-%m-%dT%H:%M:%S%z"),
               "patterns": list(patterns), "unmatched_patterns": empty, "settings": base_name,
               "jobs": len(files), "ok": counts.get("ok", 0),
               "incomplete": counts.get("incomplete", 0), "failed": counts.get("failed", 0),
               "skipped": [{"file": str(f), "reason": r} for f, r in skipped.items()],
               "executor": ex.describe(), "elapsed_s": elapsed,
               "jobs_per_minute": 60.0 * len(files) / elapsed if elapsed > 0 else None}
    return BatchResult(table, failures, summary)
