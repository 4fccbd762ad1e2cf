"""NMEA GNSS in a job: 2-D velocity (speed and course over ground) for the gnss_velocity start
and as a 2-D velocity measurement; position sigmas from GST, else from the HDOP with the
reader's UERE, else from aiding.gnss_position_std, and a message naming that key when none is
available."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pynmea2
import pytest
from example_data import NMEA_HDOP, generate_for, horizontal_errors
from io_helpers import gga, gst, rmc

from insgnss.config import load_job_dict
from insgnss.errors import ConfigError
from insgnss.io.nmea import UERE, VDOP_PER_HDOP, read_nmea
from insgnss.pipeline import run_job

LAT, LON = 45.0, 7.0

#: the docs/jobs.md NMEA example (generic CSV IMU in deg/s, g, ms, FRD; NMEA GNSS)
JOB = {"inputs": {"imu": {"format": "csv", "path": "imu.csv", "gyro_unit": "deg/s",
                          "accel_unit": "g", "time_unit": "ms", "axis_map": "y,x,-z",
                          "columns": {"time": "t_ms", "gyro_x": "gx", "gyro_y": "gy",
                                      "gyro_z": "gz", "accel_x": "ax", "accel_y": "ay",
                                      "accel_z": "az"}},
                  "gnss": {"format": "nmea", "path": "gnss.nmea", "lever_arm": [0.0, 0.3, 1.1]}},
       "initialization": {"method": "gnss_velocity"},
       "filter": {"imu_grade": "consumer"},
       "outputs": {"report": False, "progress": False}}


def gsa(pdop, hdop, vdop) -> str:
    f = ("A", "3", "05", "07") + ("",) * 10 + (f"{pdop:.1f}", f"{hdop:.1f}", f"{vdop:.1f}")
    return str(pynmea2.GSA("GN", "GSA", f))


def _run(job, tmp_path):
    job, truth = generate_for(job, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = run_job(load_job_dict(job, tmp_path / "job.toml"), progress=False)
    return res, truth


def test_reader_sigmas_from_gst_else_hdop(tmp_path):
    tod = 12 * 3600.0
    lines = [rmc(tod, "080725", LAT, LON, 10.0, 45.0), gga(tod, LAT, LON, 300.0, quality=1,
                                                           hdop=1.2),
             gsa(2.0, 1.2, 1.7), gst(tod, 0.5, 0.6, 0.9),
             rmc(tod + 1, "080725", LAT, LON, 10.0, 45.0), gga(tod + 1, LAT, LON, 300.0,
                                                               quality=2, hdop=0.8),
             gsa(2.0, 0.8, 1.5),
             rmc(tod + 2, "080725", LAT, LON, 10.0, 45.0), gga(tod + 2, LAT, LON, 300.0,
                                                               quality=4, hdop=0.7)]
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every line is valid NMEA
        df = read_nmea(p)
    # epoch 0: GST wins over the HDOP
    np.testing.assert_allclose(df[["north_std", "east_std", "up_std"]].iloc[0], [0.5, 0.6, 0.9])
    # epoch 1: DGPS, HDOP 0.8, VDOP 1.5 (GSA): sigma_e = sigma_n = HDOP UERE / sqrt 2
    h = 0.8 * UERE[2] / np.sqrt(2.0)
    np.testing.assert_allclose(df[["east_std", "north_std", "up_std"]].iloc[1],
                               [h, h, 1.5 * UERE[2]])
    assert np.hypot(h, h) == pytest.approx(0.8 * UERE[2])  # the definition of HDOP
    # epoch 2: RTK fixed, no GSA after it: VDOP = 2 HDOP
    h = 0.7 * UERE[4] / np.sqrt(2.0)
    np.testing.assert_allclose(df[["east_std", "north_std", "up_std"]].iloc[2],
                               [h, h, VDOP_PER_HDOP * 0.7 * UERE[4]])
    assert df.attrs["std_source"] == {"gst": 1, "hdop": 2, "none": 0}
    # horizontal velocity only
    assert "vel_u" not in df.columns and "vel_e" in df.columns
    # GST only
    only = read_nmea(p, uere=None)
    assert only.attrs["std_source"] == {"gst": 1, "hdop": 0, "none": 2}
    assert np.isnan(only["east_std"].iloc[1:]).all()


def test_gnss_velocity_start_and_hdop_sigmas(tmp_path):
    """The docs example that died with KeyError "['vel_u'] not in index": it starts from the
    NMEA course and speed and the sigmas of the simulated receiver (HDOP 0.9, DGPS) match the
    noise, so every epoch is accepted and the solution is sub-metre."""
    res, truth = _run(JOB, tmp_path)
    s = res.summary
    assert s["complete"] and s["initialization"]["method"] == "gnss_velocity"
    assert s["initialization"]["heading_source"] == "gnss_velocity"
    c = s["measurements"]["gnss_pos"]
    assert c["applied"] == c["offered"] > 100 and c["rejected"] == 0
    g = res.inputs.gnss
    assert g.attrs["std_source"]["gst"] > 0 and g.attrs["std_source"]["hdop"] > 0
    np.testing.assert_allclose(g["east_std"][g.index[1::4]], NMEA_HDOP / np.sqrt(2), rtol=1e-6)
    err = horizontal_errors(res.filter.smoothed, truth)
    assert np.sqrt(np.mean(err ** 2)) < 0.5 and err.max() < 1.5


def test_velocity_aiding_is_2d(tmp_path):
    job = copy.deepcopy(JOB)
    job["aiding"] = {"gnss_velocity": True}
    with pytest.raises(ConfigError, match="aiding.gnss_velocity_std") as e:
        _run(job, tmp_path / "a")
    assert e.value.column == "aiding.gnss_velocity_std" and "NMEA has none" in str(e.value)
    job["aiding"]["gnss_velocity_std"] = 0.05
    res, truth = _run(job, tmp_path / "b")
    assert res.summary["complete"]
    inn = res.filter.innovations
    vel = inn[inn["type"] == "gnss_vel"]
    assert len(vel) > 100 and vel["accepted"].mean() > 0.95
    assert (vel["dof"] == 2).all()  # east and north only
    # the 2-D velocity innovations are the horizontal velocity errors: RMS near their 5 cm
    # (the simulated RMC speed and course carry the GNSS velocity noise)
    assert np.isfinite(vel["nis"]).all() and 0.3 < vel["nis"].mean() / 2 < 3.0
    err = horizontal_errors(res.filter.smoothed, truth)
    assert err.max() < 1.5


def test_no_sigma_names_the_key(tmp_path):
    job, _ = generate_for(JOB, tmp_path)
    # strip GST and the HDOP field from every sentence: no sigma anywhere
    p = tmp_path / "gnss.nmea"
    out = []
    for line in p.read_text().splitlines():
        if "GST" in line:
            continue
        if "GGA" in line:
            f = line.split("*")[0].split(",")
            f[8] = ""
            body = ",".join(f)[1:]
            ck = 0
            for ch in body:
                ck ^= ord(ch)
            line = f"${body}*{ck:02X}"
        out.append(line)
    p.write_text("\n".join(out) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ConfigError, match="no GST sentence and no HDOP") as e:
            run_job(load_job_dict(job, tmp_path / "job.toml"), progress=False)
        assert e.value.column == "aiding.gnss_position_std"
        job["aiding"] = {"gnss_position_std": 0.7}
        res = run_job(load_job_dict(job, tmp_path / "job.toml"), progress=False)
    assert res.summary["complete"] and res.summary["measurements"]["gnss_pos"]["applied"] > 100
