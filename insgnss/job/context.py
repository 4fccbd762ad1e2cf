"""The prepared run handed from the preparation step (:mod:`.run`) to a process
(:mod:`.processes`): the inputs after the IMU table policies and the time offset, the filter's
IMU model, the outage windows and what the preparation did."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..config import Job
from ..imu import ImuErrorModel
from .inputs import Inputs


@dataclass
class RunContext:
    """A job ready to run.

    Attributes
    ----------
    job : Job
    inputs : Inputs
        IMU table after :func:`insgnss.policies.check_imu_table` (and the estimated time
        offset, if any).
    model : ImuErrorModel
        The filter's IMU error model.
    windows : list of (start, end)
        GNSS outage windows [s, job time base].
    imu_report : dict
        What the IMU policies found and did (``summary.json`` ``"imu"``).
    preprocessing : dict
        What preprocessing estimated (time offset, noise from the static window).
    t_start : float
        ``time.perf_counter()`` at the start of the run.
    timing : dict
        Seconds spent before the process (``read``).
    progress : bool
        Show a progress bar.
    spill_dir : Path or None
        Where the smoother's node store is memory-mapped beyond ``filter.store_memory_mb``
        (None: the system's temporary folder).
    """

    job: Job
    inputs: Inputs
    model: ImuErrorModel
    windows: list
    imu_report: dict
    t_start: float
    preprocessing: dict = field(default_factory=dict)
    timing: dict = field(default_factory=dict)
    progress: bool = False
    spill_dir: Path | None = None


__all__ = ["RunContext"]
