"""Shared report test fixtures: the demo, the drive and a foot job, processed once per session,
their output folders written with every figure format."""

from __future__ import annotations

import re
from pathlib import Path

from insgnss.report_data import FIGURE_KEYS

REPO = Path(__file__).resolve().parents[1]

#: figures each kind of job must show (issue 18): with a full reference (simulation), with a
#: position-only reference (real drive), without a reference (foot-mounted INS)
EXPECTED = {
    "demo": {"track", "position_errors", "velocity_errors", "attitude_errors", "heading",
             "sensor_errors", "outage_drift", "innovations", "nis", "nees"},
    "drive": {"track", "position_errors", "velocity_sigma", "velocity_difference",
              "attitude_sigma", "attitude_difference", "heading", "sensor_errors",
              "outage_drift", "innovations", "nis", "nees"},
    "foot": {"track", "position_sigma", "velocity_sigma", "attitude_sigma",
             "position_difference", "velocity_difference", "attitude_difference", "heading",
             "sensor_errors", "innovations"},
}


def figure_keys(html: str) -> set[str]:
    """Keys of the figures of a report page (``<figure class='fig' data-key=...>``)."""
    keys = set(re.findall(r"<figure class='fig' data-key='([a-z_]+)'>", html))
    assert keys <= set(FIGURE_KEYS), keys - set(FIGURE_KEYS)
    return keys


def set_outputs(job, **kw):
    """Change ``[outputs]`` settings of a loaded job in place."""
    job.settings["outputs"].update(kw)
    return job
