"""``process_model = "riss"`` in a job: the simulated land-vehicle scenario with odometer runs end
to end through the pipeline (initialization, aiding, evaluation, outputs)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from insgnss.config import load_job_dict
from insgnss.errors import ConfigError
from insgnss.pipeline import run_job, write_outputs

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "land_vehicle_odometer.toml"


def _job(**changes):
    data = tomllib.loads(SCENARIO.read_text())
    data["job"] = {"platform": "generic"}  # GNSS aiding only: the RISS mechanics
    data["filter"] = {"process_model": "riss", "smoother": True}
    # the simulated GNSS is flagged q = 5 (single point) with its true sigma
    data["aiding"] = {"gnss_velocity": True, "q_scale": {"5": 1.0}}
    data["outputs"] = {"progress": False, "report": False}
    for k, v in changes.items():
        data.setdefault(k, {}).update(v)
    return load_job_dict(data, path=SCENARIO)


def test_riss_job_runs_end_to_end(tmp_path):
    res = run_job(_job())
    s = res.summary
    assert s["complete"] and s["process_model"] == "riss"
    # 502 epochs overlap the RISS span; the first one gives the initial position, not an update
    assert {k: c["offered"] for k, c in s["measurements"].items()} == \
        {"gnss_pos": 501, "gnss_vel": 501}
    for c in s["measurements"].values():  # applied + rejected = offered (no unusable epoch)
        assert c["applied"] + c["rejected"] == 501 and c["applied"] > 490
    ev = s["evaluation"]
    print(f"\nRISS job (consumer MEMS, two 90 s outages): horizontal RMS forward "
          f"{ev['forward']['rms_h_m']:.2f} m, smoothed {ev['smoothed']['rms_h_m']:.2f} m")
    assert ev["smoothed"]["rms_h_m"] < 1.0  # GNSS sigma 1.5 m
    assert ev["forward"]["rms_h_m"] < 3.0
    fw = res.filter.forward
    assert {"odometer_scale", "gyro_bias_z", "accel_bias_x", "accel_bias_y"} <= set(fw.columns)
    # the odometer scale factor drawn by the simulation is recovered
    odo, truth = res.inputs.odometer, res.inputs.truth
    v_true = np.hypot(truth.vel_e, truth.vel_n).reindex(odo.index, method="nearest").to_numpy()
    moving = v_true > 5.0
    k_true = np.median(odo.speed.to_numpy()[moving] / v_true[moving]) - 1.0
    print(f"odometer scale factor: simulated {k_true:.4f}, estimated {fw.odometer_scale.iloc[-1]:.4f}"
          f" +- {fw.odometer_scale_std.iloc[-1]:.4f}")
    assert fw.odometer_scale.iloc[-1] == pytest.approx(k_true, abs=1e-3)
    paths = write_outputs(res, tmp_path / "out")
    assert any(p.name.startswith("forward") for p in paths.values())


def test_riss_job_refuses_odometer_aiding():
    with pytest.raises(ConfigError, match="odometer"):
        run_job(_job(aiding={"odometer": True}))


def test_riss_settings_from_the_job_reach_the_filter(monkeypatch):
    """[filter.riss] keys are passed to RissConfig (and wrong ones are named)."""
    from insgnss.filter import riss_model

    seen = {}
    real = riss_model.run_riss_filter

    def spy(imu, odo, state, meas, cfg, rcfg):
        seen["rcfg"] = rcfg
        return real(imu, odo, state, meas, cfg, rcfg)

    monkeypatch.setattr(riss_model, "run_riss_filter", spy)
    job = _job()
    job.settings["filter"]["riss"].update(azimuth="level", window=0.5, slip_std=0.05)
    run_job(job)
    assert seen["rcfg"].azimuth == "level" and seen["rcfg"].window == 0.5
    assert seen["rcfg"].slip_std == 0.05
    with pytest.raises(ConfigError) as exc:
        load_job_dict({"filter": {"riss": {"azimuthh": "level"}}})
    assert exc.value.column == "filter.riss.azimuthh"
