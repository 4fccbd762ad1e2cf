"""What a run of a job produced, in memory: :class:`JobResult` (trajectories and logs of the
filter, evaluation, summary) and :class:`PresetResult`, the filter-like result of a process
that does not run :func:`insgnss.filter.engine.run_filter` (the foot-mounted INS)."""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from ..config import Job
from ..filter.engine import FilterResult
from .initialization import Initialization
from .inputs import Inputs


@dataclass
class JobResult:
    """Everything a run produced (in memory)."""

    job: Job
    inputs: Inputs
    init: Initialization
    windows: list
    filter: FilterResult
    evaluation: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)


@dataclass
class PresetResult:
    """Filter-like result of a preset process (same attributes the outputs use)."""

    forward: pd.DataFrame
    smoothed: pd.DataFrame | None
    innovations: pd.DataFrame
    rejected: pd.DataFrame
    timing: dict
    complete: bool = True
    error: Exception | None = None


__all__ = ["JobResult", "PresetResult"]
