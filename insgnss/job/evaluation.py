"""Evaluation of a run against the job's reference (``[inputs.reference]``, ``[evaluation]``):
position errors at the reference epochs, at the point the reference measures, and the outage
metrics of the drive benchmark protocol (:mod:`insgnss.evaluate`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..config import Job
from ..evaluate import move_point, outage_metrics, position_errors
from .inputs import Inputs
from .result import JobResult


def evaluate_solution(sol: pd.DataFrame, inputs: Inputs, windows, job: Job) -> dict:
    """Errors of one solution against the job's reference (empty without a reference):
    ``{"errors": table, "outages": table, "summary": dict}``."""
    if inputs.reference is None or sol is None or not len(sol) or \
            not job["evaluation"]["enabled"]:  # (a filter stopped at its first epoch)
        return {}
    pt = move_point(sol, inputs.lever_arm) if inputs.reference_point == "antenna" else sol
    err = position_errors(pt, inputs.reference)
    for s in ("east_std", "north_std", "up_std"):
        if s in sol.columns:
            err[s] = np.interp(err.index.to_numpy(float), sol.index.to_numpy(float),
                               sol[s].to_numpy(float))
    ev = job["evaluation"]
    t_first = float(inputs.gnss.index[0]) if inputs.gnss is not None and len(inputs.gnss) \
        else float(inputs.reference.index[0])
    table, summary = outage_metrics(err, windows, t_first=t_first,
                                    settle_time=ev["settle_time"], guard_time=ev["guard_time"])
    hz = err["horizontal"].dropna()
    summary["rms_h_m"] = float(np.sqrt(np.mean(hz.to_numpy() ** 2))) if len(hz) else float("nan")
    summary["max_h_m"] = float(hz.max()) if len(hz) else float("nan")
    summary["n_reference"] = int(len(err))
    summary["n_covered"] = int(err["horizontal"].notna().sum())
    return {"errors": err, "outages": table, "summary": summary}


def evaluate_result(out: JobResult) -> JobResult:
    """Fill ``out.evaluation`` for the forward and the smoothed solution; returns ``out``."""
    for name in ("forward", "smoothed"):
        ev = evaluate_solution(getattr(out.filter, name), out.inputs, out.windows, out.job)
        if ev:
            out.evaluation[name] = ev
    return out


__all__ = ["evaluate_result", "evaluate_solution"]
