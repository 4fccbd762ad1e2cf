"""RTKLIB .pos (all layouts, time systems) and .tag readers: known values and the real drive."""

from __future__ import annotations

import numpy as np
import pytest
from io_helpers import T0_GPS, pos_text, tag_bytes, trajectory

from insgnss.errors import InputFormatError, InvalidValueError, TimeOrderError
from insgnss.io import read_rtklib_pos, read_rtklib_tag
from insgnss.io.gpstime import (
    UNIX_GPST_OFFSET,
    datetime64_from_gps_seconds,
    gps_seconds_from_datetime64,
    gps_seconds_from_utc,
    week_sow_from_gps_seconds,
)

DEG_1E9 = np.radians(1e-9)


def write(tmp_path, text, name="sol.pos"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("time_format", ["calendar", "week"])
@pytest.mark.parametrize("pos", ["llh", "dms", "ecef"])
def test_known_solution_all_layouts(tmp_path, time_format, pos):
    t, lat, lon, h, vel = trajectory(12)
    q = np.array([1] * 10 + [2, 5])
    p = write(tmp_path, pos_text(t, lat, lon, h, q=q, vel=vel, time_format=time_format, pos=pos))
    df = read_rtklib_pos(p)
    np.testing.assert_allclose(df.index.to_numpy(), t, atol=1e-6)
    tol_ang = {"llh": 1.1 * DEG_1E9, "dms": np.radians(1e-8 / 3600), "ecef": 1e-4 / 6.4e6}[pos]
    np.testing.assert_allclose(df["lat"], lat, atol=tol_ang)
    np.testing.assert_allclose(df["lon"], lon, atol=tol_ang / np.cos(lat[0]))
    np.testing.assert_allclose(df["height"], h, atol=1e-4)
    np.testing.assert_allclose(df[["east_std", "north_std", "up_std"]].to_numpy(),
                               np.tile([0.02, 0.01, 0.03], (12, 1)), atol=2e-6)
    np.testing.assert_allclose(df[["vel_e", "vel_n", "vel_u"]].to_numpy(), vel, atol=2e-5)
    np.testing.assert_allclose(df[["vel_e_std", "vel_n_std", "vel_u_std"]].to_numpy(),
                               np.tile([0.06, 0.05, 0.07], (12, 1)), atol=2e-6)
    assert df["q"].tolist() == q.tolist() and df["q"].dtype == np.int64
    assert (df["ns"] == 21).all()
    assert df.attrs["time_base"] == "gps" and df.attrs["gps_week"] == 2374
    assert df.attrs["time_system"] == "GPST" and df.attrs["format"] == "rtklib-pos"
    assert df.attrs["source_rows"].tolist() == list(range(4, 16))


@pytest.mark.parametrize("system", ["UTC", "JST"])
def test_utc_and_jst_are_converted_with_leap_seconds(tmp_path, system):
    t, lat, lon, h, _ = trajectory(5)
    df = read_rtklib_pos(write(tmp_path, pos_text(t, lat, lon, h, system=system)))
    np.testing.assert_allclose(df.index.to_numpy(), t, atol=1e-6)
    assert df.attrs["time_system"] == system


def test_leap_second_table():
    utc = np.array(["1980-01-06T00:00:00", "2016-12-31T23:59:59", "2017-01-01T00:00:00",
                    "2025-07-08T19:34:00.499"], dtype="datetime64[ns]")
    gps = gps_seconds_from_utc(utc)
    assert gps[0] == 0.0
    assert gps[2] - gps[1] == pytest.approx(2.0)  # the leap second 2016-12-31T23:59:60
    assert gps[3] == pytest.approx(T0_GPS, abs=1e-6)  # GPST = UTC + 18 s
    assert str(datetime64_from_gps_seconds(T0_GPS).astype("datetime64[ms]")) == "2025-07-08T19:34:18.499"


def test_time_bases(tmp_path):
    t, lat, lon, h, _ = trajectory(4)
    p = write(tmp_path, pos_text(t, lat, lon, h))
    week, sow = week_sow_from_gps_seconds(t)
    df = read_rtklib_pos(p, time_base="sow")
    np.testing.assert_allclose(df.index, sow, atol=1e-6)
    assert df.attrs["time_base"] == "sow" and df.attrs["gps_week"] == week[0] == 2374
    df = read_rtklib_pos(p, time_base="unix_gpst")
    np.testing.assert_allclose(df.index, t + UNIX_GPST_OFFSET, atol=1e-6)


def test_without_header_and_without_velocity(tmp_path):
    t, lat, lon, h, _ = trajectory(6)
    df = read_rtklib_pos(write(tmp_path, pos_text(t, lat, lon, h, header=False)))
    assert "vel_e" not in df.columns and len(df) == 6
    np.testing.assert_allclose(df["lat"], lat, atol=1.1 * DEG_1E9)


def test_errors_name_file_row_column(tmp_path):
    t, lat, lon, h, vel = trajectory(6)
    lines = pos_text(t, lat, lon, h, vel=vel).splitlines()
    bad = lines.copy()
    bad[5] = bad[5].replace(" 1 21 ", " 1 2x1 ")
    with pytest.raises(InputFormatError) as e:
        read_rtklib_pos(write(tmp_path, "\n".join(bad)))
    assert (e.value.row, e.value.column, e.value.found) == (6, "ns", "'2x1'")
    bad = lines.copy()
    bad[4] = bad[4].replace(" 1 21 ", " 7 21 ")
    with pytest.raises(InvalidValueError) as e:
        read_rtklib_pos(write(tmp_path, "\n".join(bad)))
    assert (e.value.row, e.value.column) == (5, "Q")
    bad = lines.copy()
    bad[6] = bad[6].replace("2025/07/08", "2025/07/38")
    with pytest.raises(InputFormatError) as e:
        read_rtklib_pos(write(tmp_path, "\n".join(bad)))
    assert (e.value.row, e.value.column) == (7, "GPST")
    bad = lines[:5] + [lines[6], lines[5]] + lines[7:]
    with pytest.raises(TimeOrderError) as e:
        read_rtklib_pos(write(tmp_path, "\n".join(bad)))
    assert (e.value.row, e.value.column) == (7, "GPST")
    bad = lines.copy()
    bad[2] = bad[2].replace("latitude(deg)", "e-baseline(m)")
    with pytest.raises(InputFormatError, match="unsupported") as e:
        read_rtklib_pos(write(tmp_path, "\n".join(bad)))
    assert e.value.row == 3


def test_tag_round_trip(tmp_path):
    ticks = np.arange(0, 5000, 15)
    for size in (4, 8):
        p = tmp_path / f"x{size}.tag"
        p.write_bytes(tag_bytes(T0_GPS + 3.355, ticks, fpos_size=size))
        tag = read_rtklib_tag(p)
        assert tag.start == pytest.approx(T0_GPS + 3.355, abs=1e-6)
        assert tag.end == pytest.approx(T0_GPS + 3.355 + 4.995, abs=1e-6)
        np.testing.assert_array_equal(tag.ticks, ticks)
        np.testing.assert_array_equal(tag.fpos, np.arange(ticks.size) * 44)
        assert tag.version == "demo5" and tag.tick_f == 12345


def test_tag_errors(tmp_path):
    p = tmp_path / "x.tag"
    p.write_bytes(b"TIMETAG XYZ" + bytes(80))
    with pytest.raises(InputFormatError, match="not an RTKLIB time-tag"):
        read_rtklib_tag(p)
    good = tag_bytes(T0_GPS, [0, 10, 20, 30])
    p.write_bytes(good[:70])
    with pytest.raises(InputFormatError, match="truncated"):
        read_rtklib_tag(p)
    p.write_bytes(good[:-3])
    with pytest.raises(InputFormatError, match="truncated time-tag record"):
        read_rtklib_tag(p)
    p.write_bytes(tag_bytes(T0_GPS, [0, 10, 5, 30], fpos=[0, 1, 2, 3]))
    with pytest.raises(TimeOrderError) as e:
        read_rtklib_tag(p)
    assert (e.value.row, e.value.column) == (3, "tick")


def test_real_drive_pos(drive_dir):
    df = read_rtklib_pos(drive_dir / "gnss_1934_sf.pos")
    assert len(df) == 2197 and int((df["q"] == 1).sum()) == 2189 and int((df["q"] == 2).sum()) == 8
    assert df.index[0] == pytest.approx(1436038458.499, abs=1e-6)  # 2025-07-08 19:34:18.499 GPST
    assert df.index[-1] - df.index[0] == pytest.approx(549.0, abs=1e-6)
    assert np.degrees(df["lat"].iloc[0]) == pytest.approx(40.0966268, abs=1e-9)
    assert np.degrees(df["lon"].iloc[0]) == pytest.approx(-105.1474483, abs=1e-9)
    assert df["height"].between(1570, 1610).all()
    assert np.hypot(df["vel_e"], df["vel_n"]).max() == pytest.approx(16.3, abs=0.1)
    assert df["north_std"].iloc[0] == pytest.approx(0.0098995)
    assert df.attrs["source_rows"][0] == 2


def test_real_drive_tag(drive_dir):
    tag = read_rtklib_tag(drive_dir / "imu_1934.csv.tag")
    want = gps_seconds_from_datetime64(np.array(["2025-07-08T19:34:21.854",
                                                 "2025-07-08T19:43:30.585"], "datetime64[ns]"))
    np.testing.assert_allclose([tag.start, tag.end], want, atol=1e-6)
    assert tag.ticks.size == 37632 and tag.version == "demo5"
