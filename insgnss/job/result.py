"""What a run of a job produced, in memory: :class:`JobResult` (trajectories and logs of the
filter, evaluation, summary) and :class:`PresetResult`, the filter-like result of a process
that does not run :func:`insgnss.filter.engine.run_filter` (the foot-mounted INS)."""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from ..config import Job
from ..errors import InsgnssError
from ..filter.engine import FilterResult
from ..imu import ImuErrorModel
from .initialization import Initialization
from .inputs import Inputs


@dataclass
class JobResult:
    """Everything a run produced (in memory).

    ``failure`` is set when the run went to its end but is not usable: an aiding source the
    job asks for of which the filter applied nothing
    (:class:`~insgnss.errors.NoUsableAidingError`). The outputs are still written, marked
    incomplete; ``insgnss process`` then exits with status 2. ``model`` is the IMU error
    model the filter used (with the noise measured in the static window, if the job asks).
    """

    job: Job
    inputs: Inputs
    init: Initialization
    windows: list
    filter: FilterResult
    evaluation: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    failure: InsgnssError | None = None
    model: ImuErrorModel | None = None


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
