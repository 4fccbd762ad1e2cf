"""Evaluation of a run against the job's reference (``[inputs.reference]``, ``[evaluation]``):
position errors at the reference epochs, at the point the reference measures, the outage
metrics of the drive benchmark protocol (:mod:`insgnss.evaluate`) and the single-run position
NEES.

Position NEES ``e^T P^-1 e`` (3 dof; :func:`insgnss.consistency.nees_blocks`) at the reference
epochs that are filter epochs, with the full position block of the forward ``P(e|e)`` or the
smoothed ``P`` (the error state's position at the IMU point; the error at the reference point
differs by the lever arm times the attitude error, millimetres; not for the wander-azimuth
frame, whose P is in ECEF axes). Summarised over the epochs
inside the outage windows (``nees_pos_outage_*``): there the reference is independent of the
filter, while outside them the GNSS fixes the filter uses are often the reference itself
(``nees_pos_*`` over all epochs is then far below 3). A consistent filter has a mean of 3 and
99.73 % of the epochs below ``chi2_3(99.73 %)`` = 14.16 (``*_within_3sigma_fraction``; the
epochs of one outage are correlated, so this is no independent-sample test).
"""

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


#: chi-square point of 3 dof at the 3-sigma probability (99.73 %)
CHI2_3DOF_3SIGMA = 14.156


def position_nees(err: pd.DataFrame, epoch_times, P, windows) -> dict:
    """Summary of the position NEES (module docstring) at the rows of ``err`` (``east north
    up`` at reference epochs) that are epochs ``epoch_times`` of the covariances ``P``; empty
    without covariances or coinciding epochs."""
    from ..consistency import match_times, nees_blocks
    from ..outages import in_windows

    if P is None or epoch_times is None or not len(epoch_times) or not len(err):
        return {}
    ep = np.asarray(epoch_times, float)[: P.shape[0]]
    t = err.index.to_numpy(float)
    k = match_times(t, ep)
    e = err[["east", "north", "up"]].to_numpy(float)
    use = (k >= 0) & np.isfinite(e).all(axis=1)
    if not np.any(use):
        return {}
    x = np.column_stack([e[use], np.zeros((int(use.sum()), 6))])
    nees = nees_blocks(x, P[k[use]][:, :9, :9])[:, 0]
    inside = in_windows(t[use], windows)
    out = {}
    for tag, m in (("nees_pos", np.isfinite(nees)), ("nees_pos_outage", inside & np.isfinite(nees))):
        v = nees[m]
        out[f"{tag}_n"] = int(v.size)
        if v.size:
            out[f"{tag}_mean"] = float(np.mean(v))
            out[f"{tag}_median"] = float(np.median(v))
            out[f"{tag}_within_3sigma_fraction"] = float(np.mean(v <= CHI2_3DOF_3SIGMA))
    return out


def evaluate_result(out: JobResult) -> JobResult:
    """Fill ``out.evaluation`` for the forward and the smoothed solution (with the position
    NEES where the filter kept its epoch covariances); returns ``out``."""
    for name in ("forward", "smoothed"):
        ev = evaluate_solution(getattr(out.filter, name), out.inputs, out.windows, out.job)
        if ev:
            # (the wander-azimuth model keeps P in ECEF axes: no ENU NEES from it)
            P = None if out.job["filter"]["frame"] == "wander" else \
                getattr(out.filter, "P_filtered" if name == "forward" else "P_smoothed", None)
            ev["summary"].update(position_nees(ev["errors"], getattr(out.filter, "epoch_times",
                                                                     None), P, out.windows))
            out.evaluation[name] = ev
    return out


__all__ = ["evaluate_result", "evaluate_solution"]
