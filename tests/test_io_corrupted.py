"""Corrupted-input suite (issue 8): one generated file per problem, each giving the documented
error (docs/formats.md, "Validation") with the file, the editor line and the column."""

from __future__ import annotations

import numpy as np
import pytest
from io_helpers import G0, IMU_HEADER, T0_GPS, kfgins_imu_text, pos_text, raw_imu_text, tag_bytes, trajectory

from insgnss.errors import (
    DataGapError,
    InputFormatError,
    InsgnssWarning,
    InvalidValueError,
    RateMismatchError,
    TimeOrderError,
    UnitError,
)
from insgnss.io import (
    check_gnss_in_imu_span,
    read_imu_csv,
    read_kfgins_gnss,
    read_kfgins_imu,
    read_kfgins_nav,
    read_nmea,
    read_rtklib_pos,
    read_rtklib_tag,
    read_rtklibexplorer_imu,
    read_trajectory_csv,
)

N = 300


def base_rows(t0: float = T0_GPS):
    """Vehicle-like still IMU at 100 Hz (vibration noise, a yaw-rate bias), SI units."""
    rng = np.random.default_rng(11)
    t = t0 + 0.01 * np.arange(N)
    gyro = rng.normal(0.0, 0.003, (N, 3)) + [0.0, 0.0, 0.05]
    accel = np.array([0.05, -0.1, G0]) + rng.normal(0.0, 0.03, (N, 3))
    return t, gyro, accel


def csv_lines(t, gyro, accel):
    return [IMU_HEADER] + [",".join(f"{x:.6f}" if j else f"{x:.3f}" for j, x in enumerate(r))
                           for r in np.column_stack([t, gyro, accel])]


def set_cell(lines, sample, col, text):
    f = lines[sample + 1].split(",")
    f[IMU_HEADER.split(",").index(col)] = text
    lines[sample + 1] = ",".join(f)


def missing_column(t, g, a):
    lines = csv_lines(t, g, a)
    lines[0] = lines[0].replace("gyro_z", "gyro_q")
    return lines, {}


def non_numeric(t, g, a):
    lines = csv_lines(t, g, a)
    set_cell(lines, 10, "accel_y", "abc")
    return lines, {}


def nan_cell(t, g, a):
    lines = csv_lines(t, g, a)
    set_cell(lines, 20, "gyro_x", "nan")
    return lines, {}


def inf_cell(t, g, a):
    lines = csv_lines(t, g, a)
    set_cell(lines, 30, "accel_z", "inf")
    return lines, {}


def empty_file(t, g, a):
    return [], {}


def non_increasing(t, g, a):
    t = t.copy()
    t[40] = t[38]
    return csv_lines(t, g, a), {}


def duplicated(t, g, a):
    t = t.copy()
    t[50] = t[49]
    return csv_lines(t, g, a), {"duplicates": "error"}


def gap(t, g, a):
    keep = np.r_[0:100, 250:N]
    return csv_lines(t[keep], g[keep], a[keep]), {}


def rate_mismatch(t, g, a):
    return csv_lines(t, g, a), {"rate_hz": 200.0}


def deg_s_as_rad_s(t, g, a):
    return csv_lines(t, np.degrees(g), a), {"gyro_unit": "rad/s"}


def g_as_m_s2(t, g, a):
    return csv_lines(t, g, a / G0), {"accel_unit": "m/s^2"}


CASES = [
    # name, builder, error, row (1-based, header = 1), column
    ("missing column", missing_column, InputFormatError, 1, "gyro_z"),
    ("non-numeric cell", non_numeric, InputFormatError, 12, "accel_y"),
    ("NaN", nan_cell, InvalidValueError, 22, "gyro_x"),
    ("inf", inf_cell, InvalidValueError, 32, "accel_z"),
    ("empty file", empty_file, InputFormatError, 1, None),
    ("non-increasing time", non_increasing, TimeOrderError, 42, "time"),
    ("duplicated time", duplicated, TimeOrderError, 52, "time"),
    ("gap", gap, DataGapError, 102, "time"),
    ("rate mismatch", rate_mismatch, RateMismatchError, 3, "time"),
    ("deg/s declared as rad/s", deg_s_as_rad_s, UnitError, 7, "gyro_z"),
    ("g declared as m/s^2", g_as_m_s2, UnitError, 2, "accel_z"),
]


@pytest.mark.parametrize("name, build, error, row, column", CASES, ids=[c[0] for c in CASES])
def test_imu_csv_problem(tmp_path, name, build, error, row, column):
    lines, kw = build(*base_rows())
    p = tmp_path / "imu.csv"
    p.write_text("\n".join(lines) + ("\n" if lines else ""))
    with pytest.raises(error) as e:
        read_imu_csv(p, **kw)
    err = e.value
    assert (err.file, err.row, err.column) == (str(p), row, column), str(err)
    assert str(p) in str(err) and f"row {row}" in str(err)
    assert err.expected is not None or name == "missing column"


def test_clean_base_file_reads(tmp_path):
    p = tmp_path / "imu.csv"
    p.write_text("\n".join(csv_lines(*base_rows())))
    assert len(read_imu_csv(p, rate_hz=100.0, gyro_unit="rad/s", accel_unit="m/s^2")) == N


def test_duplicates_and_short_gaps_are_repaired_by_default(tmp_path):
    t, g, a = base_rows()
    t = t.copy()
    t[50] = t[49]
    keep = np.r_[0:100, 150:N]  # 0.51 s logger gap: bridged
    p = tmp_path / "imu.csv"
    p.write_text("\n".join(csv_lines(t[keep], g[keep], a[keep])))
    with pytest.warns(InsgnssWarning):
        df = read_imu_csv(p)
    assert df.attrs["dropped_duplicates"] == [{"row": 52, "time": pytest.approx(t[49])}]
    gaps = [x for x in df.attrs["gaps"] if x["duration"] > 0.1]
    assert len(gaps) == 1 and gaps[0]["row"] == 102 and gaps[0]["action"] == "bridged"
    assert gaps[0]["duration"] == pytest.approx(0.51)


def test_gnss_outside_imu_span(tmp_path):
    t, g, a = base_rows()
    p_imu = tmp_path / "imu.csv"
    p_imu.write_text("\n".join(csv_lines(t, g, a)))
    imu = read_imu_csv(p_imu, time_base="gps")
    tg, lat, lon, h, _ = trajectory(8, t0=T0_GPS + 86400.0)  # one day later
    p_pos = tmp_path / "gnss.pos"
    p_pos.write_text(pos_text(tg, lat, lon, h))
    gnss = read_rtklib_pos(p_pos)
    with pytest.raises(TimeOrderError) as e:
        check_gnss_in_imu_span(gnss, imu)
    assert (e.value.file, e.value.row, e.value.column) == (str(p_pos), 4, "GPST")


# ------------------------------------------------------------------ the other readers


def _pos(tmp_path, mutate):
    t, lat, lon, h, vel = trajectory(6)
    lines = pos_text(t, lat, lon, h, vel=vel).splitlines()
    mutate(lines)
    p = tmp_path / "x.pos"
    p.write_text("\n".join(lines) + "\n")
    return read_rtklib_pos(p), p


def _replace_field(lines, i, k, text):
    f = lines[i].split()
    f[k] = text
    lines[i] = " ".join(f)


def _kfgins_imu(tmp_path, mutate):
    t = 1000.0 + 0.01 * np.arange(1, 41)
    text = kfgins_imu_text(t, np.full((40, 3), 1e-5), np.tile([0.0, 0.0, -G0 * 0.01], (40, 1)))
    lines = text.splitlines()
    mutate(lines)
    p = tmp_path / "imu.txt"
    p.write_text("\n".join(lines) + "\n")
    return read_kfgins_imu(p), p


def _raw(tmp_path, mutate):
    n = 50
    ms = 1000 + 10 * np.arange(n)
    lines = raw_imu_text(ms, np.tile([0.1, 0.0, 1.0], (n, 1)), np.zeros((n, 3))).splitlines()
    mutate(lines)
    p = tmp_path / "imu_1.csv"
    p.write_text("\n".join(lines) + "\n")
    (tmp_path / "imu_1.csv.tag").write_bytes(tag_bytes(T0_GPS, np.linspace(0, (n - 3) * 10, 10)))
    return read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180)), p


OTHER = [
    ("pos non-numeric", lambda tp: _pos(tp, lambda ls: _replace_field(ls, 4, 4, "4O.1")),
     InputFormatError, 5, "height(m)"),
    ("pos NaN", lambda tp: _pos(tp, lambda ls: _replace_field(ls, 5, 15, "nan")),
     InvalidValueError, 6, "vn(m/s)"),
    ("pos missing field", lambda tp: _pos(tp, lambda ls: ls.__setitem__(6, ls[6].rsplit(" ", 1)[0])),
     InputFormatError, 7, None),
    ("pos duplicated epoch", lambda tp: read_rtklib_pos(_dup_pos(tp), duplicates="error"),
     TimeOrderError, 8, "GPST"),
    ("kfgins imu extra field", lambda tp: _kfgins_imu(tp, lambda ls: ls.__setitem__(3, ls[3] + " 1")),
     InputFormatError, 4, None),
    ("kfgins imu inf", lambda tp: _kfgins_imu(tp, lambda ls: _replace_field(ls, 7, 5, "inf")),
     InvalidValueError, 8, "dv_y"),
    ("raw imu non-numeric",
     lambda tp: _raw(tp, lambda ls: ls.__setitem__(9, ls[9].replace("1.000", "1.0.0"))),
     InputFormatError, 10, "az"),
    ("raw imu backwards counter",
     lambda tp: _raw(tp, lambda ls: ls.__setitem__(9, ls[9].rsplit(",", 1)[0] + ",900")),
     TimeOrderError, 10, "t_ms"),
]


def _dup_pos(tmp_path):
    t, lat, lon, h, vel = trajectory(6)
    t[4] = t[3]
    p = tmp_path / "d.pos"
    p.write_text(pos_text(t, lat, lon, h, vel=vel))
    return p


@pytest.mark.parametrize("name, run, error, row, column", OTHER, ids=[c[0] for c in OTHER])
def test_other_readers_problem(tmp_path, name, run, error, row, column):
    with pytest.raises(error) as e:
        run(tmp_path)
    assert (e.value.row, e.value.column) == (row, column), str(e.value)
    assert e.value.file is not None and str(tmp_path) in e.value.file


@pytest.mark.parametrize("reader", [read_imu_csv, read_rtklib_pos, read_kfgins_imu, read_kfgins_gnss,
                                    read_kfgins_nav, read_nmea, read_trajectory_csv, read_rtklib_tag])
def test_every_reader_rejects_an_empty_file(tmp_path, reader):
    p = tmp_path / "empty.txt"
    p.write_text("")
    with pytest.raises(InputFormatError) as e:
        reader(p)
    assert e.value.file == str(p)
