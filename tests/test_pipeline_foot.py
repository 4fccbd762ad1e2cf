"""`insgnss process` with the foot-mounted preset on a converted PyShoe trial."""

import importlib.util
import json
from pathlib import Path

import numpy as np

from insgnss.cli import main
from insgnss.io.native import read_table

REPO = Path(__file__).resolve().parents[1]


def _convert_module():
    spec = importlib.util.spec_from_file_location("pyshoe_convert",
                                                  REPO / "scenarios" / "pyshoe" / "convert.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_foot_preset_job_runs_from_the_cli(pyshoe_dir, tmp_path):
    convert = _convert_module()
    imu_csv, truth_csv = convert.write_trial(pyshoe_dir / "2017-11-22-11-22-03.mat", tmp_path)
    preset = (REPO / "scenarios" / "foot_mounted.toml").read_text()
    job = tmp_path / "foot.toml"
    job.write_text(preset + f'\n[inputs.imu]\nformat = "native"\npath = "{imu_csv.name}"\n'
                   '\n[outputs]\ndir = "out"\nformats = ["csv"]\n')
    assert main(["process", str(job), "--no-progress"]) == 0
    out = tmp_path / "out"
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["preset"] == "foot" and s["zupt_updates"] > 1000
    traj = read_table(out / "smoothed.csv")
    truth = read_table(truth_csv)
    sol = convert.solution_xyz(traj)
    # the walk returns close to its start (a loop in the Vicon area); heading is
    # unobservable, so compare distances from the start, which do not depend on yaw
    d_sol = np.hypot(sol["x"].to_numpy(), sol["y"].to_numpy())
    tx = truth["x"].to_numpy() - truth["x"].iloc[0]
    ty = truth["y"].to_numpy() - truth["y"].iloc[0]
    d_true = np.hypot(tx, ty)
    n = min(len(d_sol), len(d_true))
    assert np.sqrt(np.mean((d_sol[:n] - d_true[:n]) ** 2)) < 0.3
    assert (out / "report.html").exists()
    import multiprocessing

    import insgnss.report as rep

    assert rep._SERVER is None and not multiprocessing.active_children()  # the figure server
