"""KF-GINS text formats: IMU increments (FRD), GNSS with NED std, .nav reader and writer."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from io_helpers import G0, kfgins_imu_text

from insgnss.attitude import P_SWAP
from insgnss.errors import ConfigError, InputFormatError, InvalidValueError
from insgnss.imu import DTHETA_COLS, DV_COLS
from insgnss.io import (
    read_kfgins_gnss,
    read_kfgins_imu,
    read_kfgins_nav,
    read_reference,
    write_kfgins_nav,
)

WEEK = 2174


def test_imu_frd_to_rfu(tmp_path):
    n = 100
    t = 357000.0 + 0.005 * np.arange(1, n + 1)
    rng = np.random.default_rng(2)
    dth_frd = rng.normal(0, 1e-5, (n, 3)) + [1e-4, -2e-4, 3e-4]
    dv_frd = np.tile([0.001, -0.002, -G0 * 0.005], (n, 1))  # FRD: specific force up is -z
    p = tmp_path / "imu.txt"
    p.write_text(kfgins_imu_text(t, dth_frd, dv_frd))
    df = read_kfgins_imu(p, rate_hz=200.0)
    assert list(df.columns) == DTHETA_COLS + DV_COLS
    np.testing.assert_allclose(df[DTHETA_COLS].to_numpy(), dth_frd @ P_SWAP.T, atol=1e-15)
    np.testing.assert_allclose(df[DV_COLS].to_numpy()[0], [-0.002, 0.001, G0 * 0.005], atol=1e-15)
    assert df.attrs["time_base"] == "sow"
    np.testing.assert_allclose(df.index.to_numpy(), t)
    df = read_kfgins_imu(p, week=WEEK)
    assert df.attrs["time_base"] == "gps" and df.attrs["gps_week"] == WEEK
    np.testing.assert_allclose(df.index.to_numpy(), t + WEEK * 604800.0)
    # comma separated works too
    p.write_text(kfgins_imu_text(t, dth_frd, dv_frd).replace(" ", ","))
    assert len(read_kfgins_imu(p)) == n
    with pytest.raises(ConfigError):
        read_kfgins_imu(p, week=-1)


def test_gnss_7_and_13_columns(tmp_path):
    t = 357000.0 + np.arange(5.0)
    lat, lon, h = 30.4447873, 114.4718, 20.9
    rows7 = [f"{s:.3f} {lat + 1e-6 * i:.9f} {lon:.9f} {h:.3f} 0.005 0.004 0.008"
             for i, s in enumerate(t)]
    p = tmp_path / "gnss.txt"
    p.write_text("\n".join(rows7) + "\n")
    df = read_kfgins_gnss(p)
    np.testing.assert_allclose(np.degrees(df["lat"]), lat + 1e-6 * np.arange(5), atol=1e-12)
    np.testing.assert_allclose(df[["east_std", "north_std", "up_std"]].iloc[0], [0.004, 0.005, 0.008])
    assert "vel_e" not in df.columns
    rows13 = [r + " 1.0 2.0 -0.5 0.01 0.02 0.03" for r in rows7]
    p.write_text("\n".join(rows13) + "\n")
    df = read_kfgins_gnss(p, week=WEEK)
    np.testing.assert_allclose(df[["vel_e", "vel_n", "vel_u"]].iloc[0], [2.0, 1.0, 0.5])
    np.testing.assert_allclose(df[["vel_e_std", "vel_n_std", "vel_u_std"]].iloc[0], [0.02, 0.01, 0.03])
    np.testing.assert_allclose(df.index, t + WEEK * 604800.0)
    p.write_text("\n".join(rows7[:2] + [rows7[2] + " 9"] + rows7[3:]) + "\n")
    with pytest.raises(InputFormatError) as e:
        read_kfgins_gnss(p)
    assert (e.value.row, e.value.found) == (3, "8 fields")
    p.write_text("\n".join(rows7[:3] + [rows7[3].replace(" 0.004 ", " -0.004 ")] + rows7[4:]))
    with pytest.raises(InvalidValueError) as e:
        read_kfgins_gnss(p)
    assert (e.value.row, e.value.column) == (4, "std_e")


def nav_table(n=20, week=WEEK):
    t = week * 604800.0 + 357000.0 + 0.1 * np.arange(n)
    rng = np.random.default_rng(7)
    df = pd.DataFrame({
        "lat": np.radians(30.44 + 1e-6 * np.arange(n)), "lon": np.radians(114.47 + 2e-6 * np.arange(n)),
        "height": 20.0 + 0.01 * np.arange(n),
        "vel_e": rng.normal(0, 3, n), "vel_n": rng.normal(0, 3, n), "vel_u": rng.normal(0, 0.1, n),
        "roll": np.radians(rng.uniform(-10, 10, n)), "pitch": np.radians(rng.uniform(-10, 10, n)),
        "heading": np.radians(rng.uniform(0, 360, n)),
    }, index=pd.Index(t, name="time"))
    df.attrs["time_base"] = "gps"
    return df


def test_nav_round_trip(tmp_path):
    df = nav_table()
    p = write_kfgins_nav(df, tmp_path / "out.nav")
    text = p.read_text().splitlines()
    f = text[0].split()
    assert len(f) == 11 and f[0] == str(WEEK) and float(f[1]) == pytest.approx(357000.0)
    # NED velocity and yaw in (-180, 180]
    assert float(f[5]) == pytest.approx(df["vel_n"].iloc[0], abs=1e-5)
    assert float(f[7]) == pytest.approx(-df["vel_u"].iloc[0], abs=1e-5)
    back = read_kfgins_nav(p)
    assert back.attrs["time_base"] == "gps" and back.attrs["gps_week"] == WEEK
    np.testing.assert_allclose(back.index, df.index, atol=1e-6)
    for c in ("lat", "lon"):
        np.testing.assert_allclose(back[c], df[c], atol=np.radians(1e-10))
    for c in ("height", "vel_e", "vel_n", "vel_u"):
        np.testing.assert_allclose(back[c], df[c], atol=1e-5)
    for c in ("roll", "pitch", "heading"):
        np.testing.assert_allclose(back[c], df[c], atol=np.radians(1e-8))
    ref = read_reference(p)
    np.testing.assert_allclose(ref["heading"], df["heading"], atol=np.radians(1e-8))


def test_nav_seconds_of_week_and_week_zero(tmp_path):
    df = nav_table(5)
    sow = df.copy()
    sow.index = df.index - WEEK * 604800.0
    sow.attrs = {"time_base": "sow"}
    p = write_kfgins_nav(sow, tmp_path / "sow.nav")
    assert p.read_text().split()[0] == "0"
    back = read_kfgins_nav(p)
    assert back.attrs["time_base"] == "sow"
    np.testing.assert_allclose(back.index, sow.index, atol=1e-6)
    back = read_kfgins_nav(p, week=WEEK)
    np.testing.assert_allclose(back.index, df.index, atol=1e-6)


def test_nav_writer_refuses_inputs_and_missing_columns(tmp_path):
    df = nav_table(3)
    src = tmp_path / "truth.nav"
    write_kfgins_nav(df, src)
    before = src.read_bytes()
    with pytest.raises(ConfigError, match="overwrite an input"):
        write_kfgins_nav(df, src, protect=[src])
    assert src.read_bytes() == before
    with pytest.raises(InputFormatError) as e:
        write_kfgins_nav(df.drop(columns="pitch"), tmp_path / "x.nav")
    assert e.value.column == "pitch"
    bad = src.read_text().replace(src.read_text().split()[9], "95.0", 1)
    src.write_text(bad)
    with pytest.raises(InvalidValueError) as e:
        read_kfgins_nav(src)
    assert (e.value.row, e.value.column) == (1, "pitch")
