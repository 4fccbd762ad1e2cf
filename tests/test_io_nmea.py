"""NMEA reader: GGA epochs with RMC dates/velocity, VTG, GST, quality mapping, bad lines."""

from __future__ import annotations

import numpy as np
import pytest
from io_helpers import gga, gst, rmc, vtg

from insgnss.errors import ConfigError, InputFormatError, InsgnssWarning, TimeOrderError
from insgnss.io import read_nmea
from insgnss.io.gpstime import gps_seconds_from_datetime64

LAT, LON = 40.0966268, -105.1474483


def write(tmp_path, lines):
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(lines) + "\n")
    return p


def gps(iso):
    return float(gps_seconds_from_datetime64(np.array([iso], "datetime64[ns]"))[0])


def test_gga_rmc_vtg_gst_known_values(tmp_path):
    tod0 = 19 * 3600 + 34 * 60 + 0.5
    lines = []
    for k in range(4):
        tod = tod0 + 0.25 * k
        lines += [rmc(tod, "080725", LAT + 1e-5 * k, LON, 10.0, 30.0),
                  gga(tod, LAT + 1e-5 * k, LON, 1620.0 + k, sep=-18.5, quality=4 if k < 3 else 5),
                  gst(tod, 0.011, 0.012, 0.02), "$GNGSA,A,3,05,07,,,,,,,,,,,1.5,0.8,1.2*21"]
    df = read_nmea(write(tmp_path, lines))
    # UTC 19:34:00.5 on 2025-07-08 is GPST 19:34:18.5
    np.testing.assert_allclose(df.index.to_numpy(), gps("2025-07-08T19:34:18.5") + 0.25 * np.arange(4),
                               atol=1e-6)
    np.testing.assert_allclose(np.degrees(df["lat"]), LAT + 1e-5 * np.arange(4), atol=1e-9)
    np.testing.assert_allclose(np.degrees(df["lon"]), LON, atol=1e-9)
    np.testing.assert_allclose(df["height"], 1620.0 - 18.5 + np.arange(4), atol=1e-9)
    assert df.attrs["height_reference"] == "ellipsoid"
    assert df["q"].tolist() == [1, 1, 1, 2] and df["fix_quality"].tolist() == [4, 4, 4, 5]
    v = 10.0 * 1852.0 / 3600.0
    np.testing.assert_allclose(df[["vel_e", "vel_n"]].iloc[0],
                               [v * np.sin(np.radians(30.0)), v * np.cos(np.radians(30.0))], atol=1e-9)
    np.testing.assert_allclose(df[["north_std", "east_std", "up_std"]].iloc[2], [0.011, 0.012, 0.02])
    assert (df["ns"] == 12).all() and df["hdop"].iloc[0] == pytest.approx(0.8)
    assert df.attrs["source_rows"].tolist() == [2, 6, 10, 14]
    assert df.attrs["skipped_lines"] == [] and df.attrs["time_base"] == "gps"


def test_vtg_velocity_and_midnight_rollover(tmp_path):
    lines = [gga(86399.5, LAT, LON, 100.0), vtg(90.0, 36.0), rmc(86399.5, "311216", LAT, LON, 19.438, 90.0),
             gga(0.5, LAT, LON, 100.0), vtg(180.0, 36.0)]
    df = read_nmea(write(tmp_path, lines))
    # 2016-12-31 23:59:59.5 UTC (GPS-UTC = 17 s) and 2017-01-01 00:00:00.5 UTC (18 s)
    np.testing.assert_allclose(df.index.to_numpy(),
                               [gps("2017-01-01T00:00:16.5"), gps("2017-01-01T00:00:18.5")], atol=1e-6)
    np.testing.assert_allclose(df[["vel_e", "vel_n"]].to_numpy(), [[10.0, 0.0], [0.0, -10.0]], atol=1e-3)
    assert df["vel_e"].iloc[0] == pytest.approx(19.438 * 1852 / 3600, abs=1e-6)  # RMC beats VTG


def test_no_date_uses_argument_or_seconds_of_day(tmp_path):
    p = write(tmp_path, [gga(3600.0, LAT, LON, 10.0, sep=None), gga(3601.0, LAT, LON, 10.0, sep=None)])
    df = read_nmea(p)
    assert df.attrs["time_base"] == "utc_sod" and df.index.tolist() == [3600.0, 3601.0]
    assert df.attrs["height_reference"] == "msl"
    df = read_nmea(p, date="2025-07-08")
    assert df.index[0] == pytest.approx(gps("2025-07-08T01:00:18"), abs=1e-6)
    with pytest.raises(ConfigError):
        read_nmea(p, date="8 July")


def test_no_fix_and_bad_lines(tmp_path):
    good = gga(10.0, LAT, LON, 10.0)
    corrupt = good[:-2] + ("00" if good[-2:] != "00" else "11")  # wrong checksum
    lines = [good, corrupt, "garbage \x7f", gga(11.0, LAT, LON, 10.0, quality=0),
             gga(12.0, LAT, LON, 10.0, quality=1)]
    p = write(tmp_path, lines)
    with pytest.warns(InsgnssWarning) as w:
        df = read_nmea(p)
    assert len(w) == 2
    assert [r["row"] for r in df.attrs["skipped_lines"]] == [2, 3]
    assert df.attrs["dropped_no_fix"] == [{"row": 4, "quality": 0}]
    assert df["q"].tolist() == [1, 5]
    with pytest.raises(InputFormatError) as e:
        read_nmea(p, bad_lines="error")
    assert e.value.row == 2
    with pytest.raises(InputFormatError, match="no GGA"):
        read_nmea(write(tmp_path, [vtg(0.0, 1.0)]))


def test_time_order(tmp_path):
    p = write(tmp_path, [gga(10.0, LAT, LON, 1.0), gga(12.0, LAT, LON, 1.0), gga(11.0, LAT, LON, 1.0)])
    with pytest.raises(TimeOrderError) as e:
        read_nmea(p)
    assert e.value.row == 3
    p = write(tmp_path, [gga(10.0, LAT, LON, 1.0), gga(10.0, LAT, LON, 1.0), gga(11.0, LAT, LON, 1.0)])
    with pytest.warns(InsgnssWarning, match="duplicated"):
        df = read_nmea(p)
    assert len(df) == 2 and df.attrs["dropped_duplicates"][0]["row"] == 2
