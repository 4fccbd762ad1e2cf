"""The job examples of docs/jobs.md run as written, on small generated data.

Each ```toml block of the "Examples" section is a job as a user writes it. The test generates
data that fits it (tests/example_data.py: a short simulated drive written in the job's formats,
units, axes, mounting and time base, at the file names the job gives), runs the job and checks
its solution against the simulated truth. A block without ``[inputs.imu]`` is a snippet to add
to a job: it runs on top of :data:`BASE` (native IMU and GNSS tables).
"""

from __future__ import annotations

import re
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
from example_data import generate_for, horizontal_errors

from insgnss.batch import merge_settings
from insgnss.config import load_job_dict
from insgnss.pipeline import run_job

DOC = Path(__file__).resolve().parents[1] / "docs" / "jobs.md"
#: the job a snippet is added to
BASE = {"inputs": {"imu": {"format": "native", "path": "imu.csv"},
                   "gnss": {"format": "native", "path": "gnss.csv",
                            "lever_arm": [0.0, 0.5, 1.2]}},
        "initialization": {"method": "static", "static_duration": 20.0}}
#: horizontal error bound [m] of a GNSS-aided run
MAX_H = 3.0
#: ZUPT + CUPT without GNSS: error at the control points [m] (2 cm points) and in between (a
#: tactical IMU over the 240 s between two stops: a 1 mg bias alone drifts 29 m in 240 s free)
MAX_CUPT, MAX_FREE = 0.1, 25.0


def examples() -> list[tuple[str, dict]]:
    text = DOC.read_text()
    section = text.split("## Examples", 1)[1].split("\n## ", 1)[0]
    out = []
    for title, body in re.findall(r"^### (.+?)\n(.*?)(?=^### |\Z)", section, re.M | re.S):
        for block in re.findall(r"```toml\n(.*?)```", body, re.S):
            out.append((title.strip(), tomllib.loads(block)))
    return out


EXAMPLES = examples()


def test_examples_are_found():
    titles = " ".join(t for t, _ in EXAMPLES)
    assert len(EXAMPLES) >= 5 and "NMEA" in titles and "KF-GINS" in titles


#: examples whose generated-data run is a known defect (title prefix -> reason); the real
#: recording the example describes is checked by tests/test_scenarios.py
KNOWN: dict[str, str] = {}


def _params():
    out = []
    for title, job in EXAMPLES:
        reason = next((r for k, r in KNOWN.items() if title.startswith(k)), None)
        marks = [pytest.mark.xfail(reason=reason, strict=False)] if reason else []
        out.append(pytest.param(title, job, marks=marks, id=title.split("(")[0].strip()[:40]))
    return out


@pytest.mark.parametrize("title,job", _params())
def test_docs_example_runs(title, job, tmp_path):
    if not job.get("inputs", {}).get("imu", {}).get("path"):
        job = merge_settings(BASE, job)
    job.setdefault("outputs", {}).update(report=False, progress=False)
    if job.get("job", {}).get("platform") in ("car", "pedestrian"):
        # the generated data follows the declared IMU grade, so the profile's prior model is the
        # truth; self-tuning (tests/test_autotune.py) would repeat the run ~200 times here
        job.setdefault("filter", {}).setdefault("autotune", False)
    job, truth = generate_for(job, tmp_path)
    j = load_job_dict(job, tmp_path / "job.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(j, progress=False)
    s = res.summary
    assert s["complete"], s["error"]
    sol = res.filter.smoothed if res.filter.smoothed is not None else res.filter.forward
    err = horizontal_errors(sol, truth)
    assert np.isfinite(err).all()
    if job.get("inputs", {}).get("gnss", {}).get("path"):
        assert err.max() < MAX_H, (title, float(err.max()))
    else:  # ZUPT + CUPT: on the 2 cm control points, drifting in between
        cp = res.inputs.control_points
        k = np.searchsorted(sol.index.to_numpy(float), cp.index.to_numpy(float))
        assert err[k].max() < MAX_CUPT, (title, err[k])
        assert err.max() < MAX_FREE, (title, float(err.max()))
    if job.get("inputs", {}).get("reference", {}).get("path"):  # evaluated over the whole run
        assert s["evaluation"] and all(e["n_covered"] > 0.9 * e["n_reference"]
                                       for e in s["evaluation"].values()), s["evaluation"]
