"""`insgnss mechanize` end to end on a generated IMU CSV in deg/s, g and FRD axes."""

import subprocess
import sys

import numpy as np
import pytest
from mech_helpers import LAT45, static_increments

from insgnss.attitude import rfu_to_frd
from insgnss.cli import main
from insgnss.io.native import read_table

HEADING40 = np.radians(40.0)


def _write_frd_csv(path, duration=150.0, rate=100.0, heading=HEADING40):
    imu, _ = static_increments(duration, rate, LAT45, h=200.0, roll=0.01, pitch=0.02,
                               heading=heading)
    w = rfu_to_frd(imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy()[1:] * rate)
    f = rfu_to_frd(imu[["dv_x", "dv_y", "dv_z"]].to_numpy()[1:] * rate)
    t_ms = imu.index.to_numpy()[1:] * 1000.0
    data = np.column_stack([t_ms, np.degrees(w), f / 9.80665])
    header = "time,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z"
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.12g")


def test_mechanize_cli_aligns_and_writes(tmp_path, capsys):
    src = tmp_path / "imu.csv"
    _write_frd_csv(src)
    out = tmp_path / "traj.csv"
    fig = tmp_path / "nav.png"
    rc = main(["mechanize", str(src), "--lat", "45", "--lon", "0", "--height", "200",
               "--gyro-unit", "deg/s", "--accel-unit", "g", "--time-unit", "ms",
               "--axis-map", "y,x,-z", "--align", "120", "--grade", "navigation",
               "-o", str(out), "--figure", str(fig)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "gyrocompass" in text
    traj = read_table(out)
    assert np.degrees(traj["heading"].iloc[0]) == pytest.approx(40.0, abs=1e-3)
    assert np.degrees(traj["roll"].iloc[0]) == pytest.approx(np.degrees(0.01), abs=1e-3)
    # perfect static data: 30 s of navigation stays put
    assert np.abs(traj[["vel_e", "vel_n", "vel_u"]].to_numpy()).max() < 1e-3
    assert fig.stat().st_size > 10_000


def test_mechanize_cli_errors_without_traceback(tmp_path):
    src = tmp_path / "imu.csv"
    _write_frd_csv(src, duration=5.0)
    # output equal to the input is refused; missing --align/--attitude is a clean error
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "mechanize", str(src), "--lat", "45",
                        "--lon", "0", "-o", str(tmp_path / "o.csv")], capture_output=True,
                       text=True)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "--align" in r.stderr
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "mechanize", str(src), "--lat", "45",
                        "--lon", "0", "--attitude", "0,0,0", "-o", str(src)],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert src.stat().st_size > 0


def test_every_command_has_help():
    from insgnss.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    assert "mechanize" in sub.choices
    for name, p in sub.choices.items():
        text = p.format_help()
        assert name in text and len(text) > 200


def test_mechanize_cli_wander_frame_and_gravity_model(tmp_path):
    src = tmp_path / "imu.csv"
    _write_frd_csv(src, duration=130.0)
    out = tmp_path / "traj.csv"
    rc = main(["mechanize", str(src), "--lat", "45", "--lon", "0", "--height", "200",
               "--gyro-unit", "deg/s", "--accel-unit", "g", "--time-unit", "ms",
               "--axis-map", "y,x,-z", "--align", "120", "--frame", "wander",
               "--wander-angle", "30", "--gravity-model", "somigliana", "-o", str(out)])
    assert rc == 0
    traj = read_table(out)
    assert "wander_angle" in traj.columns  # read back to radians from wander_angle_deg
    assert np.degrees(traj["wander_angle"].iloc[0]) == pytest.approx(30.0, abs=1e-9)
    assert np.degrees(traj["heading"].iloc[0]) == pytest.approx(40.0, abs=1e-3)
    assert np.abs(traj[["vel_e", "vel_n", "vel_u"]].to_numpy()).max() < 1e-3
    for bad in (["--frame", "ned"], ["--gravity-model", "wgs72"]):
        r = subprocess.run([sys.executable, "-m", "insgnss.cli", "mechanize", str(src), "--lat",
                            "45", "--lon", "0", "--attitude", "0,0,0", "-o",
                            str(tmp_path / "o.csv"), *bad], capture_output=True, text=True)
        assert r.returncode == 2 and "Traceback" not in r.stderr and bad[1] in r.stderr


def test_python_dash_m_insgnss_is_the_command():
    """``python -m insgnss`` (a venv whose scripts are not on PATH) is the ``insgnss`` command:
    the same help, and its exit status."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "insgnss", "--help"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0 and "process" in r.stdout and "usage: insgnss" in r.stdout, r.stderr
    bad = subprocess.run([sys.executable, "-m", "insgnss", "process", "no_such_job.toml"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "no_such_job.toml" in bad.stderr
