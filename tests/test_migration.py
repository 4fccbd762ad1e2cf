"""Migration: `insgnss init` job templates for the common formats run on data in those
formats, and `insgnss import-kfgins` translates a KF-GINS configuration into a job that runs."""

from __future__ import annotations

import tomllib
import warnings

import numpy as np
import pytest
from example_data import T0, generate_for, horizontal_errors

from insgnss.cli import main
from insgnss.commands.init import FORMATS
from insgnss.config import load_job
from insgnss.io.gpstime import WEEK_SECONDS
from insgnss.io.kfgins_yaml import MGAL_UG
from insgnss.io.native import read_table
from insgnss.pipeline import run_job


def _run(job):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_job(job, progress=False)


@pytest.mark.parametrize("fmt", FORMATS)
def test_init_template_runs_on_its_format(fmt, tmp_path, capsys):
    path = tmp_path / "job.toml"
    assert main(["init", "--format", fmt, "-o", str(path)]) == 0
    assert "insgnss process" in capsys.readouterr().out
    assert main(["init", "--format", fmt, "-o", str(path)]) == 2  # never overwrites
    data = tomllib.loads(path.read_text())
    job, truth = generate_for(data, tmp_path)  # data in the template's formats and names
    res = _run(load_job(path))
    assert res.summary["complete"], res.summary["error"]
    sol = res.filter.smoothed if res.filter.smoothed is not None else res.filter.forward
    assert horizontal_errors(sol, truth).max() < 3.0


KFGINS_YAML = """
# a KF-GINS configuration (format of i2Nav-WHU/KF-GINS dataset/kf-gins.yaml)
imupath: "./data/IMU.txt"
gnsspath: "./data/GNSS-RTK.txt"
outputpath: "./result"
imudatalen: 7
imudatarate: 100
starttime: {start}
endtime: -1
initpos: [ 45.0, 7.0, 250.0 ]
initvel: [ 0.0, 0.0, 0.0 ]
initatt: [ {roll}, {pitch}, {yaw} ]
initgyrbias: [ 0, 0, 0 ]
initaccbias: [ 0, 0, 0 ]
initgyrscale: [ 0, 0, 0 ]
initaccscale: [ 0, 0, 0 ]
initposstd: [ 0.05, 0.05, 0.1 ]
initvelstd: [ 0.05, 0.05, 0.05 ]
initattstd: [ 0.1, 0.1, 1.0 ]
initbgstd: [ 2.0, 2.0, 2.0 ]
imunoise:
  arw: [0.15, 0.15, 0.15]
  vrw: [0.05, 0.05, 0.05]
  gbstd: [0.5, 0.5, 0.5]
  abstd: [50.0, 50.0, 50.0]
  gsstd: [300.0, 300.0, 300.0]
  asstd: [300.0, 300.0, 300.0]
  corrtime: 1.0
antlever: [ 1.2, 0.5, -1.0 ]
"""


def test_import_kfgins(tmp_path, capsys):
    run_dir = tmp_path / "kfgins"  # where KF-GINS runs: the YAML's paths start here
    data = run_dir / "data"
    job, truth = generate_for({"inputs": {"imu": {"format": "kfgins", "path": "IMU.txt"},
                                          "gnss": {"format": "kfgins", "path": "GNSS-RTK.txt",
                                                   "lever_arm": [0.5, 1.2, 1.0]}},
                               "initialization": {"method": "given", "heading_deg": 30.0}},
                              data)
    sow0 = T0 % WEEK_SECONDS
    r0 = truth.iloc[0]
    yaml_path = run_dir / "kf-gins.yaml"
    yaml_path.write_text(KFGINS_YAML.format(start=sow0 + 2.0, roll=np.degrees(r0.roll),
                                            pitch=np.degrees(r0.pitch),
                                            yaw=np.degrees(r0.heading)))
    out = tmp_path / "jobs" / "kfgins.toml"
    out.parent.mkdir()
    assert main(["import-kfgins", str(yaml_path), "-o", str(out), "--kfgins-dir",
                 str(run_dir)]) == 0
    text = capsys.readouterr().out
    assert "not translated: initpos" in text
    job = load_job(out)
    s = job.settings
    assert s["job"]["time_base"] == "sow" and s["job"]["start"] == pytest.approx(sow0 + 2.0)
    assert job.resolve(s["inputs"]["imu"]["path"]) == (data / "IMU.txt").resolve()
    # antlever forward-right-down (1.2, 0.5, -1.0) -> right-forward-up (0.5, 1.2, 1.0)
    assert s["inputs"]["gnss"]["lever_arm"] == [0.5, 1.2, 1.0]
    m = s["filter"]["imu_model"]
    assert m["accel_bias_instability_ug"] == pytest.approx(50.0 * MGAL_UG)  # 50 mGal = 51 ug
    assert m["bias_correlation_time_s"] == 3600.0
    # initial gyro bias sigma 2 deg/h = hypot(turn-on, instability 0.5 deg/h)
    assert np.hypot(m["gyro_bias_deg_h"], m["gyro_bias_instability_deg_h"]) == pytest.approx(2.0)
    assert s["filter"]["bias_model"] == "gauss_markov" and s["filter"]["scale_factors"]
    assert s["initialization"]["heading_deg"] == pytest.approx(np.degrees(r0.heading) % 360)
    assert s["initialization"]["attitude_std_deg"] == [0.1, 0.1, 1.0]
    assert job.resolve(s["outputs"]["dir"]) == (run_dir / "result").resolve()
    # the translated job runs (window from starttime) and follows the truth
    assert main(["process", str(out), "--no-progress", "--no-report"]) == 0
    fwd = read_table(run_dir / "result" / "forward.csv")
    assert fwd.index[0] >= sow0 + 2.0
    assert horizontal_errors(fwd, truth).max() < 1.0
    assert (run_dir / "result" / "forward.nav").exists()
