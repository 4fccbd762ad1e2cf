"""rtklibexplorer raw IMU: tag time mapping, units, mounting to body RFU; the real drive."""

from __future__ import annotations

import numpy as np
import pytest
from io_helpers import G0, T0_GPS, raw_imu_text, tag_bytes
from test_io_imu_csv import groves_euler_to_ctm

from insgnss.attitude import P_SWAP
from insgnss.errors import ConfigError, InputFormatError, TimeOrderError
from insgnss.imu import ACCEL_COLS, GYRO_COLS
from insgnss.io import DRIVE_0708, read_rtklib_pos, read_rtklibexplorer_imu, rtklibexplorer_mounting
from insgnss.io.gpstime import gps_seconds_from_datetime64


def make(tmp_path, ms, accel_g, gyro_dps, *, span_ms, start=T0_GPS + 3.355):
    p = tmp_path / "imu_0000.csv"
    p.write_text(raw_imu_text(ms, accel_g, gyro_dps))
    (tmp_path / "imu_0000.csv.tag").write_bytes(tag_bytes(start, np.linspace(0, span_ms, 50).round()))
    return p


def test_time_mapping_like_the_authors_converter(tmp_path):
    n = 202
    ms = 5000 + 10 * np.arange(n)
    ms[57] += 1  # counter jitter is kept (linear map, no resampling)
    acc = np.tile([0.0, 0.0, 1.0], (n, 1))
    gyr = np.zeros((n, 3))
    p = make(tmp_path, ms, acc, gyr, span_ms=2005)
    df = read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180))
    kept = ms[1:-1]  # first and last line skipped
    want = T0_GPS + 3.355 + (kept - kept[0]) * (2.005 / (kept[-1] - kept[0]))
    np.testing.assert_allclose(df.index.to_numpy(), want, atol=1e-6)
    assert len(df) == n - 2 and df.attrs["source_rows"][0] == 2
    assert df.attrs["time_base"] == "gps"
    df2 = read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180), time_offset=-0.125)
    np.testing.assert_allclose(df2.index.to_numpy(), want - 0.125, atol=1e-6)


def test_units_and_mounting_180_0_180(tmp_path):
    """Raw +z (1 g) becomes body up; raw +x becomes body backward (RFU -y)."""
    n = 60
    ms = 1000 + 10 * np.arange(n)
    acc = np.tile([0.0, 0.0, 1.0], (n, 1))
    acc[::2] = [0.02, 0.0, 1.0]
    gyr = np.tile([1.0, 2.0, 3.0], (n, 1))  # deg/s
    p = make(tmp_path, ms, acc, gyr, span_ms=(n - 3) * 10)
    df = read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180), check_units=True)
    f = df[ACCEL_COLS].to_numpy()
    np.testing.assert_allclose(f[1], [0.0, -0.02 * G0, G0], atol=1e-12)  # row 3 of the file
    np.testing.assert_allclose(df[GYRO_COLS].to_numpy()[0], np.radians([2.0, -1.0, 3.0]), atol=1e-15)


def test_mounting_matches_the_authors_rotation():
    rpy = np.array(DRIVE_0708["mounting_rpy_deg"])
    np.testing.assert_allclose(rpy, np.array([180, 0, 180]) + [0, -6.79, 5.35])
    M = rtklibexplorer_mounting(rpy)
    np.testing.assert_allclose(M, P_SWAP @ groves_euler_to_ctm(np.radians(rpy)), atol=1e-14)


def test_errors(tmp_path):
    n = 40
    ms = 1000 + 10 * np.arange(n)
    acc = np.tile([0.0, 0.0, 1.0], (n, 1))
    gyr = np.zeros((n, 3))
    p = make(tmp_path, ms, acc, gyr, span_ms=(n - 3) * 10)
    with pytest.raises(ConfigError):
        read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0))
    bad = ms.copy()
    bad[20] = bad[18]
    p = make(tmp_path, bad, acc, gyr, span_ms=(n - 3) * 10)
    with pytest.raises(TimeOrderError) as e:
        read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180))
    assert (e.value.row, e.value.column) == (21, "t_ms")
    p = make(tmp_path, ms, acc, gyr, span_ms=(n - 3) * 10 * 1.5)  # wrong tag file
    with pytest.raises(TimeOrderError, match="time-tag span"):
        read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180))
    (tmp_path / "imu_0000.csv.tag").unlink()
    with pytest.raises(InputFormatError, match="time-tag file not found"):
        read_rtklibexplorer_imu(p, mounting_rpy_deg=(180, 0, 180))


def test_real_drive(drive_dir):
    imu = read_rtklibexplorer_imu(drive_dir / "imu_1934.csv",
                                  mounting_rpy_deg=DRIVE_0708["mounting_rpy_deg"],
                                  rate_hz=DRIVE_0708["rate_hz"])
    assert len(imu) == 54858
    assert 1.0 / np.median(np.diff(imu.index)) == pytest.approx(100.0, rel=1e-3)
    span = gps_seconds_from_datetime64(np.array(["2025-07-08T19:34:21.854",
                                                 "2025-07-08T19:43:30.585"], "datetime64[ns]"))
    np.testing.assert_allclose(imu.index[[0, -1]], span, atol=1e-6)
    assert imu.attrs["gaps"] == [] and imu.attrs["dropped_duplicates"] == []
    # parked for the first ~38 s: specific force up in RFU, about (0, 0, 9.8)
    still = imu.loc[: imu.index[0] + 30.0]
    f = still[ACCEL_COLS].mean().to_numpy()
    assert np.linalg.norm(f) == pytest.approx(9.95, abs=0.1)  # raw |f| is 1.013-1.018 g
    assert abs(f[0]) < 0.3 and abs(f[1]) < 0.3 and f[2] > 9.7
    assert np.abs(still[GYRO_COLS].mean().to_numpy()).max() < np.radians(0.5)
    # forward is forward: in the first drive-off the body y acceleration is positive
    pos = read_rtklib_pos(drive_dir / "gnss_1934_sf.pos")
    speed = np.hypot(pos["vel_e"], pos["vel_n"])
    t_go = pos.index[np.argmax(speed.to_numpy() > 2.0)]
    acc_fwd = imu.loc[t_go - 2.0: t_go, "accel_y"].mean()
    assert acc_fwd > 0.3
    # up is up: heading (clockwise) rate from the GNSS course = -gyro_z (counter-clockwise)
    course = np.unwrap(np.arctan2(pos["vel_e"], pos["vel_n"]).to_numpy())
    moving = speed.to_numpy() > 3.0
    course_rate = np.gradient(course, pos.index.to_numpy())
    wz = np.interp(pos.index.to_numpy(), imu.index.to_numpy(), imu["gyro_z"].to_numpy())
    assert np.corrcoef(course_rate[moving], wz[moving])[0, 1] < -0.98
    # offset option shifts the whole series
    imu2 = read_rtklibexplorer_imu(drive_dir / "imu_1934.csv",
                                   mounting_rpy_deg=DRIVE_0708["mounting_rpy_deg"],
                                   time_offset=DRIVE_0708["time_offset"])
    np.testing.assert_allclose(imu2.index - imu.index, -0.125, atol=1e-6)


def test_real_drive_with_dropped_samples_and_a_logger_gap(drive_dir, tmp_path):
    """Issue 8: 1 % of the samples dropped at random and a 0.5 s gap: read, bridged, reported."""
    lines = (drive_dir / "imu_1934.csv").read_text().splitlines()
    rng = np.random.default_rng(8)
    inner = np.arange(1, len(lines) - 1)
    drop = set(rng.choice(inner, size=len(inner) // 100, replace=False).tolist())
    drop |= set(range(20000, 20050))  # 50 consecutive samples = 0.5 s
    kept = [s for i, s in enumerate(lines) if i not in drop]
    p = tmp_path / "imu_1934.csv"
    p.write_text("\n".join(kept) + "\n")
    (tmp_path / "imu_1934.csv.tag").write_bytes((drive_dir / "imu_1934.csv.tag").read_bytes())
    with pytest.warns(Warning) as rec:
        imu = read_rtklibexplorer_imu(p, mounting_rpy_deg=DRIVE_0708["mounting_rpy_deg"],
                                      rate_hz=DRIVE_0708["rate_hz"])
    assert any("bridged" in str(r.message) for r in rec)
    assert len(imu) == len(lines) - 2 - len(drop)
    gaps = imu.attrs["gaps"]
    assert all(g["action"] == "bridged" for g in gaps)
    longest = max(gaps, key=lambda g: g["duration"])
    assert longest["duration"] == pytest.approx(0.51, abs=0.012) and longest["missing"] >= 49
    assert sum(g["missing"] for g in gaps) == pytest.approx(len(drop), rel=0.02)
