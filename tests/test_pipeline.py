"""End-to-end jobs: the real drive (issue 5 must-show numbers), job errors, outputs, report."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from insgnss.config import load_job, load_job_dict
from insgnss.pipeline import outage_windows, run_job, write_outputs

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def drive_result(request):
    from conftest import shared_data

    shared_data("gnss-imu-rtklibexplorer", "drive_0708")
    job = load_job(REPO / "scenarios" / "drive_0708.toml")
    job.settings["filter"]["autotune"] = False  # the profile's prior model (bench_drive: tuned)
    return run_job(job, progress=False)


def test_drive_outage_benchmark(drive_result):
    """Real car drive, the data author's 11 x 15 s outages, scored against Q=1 RTK epochs."""
    res = drive_result
    assert res.filter.complete
    assert len(res.windows) == 11
    fwd = res.evaluation["forward"]["summary"]
    smo = res.evaluation["smoothed"]["summary"]
    # every reference epoch after the IMU log starts (3.4 s after the first fix) is covered
    ref_t = res.inputs.reference.index.to_numpy()
    assert fwd["n_covered"] == int((ref_t >= res.inputs.imu.index[0]).sum())
    # forward (causal): mean end-of-outage horizontal error <= 3.0 m (peers: 6.2-6.5 m)
    assert fwd["end_h_err_m_mean"] <= 3.0
    # smoothed: mean in-outage horizontal RMS <= 0.25 m (best peer: 0.28 m)
    assert smo["rms_h_err_m_mean"] <= 0.25
    # outside the outages both follow the RTK solution within 5 cm RMS
    assert fwd["non_outage_rms_h_m"] <= 0.05
    assert smo["non_outage_rms_h_m"] <= 0.05
    # the estimated residual IMU time offset is physically small
    assert abs(res.summary["preprocessing"]["imu_time_offset_estimated_s"]) < 0.2


def test_drive_outputs_and_report(drive_result, tmp_path):
    paths = write_outputs(drive_result, tmp_path)
    for name in ("forward.csv", "smoothed.csv", "innovations.csv", "rejected.csv",
                 "summary.json", "report.html"):
        assert (tmp_path / name).stat().st_size > 0, name
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["complete"] and summary["evaluation"]["smoothed"]["rms_h_err_m_mean"] < 0.25
    html = (tmp_path / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 4
    for text in ("Summary", "Accuracy against the reference", "Track", "Position errors",
                 "Drift inside outages", "IMU biases", "Innovations"):
        assert text in html
    assert "<script" not in html  # static page, opens offline
    assert set(paths) >= {"forward.csv", "summary.json"}


def test_outage_windows_explicit_and_periodic():
    job = load_job_dict({"outages": {"windows": [[10.0, 20.0]], "relative_to": "first_gnss"}})
    import pandas as pd

    gnss = pd.DataFrame({"lat": [0.0] * 3}, index=[100.0, 150.0, 200.0])
    assert outage_windows(job, gnss) == [(110.0, 120.0)]
    job = load_job_dict({"outages": {"periodic": {"start": 10.0, "length": 5.0, "gap": 20.0}}})
    w = outage_windows(job, gnss)
    assert w[0] == (110.0, 115.0) and w[1] == (135.0, 140.0) and len(w) == 4


def test_process_cli_reports_job_errors_cleanly(tmp_path):
    bad = tmp_path / "job.toml"
    bad.write_text("[filter]\nsmoothr = true\n")
    r = subprocess.run([sys.executable, "-m", "insgnss.cli", "process", str(bad)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert "filter.smoothr" in r.stderr and "Traceback" not in r.stderr


def test_outputs_never_overwrite_inputs(tmp_path, drive_result, monkeypatch):
    """An output whose path is an input of the job is refused and the input is untouched."""
    from insgnss.errors import ConfigError

    victim = tmp_path / "forward.csv"
    victim.write_text("precious input\n")
    job = drive_result.job
    monkeypatch.setattr(type(job), "input_paths", lambda self: [victim])
    with pytest.raises(ConfigError, match="refusing to overwrite an input"):
        write_outputs(drive_result, tmp_path)
    assert victim.read_text() == "precious input\n"


def test_bundled_demo_runs_end_to_end(tmp_path):
    """The README's main command: simulate the car scenario and process it."""
    from insgnss.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--no-progress"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["source"] == "simulation"
    fwd, smo = s["evaluation"]["forward"], s["evaluation"]["smoothed"]
    assert fwd["n_outages"] == 2
    # 1.5 m GNSS: aided error well below it; MEMS dead reckoning over 30 s outages stays bounded
    assert fwd["non_outage_rms_h_m"] < 1.0 and smo["non_outage_rms_h_m"] < 0.7
    assert fwd["end_h_err_m_mean"] < 15.0
    # the smoother removes most of the in-outage drift
    assert smo["rms_h_err_m_mean"] < 0.4 * fwd["rms_h_err_m_mean"]
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 4
    for name in ("forward.csv", "smoothed.csv", "forward.kml", "smoothed.geojson"):
        assert (out / name).stat().st_size > 0


def _untuned_drive_job(tmp_path):
    """A copy of the drive job (absolute paths) with the self-tuning off, for the tests that
    check other mechanisms on it (the tuned run takes minutes)."""
    import tomllib

    data = tomllib.loads((REPO / "scenarios" / "drive_0708.toml").read_text())
    for spec in data["inputs"].values():
        for k in ("path", "tag"):
            if k in spec:
                spec[k] = str((REPO / "scenarios" / spec[k]).resolve())
    data["filter"]["autotune"] = False
    data["outputs"]["dir"] = str(tmp_path / "out")

    def toml(d, prefix=""):
        lines, tables = [], []
        for k, v in d.items():
            if isinstance(v, dict) and k != "q_scale":
                tables.append((f"{prefix}{k}", v))
            else:
                lines.append(f"{k} = {json.dumps(v)}")
        out = ([f"[{prefix.rstrip('.')}]"] if prefix and lines else []) + lines
        for name, t in tables:
            out += toml(t, name + ".")
        return out

    path = tmp_path / "drive_untuned.toml"
    path.write_text("\n".join(toml(data)) + "\n")
    return path


def test_compare_cli_on_the_drive_job(drive_result, tmp_path):
    """`insgnss compare` runs free-inertial, GNSS-only and the job's own aided forward and
    smoothed solutions on the same data (issue 5), with the antenna lever arm applied."""
    from insgnss.cli import main

    rc = main(["compare", str(_untuned_drive_job(tmp_path)), "-o", str(tmp_path),
               "--only", "free,job,job_smoothed", "--no-figures"])
    assert rc == 0
    s = json.loads((tmp_path / "compare_summary.json").read_text())
    tab = s["table"]
    assert tab["free"]["rms_h_err_m"] > 100 * tab["job"]["rms_h_err_m"]
    assert tab["job_smoothed"]["rms_h_err_m"] < 0.2 < tab["job"]["rms_h_err_m"]


def test_compare_full_imu_against_riss(tmp_path):
    """`insgnss compare` on a land vehicle with an odometer: the job with the full IMU and with
    the RISS process model, same data and aiding (issue 7's comparison through the CLI)."""
    from insgnss.cli import main

    rc = main(["compare", str(REPO / "scenarios" / "land_vehicle_odometer.toml"), "-o",
               str(tmp_path), "--only", "job,riss", "--no-figures"])
    assert rc == 0
    tab = json.loads((tmp_path / "compare_summary.json").read_text())["table"]
    # consumer MEMS, two 90 s GNSS outages: RISS drifts far less than the full IMU (both with
    # the car profile's NHC and ZUPT: 2.7 m against 12.3 m)
    assert tab["riss"]["max_h_err_m"] < 0.25 * tab["job"]["max_h_err_m"]


def test_velocity_lag_estimated_from_the_data():
    """Velocities that are backward differences of the positions (tagged at the end of the
    interval) lag by half an epoch; correctly tagged ones do not."""
    import numpy as np
    import pandas as pd

    from insgnss.earth import enu_to_geodetic
    from insgnss.preprocess import estimate_velocity_lag

    dt = 0.25
    t = np.arange(0.0, 120.0, dt)
    # a curved, accelerating path: v = (3 + sin(0.3 t), 2 cos(0.2 t))
    e = 3 * t - np.cos(0.3 * t) / 0.3
    n = 2 * np.sin(0.2 * t) / 0.2
    lat, lon, h = enu_to_geodetic(e, n, 0 * t, 0.7, 0.1, 100.0)

    def table(ve, vn):
        return pd.DataFrame({"lat": lat, "lon": lon, "height": h, "vel_e": ve, "vel_n": vn,
                             "vel_u": 0 * t}, index=pd.Index(t, name="time"))

    ve_true, vn_true = 3 + np.sin(0.3 * t), 2 * np.cos(0.2 * t)
    ve_bd = np.r_[ve_true[0], np.diff(e) / dt]  # backward differences
    vn_bd = np.r_[vn_true[0], np.diff(n) / dt]
    lag, info = estimate_velocity_lag(table(ve_bd, vn_bd))
    assert info["applied"] and lag == pytest.approx(dt / 2, abs=0.01)
    lag0, info0 = estimate_velocity_lag(table(ve_true, vn_true))
    assert lag0 == pytest.approx(0.0, abs=0.01)
