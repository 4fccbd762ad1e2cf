"""Every bundled scenario (scenarios/*.toml) runs end to end.

Simulated scenarios run shortened (``[scenario] duration`` overridden to :data:`DURATION`
seconds, the test-only fast setting); real-data jobs run in full where the data is present
(skipped without it, failing in CI); settings-only files (``scenarios/foot_mounted.toml``) run
as ``--settings`` on the simulated walk they are meant for. Each run must be complete, and its
smoothed (or forward) horizontal error against the reference below a bound that any working
processing meets and a broken one does not (a wrong initialization or frame gives tens of
metres).
"""

from __future__ import annotations

import os
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from insgnss.batch import merge_settings, skip_reason
from insgnss.config import load_job_dict
from insgnss.pipeline import run_job

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
FILES = sorted(SCENARIOS.glob("*.toml"))
#: simulated scenarios are cut to this length [s] (test-only fast setting)
DURATION = 120.0
#: scenario a settings-only file is run with (the data it is meant for)
SETTINGS_FOR = {"foot_mounted.toml": "foot_walk.toml"}
#: horizontal RMS bound [m] of a working run (consumer MEMS in town with 2.5 m GNSS included)
MAX_RMS_H = 5.0
#: the same for a job aided by the receiver's own pseudoranges (single-point positioning with
#: broadcast orbits and clocks and the Klobuchar ionosphere: metres of common bias against an
#: RTK reference, 8-9 m on the rtklibexplorer walk, docs/tight.md)
MAX_RMS_H_SPP = 15.0


def _data(path: Path) -> dict:
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def test_scenarios_are_found():
    names = {f.name for f in FILES}
    assert {"foot_walk.toml", "drive_0708.toml", "foot_mounted.toml",
            "car_town_mems.toml"} <= names


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_bundled_scenario_runs(path: Path):
    data = _data(path)
    reason = skip_reason(path, data, None)
    if reason is not None and reason.startswith("settings only"):
        base, path = data, SCENARIOS / SETTINGS_FOR[path.name]
        data = merge_settings(_data(path), base)
    elif reason is not None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"{path.name}: {reason} (the shared data must be present in CI)")
        pytest.skip(f"{path.name}: {reason}")
    job = load_job_dict(data, path)
    if job.simulation:
        sc = job.simulation.setdefault("scenario", {})
        sc["duration"] = min(float(sc.get("duration", DURATION)), DURATION)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(job, progress=False)
    s = res.summary
    assert s["complete"], s["error"]
    ev = s["evaluation"]
    assert ev, "every bundled scenario is evaluated against a truth or reference"
    sol = ev.get("smoothed") or ev["forward"]
    spp = job["aiding"]["gnss"] == "tight" or job["inputs"]["gnss_raw"]["path"] is not None
    assert np.isfinite(sol["rms_h_m"]) and sol["rms_h_m"] < (MAX_RMS_H_SPP if spp else MAX_RMS_H), sol
    if job.simulation:
        t = res.filter.forward.index.to_numpy(float)
        assert t[-1] - t[0] > 0.5 * DURATION


def test_the_riss_scenario_is_the_odometer_vehicle():
    """scenarios/land_vehicle_riss.toml is the simulated drive of land_vehicle_odometer.toml
    processed by RISS: the same trajectory, sensors and seed (one scenario, two process
    models), only the name, the description and ``[filter]`` differ."""
    full, riss = (tomllib.loads((SCENARIOS / n).read_text())
                  for n in ("land_vehicle_odometer.toml", "land_vehicle_riss.toml"))
    assert riss["filter"] == {"process_model": "riss"}
    assert full["filter"].get("process_model", "strapdown") == "strapdown"
    for d in (full, riss):
        del d["filter"], d["scenario"]["name"], d["scenario"]["description"]
    assert riss == full
