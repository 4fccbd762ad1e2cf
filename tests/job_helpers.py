"""A *recorded* small job for the output-safety tests: the small simulated car of
robustness_helpers written to native CSV files once (truth, IMU, GNSS), and a job file that
reads them like real data (inputs.imu/gnss/reference paths), about 2 s to process."""

from __future__ import annotations

import tomllib
from pathlib import Path

from robustness_helpers import SMALL_JOB_TOML

RECORDED_JOB = """
[inputs.imu]
format = "native"
path = "{data}/imu.csv"

[inputs.gnss]
format = "native"
path = "{data}/gnss.csv"

[inputs.reference]
format = "native"
path = "{reference}"
point = "imu"

[initialization]
method = "static"
static_duration = 15.0

[aiding]
gnss_velocity = true
q_scale = {{ 5 = 1.0 }}

[filter]
imu_grade = "tactical"
{filter}
[outputs]
report = false
progress = false
"""


def simulate_recording(folder: Path, seed: int = 7) -> Path:
    """Write truth.csv, imu.csv, gnss.csv of the small scenario into ``folder``."""
    from insgnss.simulate.scenario import simulate_scenario

    folder.mkdir(parents=True, exist_ok=True)
    simulate_scenario(tomllib.loads(SMALL_JOB_TOML), seed=seed).write(folder)
    return folder


def recorded_job_text(data: Path | str, reference: Path | str | None = None,
                      filter: str = "") -> str:
    """Job text reading the recording in ``data`` (reference: ``data/truth.csv``)."""
    ref = reference if reference is not None else f"{data}/truth.csv"
    return RECORDED_JOB.format(data=data, reference=ref, filter=filter)
