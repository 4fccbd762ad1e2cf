"""Evaluation of a run against the job's reference (``[inputs.reference]``, ``[evaluation]``):
position errors at the reference epochs, at the point the reference measures, the outage
metrics of the drive benchmark protocol (:mod:`insgnss.evaluate`) and the single-run position
NEES.

Position NEES (3 dof) at every reference epoch, from the solution's ``east_std north_std
up_std`` interpolated there (the diagonal of ``P``: the output tables carry no correlations, as
in the end-of-outage 3-sigma test of :mod:`insgnss.evaluate`; the filter epochs, where the full
``P`` is kept, fall on reference epochs only where GNSS epochs are, hardly ever inside an
outage): ``(e_E/s_E)^2 + (e_N/s_N)^2 + (e_U/s_U)^2``. Summarised over the epochs inside the
outage windows (``nees_pos_outage_*``): there the reference is independent of the filter, while
outside them the GNSS fixes the filter uses are often the reference itself (``nees_pos_*`` over
all epochs then mostly says how closely the filter follows its own aiding). A consistent filter
has a mean of 3 and 99.73 % of the epochs below ``chi2_3(99.73 %)`` = 14.16
(``*_within_3sigma_fraction``; the epochs of one outage are correlated, so this is no
independent-sample test).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..config import Job
from ..evaluate import enu_errors, move_point, outage_metrics
from .inputs import Inputs
from .result import JobResult


def evaluate_solution(sol: pd.DataFrame, inputs: Inputs, windows, job: Job) -> dict:
    """Errors of one solution against the job's reference (empty without a reference):
    ``{"errors": table, "outages": table, "summary": dict}``. The summary and the outage
    table are computed over every reference epoch; ``errors`` keeps the reference epochs at
    the trajectory output rate only (:func:`stored_errors`). ``sol`` is a DataFrame or a
    solution table as the engine holds it (:class:`insgnss.filter.store.Table`), read in
    blocks of reference epochs (:func:`reference_errors`)."""
    if inputs.reference is None or sol is None or not len(sol) or \
            not job["evaluation"]["enabled"]:  # (a filter stopped at its first epoch)
        return {}
    err = reference_errors(sol, inputs)
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
    summary.update(position_nees(err, windows))
    return {"errors": stored_errors(err, inputs, job), "outages": table, "summary": summary}


#: reference epochs per block of :func:`reference_errors`
REFERENCE_BLOCK = 1 << 16


def reference_errors(sol, inputs: Inputs, block: int = REFERENCE_BLOCK) -> pd.DataFrame:
    """Position errors at every reference epoch (``east north up horizontal`` and, where the
    solution has them, ``east_std north_std up_std`` interpolated there), at the point the
    reference measures.

    ``sol`` is a DataFrame or a :class:`insgnss.filter.store.Table`; for each block of
    ``block`` reference epochs only the solution rows bracketing them are read (the rows the
    interpolation uses, so the numbers are those of the whole table): no whole-log copy of
    the solution columns is made. The pages of each block of a memory-mapped reference
    (:func:`insgnss.job.inputs.read_reference`) are given back after it, and the table is
    built on one array (no copy per column)."""
    from ..filter.store import Table, select_rows
    from ..io.spill import release_frame

    ref = inputs.reference
    tr = ref.index.to_numpy(float)
    ts = sol.time if isinstance(sol, Table) else sol.index.to_numpy(float)
    cols = EVAL_COLUMNS + (ATTITUDE_COLUMNS if inputs.reference_point == "antenna" else ())
    has = list(sol.columns) if hasattr(sol, "columns") else None
    stds = [c for c in ("east_std", "north_std", "up_std") if has is None or c in has]
    # column-major: east north up horizontal, then the stds (unused columns are never touched)
    values = np.empty((4 + len(stds), tr.size)).T
    enu, sd = values[:, :3], values[:, 4:]
    for a in range(0, tr.size, block):
        b = min(a + block, tr.size)
        lo = max(int(np.searchsorted(ts, tr[a], side="right")) - 1, 0)
        hi = min(int(np.searchsorted(ts, tr[b - 1], side="right")) + 1, ts.size)
        part = select_rows(sol, lambda t, lo=lo, hi=hi: np.arange(lo, hi), cols)
        if a == 0:  # the std columns the solution really has
            stds = [c for c in stds if c in part.columns]
            sd = sd[:, :len(stds)]
        pt = move_point(part, inputs.lever_arm) if inputs.reference_point == "antenna" \
            else part
        enu[a:b] = enu_errors(pt, ref.iloc[a:b])  # (evaluate.position_errors' array)
        np.hypot(enu[a:b, 0], enu[a:b, 1], out=values[a:b, 3])
        tp = part.index.to_numpy(float)
        for k, c in enumerate(stds):
            sd[a:b, k] = np.interp(tr[a:b], tp, part[c].to_numpy(float))
        release_frame(ref, a, b)
        del part, pt
    return pd.DataFrame(values[:, :4 + len(stds)], index=ref.index,
                        columns=["east", "north", "up", "horizontal", *stds], copy=False)


def stored_errors(err: pd.DataFrame, inputs: Inputs, job: Job) -> pd.DataFrame:
    """The rows of the error table kept in :attr:`JobResult.evaluation` ``["errors"]``: the
    reference epochs at the trajectory output rate (``[outputs] rate_hz``, with the epochs
    around each GNSS and control-point epoch, :func:`insgnss.io.native.decimation_rows`), the
    epochs the report shows. The summary metrics are computed over every reference epoch
    before; a 200 Hz reference over 10 h kept whole would hold 7.2 M rows (0.4 GB per
    solution)."""
    from ..io.native import decimation_rows

    epochs = [x.index for x in (getattr(inputs, "gnss", None),
                                getattr(inputs, "control_points", None)) if x is not None]
    rows = decimation_rows(err.index.to_numpy(float), job["outputs"]["rate_hz"], epochs,
                           job["process"]["preset"])
    return err if rows is None else err.iloc[rows].copy()


#: chi-square point of 3 dof at the 3-sigma probability (99.73 %)
CHI2_3DOF_3SIGMA = 14.156


def position_nees(err: pd.DataFrame, windows) -> dict:
    """Summary of the position NEES (module docstring) of an error table with ``east north
    up`` and ``east_std north_std up_std``; empty without the stds."""
    from ..outages import in_windows

    cols = ["east", "north", "up"]
    if not len(err) or not all(f"{c}_std" in err.columns for c in cols):
        return {}
    # one column at a time: no (N, 3) temporaries (the same sum, in the same order)
    nees = np.zeros(len(err))
    ok = np.ones(len(err), bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for c in cols:
            e, sd = err[c].to_numpy(float), err[f"{c}_std"].to_numpy(float)
            nees += (e / sd) ** 2
            ok &= sd > 0
    ok &= np.isfinite(nees)
    inside = in_windows(err.index.to_numpy(float), windows)
    out = {}
    for tag, m in (("nees_pos", ok), ("nees_pos_outage", ok & inside)):
        v = nees[m]
        out[f"{tag}_n"] = int(v.size)
        if v.size:
            out[f"{tag}_mean"] = float(np.mean(v))
            out[f"{tag}_median"] = float(np.median(v))
            out[f"{tag}_within_3sigma_fraction"] = float(np.mean(v <= CHI2_3DOF_3SIGMA))
    return out


#: solution columns the evaluation reads (the attitude only to move the point to the antenna)
EVAL_COLUMNS = ("lat", "lon", "height", "east_std", "north_std", "up_std")
ATTITUDE_COLUMNS = ("roll", "pitch", "heading")


def evaluate_result(out: JobResult) -> JobResult:
    """Fill ``out.evaluation`` for the forward and the smoothed solution; returns ``out``.

    A solution the engine holds as arrays (:class:`insgnss.filter.store.Table`, possibly
    memory-mapped beyond ``[filter] store_memory_mb``) is read in blocks, and only the
    columns the evaluation uses: no whole-log DataFrame of all columns is built."""
    from ..filter.store import solution_table
    from ..io.spill import trim_heap

    if out.inputs.reference is None or not out.job["evaluation"]["enabled"]:
        return out
    for name in ("forward", "smoothed"):
        ev = evaluate_solution(solution_table(out.filter, name), out.inputs, out.windows,
                               out.job)
        trim_heap()  # the solution's columns and the temporaries go back to the system
        if ev:
            out.evaluation[name] = ev
    return out


__all__ = ["evaluate_result", "evaluate_solution", "reference_errors", "stored_errors"]
