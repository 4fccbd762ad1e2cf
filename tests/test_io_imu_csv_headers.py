"""IMU CSV: sample-index time (``time_unit = "sample"``) and multi-row headers
(``header_rows``), read directly and through a foot-mounted job file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from insgnss.cli import main
from insgnss.config import load_job
from insgnss.errors import ConfigError, InputFormatError
from insgnss.imu import ACCEL_COLS, GYRO_COLS, increments
from insgnss.io import read_imu_csv
from insgnss.io.imu_csv import header_names
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.pipeline import load_inputs
from insgnss.simulate.trajectory import generate

RATE = 204.8  # gaitmap's NilsPod rate: 1/RATE is not a short decimal


def _walk(rate=RATE, steps=4):
    """Rates (N,3) gyro [rad/s], accel [m/s^2] of a simulated foot: stand, walk, stand."""
    tr = generate(rate=rate, lat=np.radians(49.6), lon=np.radians(11.0), vehicle="pedestrian",
                  segments=[{"type": "stand", "duration": 1.0},
                            {"type": "walk", "steps": steps},
                            {"type": "stand", "duration": 1.0}])
    t, dth, dv = increments(inverse_mechanize(tr.truth))
    dt = np.diff(t)
    w, f = np.empty_like(dth), np.empty_like(dv)
    w[1:], f[1:] = dth[1:] / dt[:, None], dv[1:] / dt[:, None]
    w[0], f[0] = w[1], f[1]
    return tr, w, f


def gaitmap_text(w_left, f_left, w_right, f_right, start=0) -> str:
    """A gaitmap-style file (pandas MultiIndex columns): two header rows, sample index,
    acc in m/s^2 and gyr in deg/s, both feet interleaved."""
    cols = []
    for ax in "xyz":
        cols += [("left_sensor", f"acc_{ax}"), ("right_sensor", f"acc_{ax}")]
    for ax in "xyz":
        cols += [("left_sensor", f"gyr_{ax}"), ("right_sensor", f"gyr_{ax}")]
    lines = ["sensor," + ",".join(c[0] for c in cols), "axis," + ",".join(c[1] for c in cols)]
    data = {"left_sensor": np.hstack([f_left, np.degrees(w_left)]),
            "right_sensor": np.hstack([f_right, np.degrees(w_right)])}
    key = {f"acc_{a}": i for i, a in enumerate("xyz")} | {f"gyr_{a}": 3 + i
                                                          for i, a in enumerate("xyz")}
    for k in range(w_left.shape[0]):
        lines.append(f"{start + k}," + ",".join(f"{data[s][k, key[a]]:.17g}" for s, a in cols))
    return "\n".join(lines) + "\n"


LEFT = {"time": "sensor_axis", "gyro_x": "left_sensor_gyr_x", "gyro_y": "left_sensor_gyr_y",
        "gyro_z": "left_sensor_gyr_z", "accel_x": "left_sensor_acc_x",
        "accel_y": "left_sensor_acc_y", "accel_z": "left_sensor_acc_z"}


def test_header_names_join_levels_and_continue_merged_cells():
    names, levels = header_names(["sensor,left,,right,", "axis,acc_x,acc_y,acc_x,acc_y"])
    assert names == ["sensor_axis", "left_acc_x", "left_acc_y", "right_acc_x", "right_acc_y"]
    assert levels[2] == ("left", "acc_y")
    # pandas writes an empty top cell over an unnamed index; a one-row header is the cells
    names, _ = header_names([",a,b", ",x,y"])
    assert names == ["", "a_x", "b_y"]
    assert header_names(["t, gx ,\"gy\""])[0] == ["t", "gx", "gy"]


def test_gaitmap_two_row_header_with_sample_index(tmp_path):
    _, w, f = _walk(steps=2)
    p = tmp_path / "gaitmap.csv"
    p.write_text(gaitmap_text(w, f, -w, f[::-1], start=7))
    df = read_imu_csv(p, columns=LEFT, header_rows=2, time_unit="sample", rate_hz=RATE,
                      gyro_unit="deg/s")
    n = w.shape[0]
    # t = k / rate, exactly (the index is integral), from the first index 7
    np.testing.assert_array_equal(df.index.to_numpy(), (7 + np.arange(n)) / RATE)
    np.testing.assert_allclose(df[GYRO_COLS].to_numpy(), w, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(df[ACCEL_COLS].to_numpy(), f, rtol=1e-15, atol=1e-14)
    assert df.attrs["source_rows"][0] == 3  # after the two header lines
    # the same columns declared by their levels; the right foot is the other interleave
    right = {s: ["right_sensor", v.removeprefix("left_sensor_")] for s, v in LEFT.items()
             if s != "time"} | {"time": 0}
    dr = read_imu_csv(p, columns=right, header_rows=2, time_unit="sample", rate_hz=RATE,
                      gyro_unit="deg/s")
    np.testing.assert_allclose(dr[GYRO_COLS].to_numpy(), -w, rtol=1e-14, atol=1e-15)


def test_sample_index_errors_name_the_row_and_the_key(tmp_path):
    _, w, f = _walk(steps=1)
    text = gaitmap_text(w, f, w, f).splitlines()
    p = tmp_path / "g.csv"
    p.write_text("\n".join(text) + "\n")
    with pytest.raises(ConfigError, match="rate_hz"):
        read_imu_csv(p, columns=LEFT, header_rows=2, time_unit="sample", gyro_unit="deg/s")
    bad = text[:]
    bad[6] = "4.5" + bad[6][bad[6].index(","):]
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(InputFormatError, match="not an integer") as e:
        read_imu_csv(p, columns=LEFT, header_rows=2, time_unit="sample", rate_hz=RATE,
                     gyro_unit="deg/s")
    assert e.value.row == 7 and e.value.column == "sensor_axis"
    p.write_text("\n".join(text) + "\n")
    # a one-row reading of a two-row header: the level names are not columns
    with pytest.raises(InputFormatError, match="missing column"):
        read_imu_csv(p, columns=LEFT, time_unit="sample", rate_hz=RATE, gyro_unit="deg/s")
    with pytest.raises(ConfigError, match="header levels"):
        read_imu_csv(p, columns=LEFT | {"gyro_x": ["left_sensor", "x", "y"]}, header_rows=2,
                     time_unit="sample", rate_hz=RATE, gyro_unit="deg/s")
    with pytest.raises(ConfigError, match="header_rows"):
        read_imu_csv(p, columns=LEFT, header_rows=0, time_unit="sample", rate_hz=RATE)
    # an ambiguous joined name is an error, not the first match
    dup = text[:]
    dup[0] = dup[0].replace("right_sensor", "left_sensor")
    p.write_text("\n".join(dup) + "\n")
    with pytest.raises(InputFormatError, match="not unique"):
        read_imu_csv(p, columns=LEFT, header_rows=2, time_unit="sample", rate_hz=RATE,
                     gyro_unit="deg/s")


def _index_stamped(path, w, f):
    """UCR-style: ``time_index`` column and one header row, SI units."""
    rows = ["time_index,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z,is_zero_vel"]
    rows += [f"{k}," + ",".join(f"{x:.17g}" for x in (*f[k], *w[k])) + ",0"
             for k in range(w.shape[0])]
    path.write_text("\n".join(rows) + "\n")


FOOT_JOB = """
[job]
name = "{name}"
time_base = "run"
[process]
preset = "foot"
[inputs.imu]
path = "{file}"
time_unit = "sample"
rate_hz = {rate}
{extra}
[outputs]
dir = "out_{name}"
report = false
progress = false
"""


def test_gaitmap_and_index_stamped_files_run_through_a_foot_job(tmp_path):
    tr, w, f = _walk(steps=4)
    (tmp_path / "gaitmap.csv").write_text(gaitmap_text(w, f, w, f))
    _index_stamped(tmp_path / "ucr.csv", w, f)
    cols = "\n".join(f'columns.{k} = "{v}"' for k, v in LEFT.items())
    jobs = {
        "gaitmap": FOOT_JOB.format(name="gaitmap", file="gaitmap.csv", rate=RATE,
                                   extra=f'header_rows = 2\ngyro_unit = "deg/s"\n{cols}'),
        "ucr": FOOT_JOB.format(name="ucr", file="ucr.csv", rate=RATE, extra=(
            'columns = { time = "time_index", gyro_x = "gyro_x", gyro_y = "gyro_y", '
            'gyro_z = "gyro_z", accel_x = "acc_x", accel_y = "acc_y", accel_z = "acc_z" }')),
    }
    t_true = tr.truth.index.to_numpy()
    for name, text in jobs.items():
        jp = tmp_path / f"{name}.toml"
        jp.write_text(text)
        job = load_job(jp)
        imu = load_inputs(job).imu
        np.testing.assert_allclose(imu.index.to_numpy(), t_true, atol=1e-12)
        np.testing.assert_allclose(imu[GYRO_COLS].to_numpy(), w, atol=1e-12)
        assert main(["process", str(jp), "--no-progress"]) == 0
        s = json.loads((tmp_path / f"out_{name}" / "summary.json").read_text())
        assert s["complete"] and s["preset"] == "foot" and s["zupt_updates"] > 100
    # the job schema checks the time unit at load time
    bad = jobs["ucr"].replace('time_unit = "sample"', 'time_unit = "samples"')
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(ConfigError, match="inputs.imu.time_unit"):
        load_job(tmp_path / "bad.toml")
