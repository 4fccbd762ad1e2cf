"""GNSS outage windows of a job (``[outages]``, docs/jobs.md) in the job's time base.

Explicit windows are relative to the first GNSS epoch (``relative_to = "first_gnss"``) or
absolute; periodic outages (:func:`insgnss.outages.periodic_windows`) follow the drive benchmark
protocol (shared/eval/README.md). GNSS inside a window is withheld from the whole run.
"""

from __future__ import annotations

import pandas as pd

from ..config import Job
from ..errors import ConfigError
from ..outages import periodic_windows


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
        wins += periodic_windows(t_first, t_last, p["start"], p["length"], p["gap"],
                                 p["stop_before_end"])
    return sorted(wins)


__all__ = ["outage_windows"]
