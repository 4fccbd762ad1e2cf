"""Foot-mounted INS height and distance through a job file: the ``[filter] coning`` correction
on integrated increments (simulated 60 Hz walk, insgnss.simulate.gait) and the summary's
stance-to-stance distance (insgnss.strides)."""

from __future__ import annotations

import numpy as np
import pytest

from insgnss.config import load_job
from insgnss.imu import increments
from insgnss.pipeline import run_job
from insgnss.simulate.gait import GaitParams, simulate_walk
from insgnss.strides import path_length, stance_distance, stance_positions, still_runs

STEPS = 24


@pytest.fixture(scope="module")
def walk60():
    return simulate_walk([{"type": "stand", "duration": 2.0}, {"type": "walk", "steps": STEPS},
                          {"type": "stand", "duration": 2.0}], rate=60.0, oversample=32,
                         lat=np.radians(45.0))


def _job(tmp_path, w, coning: bool):
    t, dth, dv = increments(w.imu)
    p = tmp_path / "imu.csv"
    rows = ["time,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z"]
    rows += [",".join(f"{x:.17g}" for x in (tt, *a, *b)) for tt, a, b in zip(t, dth, dv,
                                                                              strict=True)]
    p.write_text("\n".join(rows) + "\n")
    jp = tmp_path / f"foot_{coning}.toml"
    jp.write_text(f"""
[job]
time_base = "run"
[process]
preset = "foot"
[inputs.imu]
path = "imu.csv"
gyro_unit = "rad"
accel_unit = "m/s"
[initialization]
lat_deg = 45.0
[filter]
coning = {str(coning).lower()}
[outputs]
progress = false
""")
    return run_job(load_job(jp))


def test_coning_correction_removes_the_climb_of_a_60_hz_foot_job(tmp_path, walk60):
    dist = STEPS * GaitParams().stride_length
    up = {c: _job(tmp_path, walk60, c).filter.smoothed["up"].iloc[-1] for c in (False, True)}
    assert up[False] / dist > 2e-3   # climbs 0.4 % of the distance without the correction
    assert abs(up[True]) / dist < 2e-4


def test_summary_reports_the_stance_to_stance_distance(tmp_path, walk60):
    res = _job(tmp_path, walk60, True)
    d = res.summary["distance"]
    dist = STEPS * GaitParams().stride_length
    assert d["stance_m"] == pytest.approx(dist, rel=0.01)
    assert d["stances"] >= STEPS
    assert d["forward_path_m"] >= d["stance_m"]
    assert d["smoothed_path_m"] > 0


def test_stance_distance_ignores_correction_jumps():
    """A forward track that overshoots each stride by 20 % and jumps back at the stance: its
    raw path length is inflated, the stance-to-stance distance is the true one."""
    n_str, per = 10, 50
    x, still = [], []
    for j in range(n_str):
        x += list(j + np.linspace(0.0, 1.2, per)) + [j + 1.0] * 20
        still += [False] * per + [True] * 20
    pos = np.column_stack([np.array(x), np.zeros(len(x))])
    still = np.array(still)
    assert path_length(pos) == pytest.approx(n_str * 1.4, rel=1e-9)  # 1.2 out + 0.2 back
    assert stance_distance(pos, still) == pytest.approx(n_str - 1.0, rel=1e-12)
    assert stance_positions(pos, still).shape == (n_str, 2)
    runs = still_runs(still)
    assert runs.shape == (n_str, 2) and (runs[:, 1] - runs[:, 0] == 20).all()
    assert stance_distance(pos, np.zeros(len(x), bool)) == 0.0
