"""A small simulated car job (about 2 s to run) for the robustness tests: 20 s static, then
driving with a turn; tactical IMU at 100 Hz, 1 Hz GNSS position + velocity (0.5 m)."""

from __future__ import annotations

import tomllib
from pathlib import Path

from insgnss.config import Job, load_job_dict

#: first lines of a child's script in the interrupt tests: SIGINT as a shell gives it to a
#: command (Python's KeyboardInterrupt, not blocked). A test runner's worker may run with SIGINT
#: blocked or ignored (a library's thread or helper process), and a child inherits both; a
#: Ctrl-C test then sees a run that never received its Ctrl-C
SHELL_SIGINT = """
import signal
signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
signal.signal(signal.SIGINT, signal.default_int_handler)
"""

SMALL_JOB_TOML = """
[scenario]
name = "small_car"
seed = 7
imu_rate = 100.0

[trajectory]
vehicle = "land"
lat = 45.0
lon = 7.0
height = 200.0
heading = 30.0
segments = [
  { type = "static", duration = 20.0 },
  { type = "accelerate", speed = 12.0, acceleration = 1.5 },
  { type = "hold", duration = 20.0 },
  { type = "turn", angle = 90.0, rate = 10.0 },
  { type = "hold", duration = 30.0 },
]

[imu]
grade = "tactical"

[gnss]
rate = 1.0
horizontal_std = 0.5
vertical_std = 1.0
velocity = true
velocity_std = 0.1
q = 5

[initialization]
method = "static"
static_duration = 15.0

[aiding]
gnss_position = true
gnss_velocity = true
q_scale = { 5 = 1.0 }

[outputs]
report = false
progress = false
"""


def small_job_text(**tables: str) -> str:
    """TOML text of the small job; ``tables`` maps a table name (``"aiding"``,
    ``"inputs.imu"``) to TOML lines inserted into that table (created if absent)."""
    text = SMALL_JOB_TOML
    for name, lines in tables.items():
        head = f"[{name}]\n"
        if head in text:
            text = text.replace(head, head + lines.strip() + "\n", 1)
        else:
            text += f"\n{head}{lines.strip()}\n"
    return text


def small_job(path: Path | None = None, **tables: str) -> Job:
    """The small job (see :func:`small_job_text`); with ``path`` written there and loaded from
    the file (paths in it are then relative to ``path``)."""
    text = small_job_text(**tables)
    if path is not None:
        from insgnss.config import load_job

        path.write_text(text)
        return load_job(path)
    return load_job_dict(tomllib.loads(text))
