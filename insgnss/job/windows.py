"""GNSS outage windows of a job (``[outages]``, docs/jobs.md) in the job's time base.

Explicit windows are relative to the first GNSS epoch (``relative_to = "first_gnss"``) or
absolute; periodic outages (:func:`insgnss.outages.periodic_windows`) follow the drive benchmark
protocol (shared/eval/README.md). GNSS inside a window is withheld from the whole run - from
the aiding and from the initialization alike (:func:`outside_windows`, the one place this rule
is applied).
"""

from __future__ import annotations

import pandas as pd

from ..config import Job
from ..errors import ConfigError
from ..outages import in_windows, periodic_windows


def outage_windows(job: Job, gnss: pd.DataFrame | None) -> list[tuple[float, float]]:
    """Outage windows of the job in its time base, sorted by start."""
    o = job["outages"]
    t_first = float(gnss.index[0]) if gnss is not None and len(gnss) else 0.0
    t_last = float(gnss.index[-1]) if gnss is not None and len(gnss) else 0.0
    off = t_first if o["relative_to"] == "first_gnss" else 0.0
    wins = [(off + float(a), off + float(b)) for a, b in o["windows"]]
    p = o["periodic"]
    if p["start"] is not None or p["length"] is not None:
        if p["start"] is None or p["length"] is None or p["gap"] is None:
            raise ConfigError("periodic outages need start, length and gap", file=job.path,
                              column="outages.periodic")
        if gnss is None:
            raise ConfigError("periodic outages need GNSS data", file=job.path,
                              column="outages.periodic")
        try:
            wins += periodic_windows(t_first, t_last, p["start"], p["length"], p["gap"],
                                     p["stop_before_end"])
        except ValueError as exc:  # e.g. more windows than the schedule allows
            raise ConfigError(str(exc), file=job.path, column="outages.periodic") from None
    return sorted(wins)


def outside_windows(table: pd.DataFrame, windows) -> pd.DataFrame:
    """The rows of a time-indexed table (GNSS) outside the outage windows: what a run may use."""
    if not windows or table is None or not len(table):
        return table
    keep = ~in_windows(table.index.to_numpy(float), windows)
    if keep.all():
        return table
    out = table.loc[keep]
    out.attrs = dict(table.attrs)
    if out.attrs.get("source_rows") is not None and len(out.attrs["source_rows"]) == len(table):
        out.attrs["source_rows"] = out.attrs["source_rows"][keep]
    return out


def describe_windows(windows) -> str:
    """``"3 outage window(s), 40.000 .. 100.000 s"`` for messages."""
    if not windows:
        return "no outage window"
    return f"{len(windows)} outage window(s) ([outages]) from {windows[0][0]:.3f} to " \
        f"{max(b for _, b in windows):.3f} s"


__all__ = ["describe_windows", "outage_windows", "outside_windows"]
