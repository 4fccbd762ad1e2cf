"""Foot-mounted INS height and distance through a job file: the ``[filter] coning`` correction
on integrated increments (simulated 60 Hz walk, insgnss.simulate.gait) and the summary's
stance-to-stance distance (insgnss.strides)."""

from __future__ import annotations

import numpy as np
import pytest

from insgnss.config import load_job
from insgnss.errors import ConfigError
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


def _job(tmp_path, w, coning: bool, foot: str = "", load_only: bool = False):
    t, dth, dv = increments(w.imu)
    p = tmp_path / "imu.csv"
    rows = ["time,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z"]
    rows += [",".join(f"{x:.17g}" for x in (tt, *a, *b)) for tt, a, b in zip(t, dth, dv,
                                                                              strict=True)]
    p.write_text("\n".join(rows) + "\n")
    jp = tmp_path / f"foot_{coning}_{len(foot)}.toml"
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
{foot}""")
    return load_job(jp) if load_only else run_job(load_job(jp))


def test_coning_correction_removes_the_climb_of_a_60_hz_foot_job(tmp_path, walk60):
    dist = STEPS * GaitParams().stride_length
    up = {c: _job(tmp_path, walk60, c).filter.smoothed["up"].iloc[-1] for c in (False, True)}
    assert up[False] / dist > 2e-3   # climbs 0.4 % of the distance without the correction
    assert abs(up[True]) / dist < 2e-4


def test_level_floor_job_key_removes_the_climb_and_reports_it(tmp_path, walk60):
    """``[foot] level_floor``: the uncorrected 60 Hz job climbs 0.4 % of the distance; with the
    level floor its end height is within 1 cm, and the summary says what the aiding did."""
    free = _job(tmp_path, walk60, False)
    assert free.summary["height_aiding"] == {}
    res = _job(tmp_path, walk60, False, "[foot]\nlevel_floor = true\n")
    dist = STEPS * GaitParams().stride_length
    up_free = free.filter.smoothed["up"].iloc[-1]
    up = res.filter.smoothed["up"].iloc[-1]
    assert up_free / dist > 2e-3 and abs(up) < 0.01
    ha = res.summary["height_aiding"]
    assert ha["level_floor"]["applied"] >= STEPS - 1 and ha["level_floor"]["skipped"] == 0
    assert ha["stride_height_noise"]["up_std_median_m"] == pytest.approx(
        0.01 * GaitParams().stride_length, rel=0.1)
    # horizontal: the level floor does not move the track
    end = [r.filter.smoothed[["east", "north"]].iloc[-1].to_numpy() for r in (free, res)]
    assert np.hypot(*(end[1] - end[0])) < 0.02
    for bad, msg in (('"yes"', "true or false"), ("true\nlevel_floor_std = 0.1", "below"),
                     ("true\nstride_height_noise = -1", ">= 0")):
        with pytest.raises(ConfigError, match=msg):
            _job(tmp_path, walk60, False, f"[foot]\nlevel_floor = {bad}\n", load_only=True)


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
