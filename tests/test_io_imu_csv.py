"""Generic IMU CSV reader: units, time scale, column mapping, mounting conventions."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from io_helpers import G0, IMU_HEADER, imu_csv_text, imu_rows

from insgnss.attitude import P_SWAP, Rx, Ry, Rz, euler_to_dcm
from insgnss.errors import ConfigError, InputFormatError, InsgnssWarning
from insgnss.imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS
from insgnss.io import axis_map_matrix, mounting_matrix, read_imu_csv


def write(tmp_path, text, name="imu.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_si_round_trip(tmp_path):
    t, w, f = imu_rows(60)
    p = write(tmp_path, imu_csv_text(t, w, f, fmt="%.17g"))
    df = read_imu_csv(p, rate_hz=100.0, time_base="relative")
    assert list(df.columns) == GYRO_COLS + ACCEL_COLS
    np.testing.assert_array_equal(df.index.to_numpy(), t)
    np.testing.assert_array_equal(df[GYRO_COLS].to_numpy(), w)
    np.testing.assert_array_equal(df[ACCEL_COLS].to_numpy(), f)
    assert df.attrs["source"] == str(p) and df.attrs["time_base"] == "relative"
    assert df.attrs["source_rows"].tolist() == list(range(2, 62))
    assert df.attrs["gaps"] == [] and df.attrs["dropped_duplicates"] == []
    assert df.attrs["nominal_dt"] == pytest.approx(0.01)


def test_declared_units_time_scale_offset_and_mapping(tmp_path):
    t, w, f = imu_rows(80)
    raw = pd.DataFrame({"stamp_us": np.round((t - 100.0) * 1e6).astype(np.int64),
                        "temp": 25.0,
                        "AX": f[:, 0] / G0, "AY": f[:, 1] / G0, "AZ": f[:, 2] / G0,
                        "GX": np.degrees(w[:, 0]), "GY": np.degrees(w[:, 1]),
                        "GZ": np.degrees(w[:, 2])})
    p = tmp_path / "imu.csv"
    raw.to_csv(p, index=False, float_format="%.15g", sep=";")
    cols = {"time": "stamp_us", "gyro_x": "GX", "gyro_y": "GY", "gyro_z": "GZ",
            "accel_x": "AX", "accel_y": "AY", "accel_z": "AZ"}
    df = read_imu_csv(p, columns=cols, delimiter=";", gyro_unit="deg/s", accel_unit="g",
                      time_unit="us", time_offset=100.0 - 0.125)
    np.testing.assert_allclose(df.index.to_numpy(), t - 0.125, atol=1e-9)
    np.testing.assert_allclose(df[GYRO_COLS].to_numpy(), w, atol=1e-14)
    np.testing.assert_allclose(df[ACCEL_COLS].to_numpy(), f, atol=1e-13)


def test_index_mapping_without_header(tmp_path):
    t, w, f = imu_rows(30)
    text = "\n".join(" ".join(f"{x:.12f}" for x in (*a, *g, tt)) for tt, g, a in zip(t, w, f, strict=True))
    p = write(tmp_path, text + "\n")
    cols = {"time": 6, "gyro_x": 3, "gyro_y": 4, "gyro_z": 5, "accel_x": 0, "accel_y": 1, "accel_z": 2}
    df = read_imu_csv(p, columns=cols, header=False, delimiter=None)
    np.testing.assert_allclose(df[GYRO_COLS].to_numpy(), w, atol=1e-12)
    np.testing.assert_allclose(df[ACCEL_COLS].to_numpy(), f, atol=1e-12)


def test_increments_in_deg_and_m_s(tmp_path):
    t, w, f = imu_rows(50)
    dth, dv = w * 0.01, f * 0.01
    header = "time,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z"
    p = write(tmp_path, imu_csv_text(t, np.degrees(dth), dv, header=header, fmt="%.17g"))
    df = read_imu_csv(p, gyro_unit="deg", accel_unit="m/s")
    assert list(df.columns) == DTHETA_COLS + DV_COLS
    np.testing.assert_allclose(df[DTHETA_COLS].to_numpy(), dth, atol=1e-16)
    np.testing.assert_allclose(df[DV_COLS].to_numpy(), dv, atol=1e-16)
    with pytest.raises(ConfigError, match="both be rates or both increments"):
        read_imu_csv(p, gyro_unit="deg", accel_unit="m/s^2")


def test_axis_map_frd_to_rfu(tmp_path):
    """An FRD sensor at rest reads f = (0, 0, -g); body RFU must read (0, 0, +g)."""
    t, w, f = imu_rows(40)
    frd_w, frd_f = w @ P_SWAP.T, f @ P_SWAP.T
    p = write(tmp_path, imu_csv_text(t, frd_w, frd_f, fmt="%.17g"))
    for kw in (dict(axis_map="y,x,-z"), dict(sensor_axes="frd")):
        df = read_imu_csv(p, **kw)
        np.testing.assert_allclose(df[ACCEL_COLS].to_numpy(), f, atol=1e-12)
        np.testing.assert_allclose(df[GYRO_COLS].to_numpy(), w, atol=1e-15)
        assert df["accel_z"].mean() == pytest.approx(G0, abs=0.02)


def test_axis_map_matrix():
    np.testing.assert_array_equal(axis_map_matrix("y,x,-z"), P_SWAP)
    np.testing.assert_array_equal(axis_map_matrix("x, y, z"), np.eye(3))
    A = axis_map_matrix("-y,x,z")
    np.testing.assert_array_equal(A @ [1.0, 2.0, 3.0], [-2.0, 1.0, 3.0])
    for bad in ("y,x,z", "x,x,z", "x,y", "x,y,w", "x,y,--z", 3):
        with pytest.raises(ConfigError):
            axis_map_matrix(bad)


def test_mounting_active_is_the_sensor_attitude_in_body():
    r, p, y = np.radians([3.0, -4.0, 30.0])
    M = mounting_matrix(euler_deg=np.degrees([r, p, y]))
    np.testing.assert_allclose(M, euler_to_dcm(r, p, y), atol=1e-15)
    # a sensor yawed 90 deg clockwise (its forward axis points to body right)
    M = mounting_matrix(euler_deg=(0, 0, 90))
    np.testing.assert_allclose(M @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], atol=1e-15)


def test_mounting_frd_active_matches_ned_zyx_dcm():
    """FRD triads with yaw-pitch-roll: v_frd_b = Rz(y) Ry(p) Rx(r) v_frd_s (KF-GINS)."""
    rng = np.random.default_rng(3)
    for r, p, y in rng.uniform(-1.2, 1.2, (5, 3)):
        M = mounting_matrix(euler_deg=np.degrees([r, p, y]), sensor_axes="frd")
        C_zyx = Rz(y) @ Ry(p) @ Rx(r)
        np.testing.assert_allclose(M, P_SWAP @ C_zyx, atol=1e-14)


def groves_euler_to_ctm(eul):
    """Groves' Euler_to_CTM, written out (the rtklibexplorer convention)."""
    sphi, cphi = np.sin(eul[0]), np.cos(eul[0])
    sth, cth = np.sin(eul[1]), np.cos(eul[1])
    sps, cps = np.sin(eul[2]), np.cos(eul[2])
    return np.array([
        [cth * cps, cth * sps, -sth],
        [-cphi * sps + sphi * sth * cps, cphi * cps + sphi * sth * sps, sphi * cth],
        [sphi * sps + cphi * sth * cps, -sphi * cps + cphi * sth * sps, cphi * cth]])


def test_mounting_passive_frd_matches_groves():
    rng = np.random.default_rng(4)
    for e in [np.radians([180.0, -6.79, 185.35])] + list(rng.uniform(-3, 3, (5, 3))):
        M = mounting_matrix(euler_deg=np.degrees(e), sensor_axes="frd", euler_convention="passive")
        np.testing.assert_allclose(M, P_SWAP @ groves_euler_to_ctm(e), atol=1e-14)


def test_mounting_rejects_bad_arguments():
    for kw in (dict(euler_deg=(1, 2)), dict(euler_deg=("a", 1, 2)), dict(euler_deg=(np.nan, 0, 0)),
               dict(sensor_axes="ned"), dict(euler_deg=(0, 0, 0), euler_convention="zyx")):
        with pytest.raises(ConfigError):
            mounting_matrix(**kw)


@pytest.mark.parametrize("kw, key", [
    (dict(gyro_unit="rpm"), "gyro_unit"), (dict(accel_unit="gal"), "accel_unit"),
    (dict(time_unit="min"), "time_unit"), (dict(time_offset="x"), "time_offset"),
    (dict(columns={"tim": "time"}), "columns.tim"),
    (dict(columns={"time": 1.5, "gyro_x": 1, "gyro_y": 2, "gyro_z": 3, "accel_x": 4, "accel_y": 5,
                   "accel_z": 6}), "columns.time"),
])
def test_bad_declarations_name_the_key(tmp_path, kw, key):
    t, w, f = imu_rows(20)
    p = write(tmp_path, imu_csv_text(t, w, f))
    with pytest.raises(ConfigError) as e:
        read_imu_csv(p, **kw)
    assert e.value.column == key


def test_extra_columns_are_ignored_and_missing_named(tmp_path):
    t, w, f = imu_rows(20)
    text = imu_csv_text(t, w, f).replace(IMU_HEADER, "time,gyro_x,gyro_y,gyro_z,accel_x,accel_y,acc_z")
    p = write(tmp_path, text)
    with pytest.raises(InputFormatError) as e:
        read_imu_csv(p)
    assert (e.value.row, e.value.column) == (1, "accel_z")
    lines = imu_csv_text(t, w, f).splitlines()
    lines = [lines[0] + ",status"] + [s + ",ok" for s in lines[1:]]
    df = read_imu_csv(write(tmp_path, "\n".join(lines)))
    assert len(df) == 20


def test_duplicates_dropped_with_warning(tmp_path):
    t, w, f = imu_rows(30)
    t[10] = t[9]
    p = write(tmp_path, imu_csv_text(t, w, f, fmt="%.17g"))
    with pytest.warns(InsgnssWarning) as rec:
        df = read_imu_csv(p)
    # the repeated stamp replaced a sample: one duplicate dropped, one 2-interval gap bridged
    assert ["duplicated" in str(r.message) for r in rec] == [True, False]
    assert df.attrs["gaps"][0]["row"] == 13 and df.attrs["gaps"][0]["action"] == "bridged"
    assert len(df) == 29 and df.attrs["dropped_duplicates"] == [{"row": 12, "time": t[9]}]
    np.testing.assert_array_equal(df.attrs["source_rows"][9:11], [11, 13])
