"""Orbits, clocks, corrections and navigation-message primitives of insgnss.gnss (analytic
cases and synthetic constellations; no data files)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from gnss_helpers import synthetic_constellation

from insgnss.gnss.constants import C_LIGHT, F_L1, F_L2, OMEGA_E_WGS84
from insgnss.gnss.corrections import (
    geometry,
    klobuchar_delay,
    niell_mapping,
    saastamoinen_zenith,
    sagnac_rotate,
    tropo_delay,
)
from insgnss.gnss.ephemeris import assign_ephemeris, group_delay, is_healthy, satellite_states
from insgnss.gnss.navmsg import Bits, crc24q, nearest_week_time, sisa_from_index

T0 = 2381 * 604800.0 + 408600.0  # the walk's week


def test_bits_signed_and_split_fields():
    # fields 0b101 (5) at 0, -3 as 4 bits at 3, then a 10-bit value split 3 + 7
    v = (0b101 << 17) | ((-3 & 0xF) << 13) | (0b1011001110 << 3)
    b = Bits(v, 20)
    assert b.u(0, 3) == 5
    assert b.s(3, 4) == -3
    assert b.u(7, 10) == 0b1011001110
    assert b.u2(7, 3, 10, 7) == 0b1011001110
    assert b.s2(7, 3, 10, 7) == 0b1011001110 - 1024


def test_crc24q_check_value():
    # CRC-24Q (poly 0x864CFB, init 0, no reflection): check value of "123456789" is 0xCDE703
    assert crc24q(int.from_bytes(b"123456789", "big"), 72) == 0xCDE703
    # leading zero bits do not change it
    assert crc24q(int.from_bytes(b"123456789", "big"), 76) == 0xCDE703


def test_nearest_week_time_and_bdt():
    assert nearest_week_time(604000.0, 2381 * 604800.0 + 100.0) == 2380 * 604800.0 + 604000.0
    # BDT seconds of week 0 is GPST week start + 14 s
    assert nearest_week_time(0.0, 2381 * 604800.0 + 50.0, -14.0) == 2381 * 604800.0 + 14.0


def test_sisa_index():
    assert sisa_from_index(0) == 0.0
    assert sisa_from_index(50) == pytest.approx(0.5)
    assert sisa_from_index(100) == pytest.approx(2.0)
    assert sisa_from_index(255) == np.inf


def test_orbit_velocity_and_clock_rate_are_derivatives():
    eph = synthetic_constellation(T0)
    # a BeiDou GEO (C01: rotated-frame orbit) and a CNAV-style set (A_dot, delta_n_dot)
    geo = eph.iloc[[0]].assign(sat="C01", system="C", prn=1, source="d1", sqrt_a=6493.4,
                               i0=np.radians(1.0), toe_sow=eph["toe_sow"].iloc[0] - 14.0)
    cnav = eph.iloc[[1]].assign(sat="G30", prn=30, source="cnav", a_dot=0.01,
                                delta_n_dot=1e-14)
    eph = pd.concat([eph, geo, cnav], ignore_index=True)
    rows = np.arange(len(eph))
    t = T0 + 1234.0
    s = satellite_states(eph, rows, t)
    h = 1.0  # central difference: O(h^2 jerk) ~ 1e-5 m/s
    a, b = satellite_states(eph, rows, t + h), satellite_states(eph, rows, t - h)
    assert np.abs((a["pos"] - b["pos"]) / (2 * h) - s["vel"]).max() < 1e-4
    assert np.abs((a["clock"] - b["clock"]) / (2 * h) - s["clock_rate"]).max() < 1e-15
    r = np.linalg.norm(s["pos"], axis=1)
    assert np.all((r[:-2] > 2.55e7) & (r[:-2] < 3.1e7))
    assert 4.1e7 < r[-2] < 4.3e7  # the GEO


def test_keplerian_radius_period_and_relativity():
    eph = synthetic_constellation(T0).iloc[[2]].copy()
    for c in ("cuc", "cus", "crc", "crs", "cic", "cis", "delta_n", "idot", "omega_dot"):
        eph[c] = 0.0
    eph["e"] = 0.05
    eph["m0"] = 0.0
    A = eph["sqrt_a"].iloc[0] ** 2
    mu = 3.986005e14
    n = np.sqrt(mu / A**3)
    ts = T0 + np.linspace(0.0, 2 * np.pi / n, 7)
    s = satellite_states(eph, np.zeros(ts.size, int), ts)
    r = np.linalg.norm(s["pos"], axis=1)
    assert r.min() == pytest.approx(A * 0.95, rel=1e-9)  # perigee at M = E = 0 (t = toe)
    # after one period the inertial position repeats: undo the Earth rotation of the frame
    th = OMEGA_E_WGS84 * (ts[-1] - ts[0])
    p0 = s["pos"][0]
    p1 = s["pos"][-1]
    back = np.array([np.cos(th) * p1[0] - np.sin(th) * p1[1], np.sin(th) * p1[0] + np.cos(th) * p1[1],
                     p1[2]])
    assert np.linalg.norm(back - p0) < 1e-3
    # relativistic clock term F e sqrt(A) sin E equals -2 r.v / c^2 on a Keplerian orbit
    s = satellite_states(eph, np.zeros(5, int), T0 + np.array([600.0, 3000.0, 9000.0, 15000.0,
                                                                 30000.0]))
    rv = np.einsum("ij,ij->i", s["pos"], s["vel"])
    assert np.allclose(s["relativity"], -2.0 * rv / C_LIGHT**2, atol=1e-12, rtol=1e-6)


def test_group_delays_and_health():
    eph = synthetic_constellation(T0)
    g, e = eph[eph.system == "G"], eph[eph.system == "E"]
    assert np.allclose(group_delay("G", g, "1C"), g["tgd"])
    assert np.allclose(group_delay("G", g, "2W"), (F_L1 / F_L2) ** 2 * g["tgd"])
    assert np.all(np.isnan(group_delay("G", g, "5Q")))  # LNAV has no L5 group delay
    assert np.allclose(group_delay("E", e, "1C"), e["tgd2"])  # BGD(E1, E5b) with I/NAV
    assert np.all(group_delay("C", e.assign(system="C"), "6I") == 0.0)
    assert list(is_healthy(["lnav", "cnav", "cnav", "inav", "inav"], [0, 1, 4, 4, 1], "1C")) == \
        [True, True, False, True, False]


def test_assign_ephemeris_nearest_toe_and_causal():
    eph = synthetic_constellation(T0).iloc[[0, 0, 0]].reset_index(drop=True)
    eph.loc[1, ["toe", "time_received"]] = [T0 + 7200.0, T0 + 6000.0]
    eph.loc[2, ["toe", "health"]] = [T0 + 3600.0, 1]  # unhealthy: never chosen
    t = np.array([T0 + 3000.0, T0 + 4000.0, T0 + 4000.0, T0 + 20000.0])
    rows = assign_ephemeris(eph, t, ["G01"] * 4, ["1C", "1C", "1C", "1C"])
    assert list(rows) == [0, 1, 1, -1]
    rows = assign_ephemeris(eph, t[:2], ["G01"] * 2, ["1C"] * 2, causal=True)
    assert list(rows) == [0, 0]


def test_sagnac_rotation_matches_first_order_correction():
    r_rx = np.array([-1.2e6, -4.8e6, 4.1e6])
    sats = np.array([[1.5e7, -1.2e7, 1.8e7], [-1.6e7, -1.9e7, 9e6]])
    rho0 = np.linalg.norm(sats - r_rx, axis=1)
    rho, los, el, az, p, v = geometry(r_rx, sats, np.zeros_like(sats), 0.7, -1.83)
    # textbook first-order correction: (We / c) (x_s y_r - y_s x_r)
    first = OMEGA_E_WGS84 / C_LIGHT * (sats[:, 0] * r_rx[1] - sats[:, 1] * r_rx[0])
    assert np.allclose(rho - rho0, first, atol=2e-3)
    assert np.all(np.abs(first) > 1.0)  # the effect is tens of metres here, not a no-op
    p2, _ = sagnac_rotate(sats, np.zeros_like(sats), np.zeros(2))
    assert np.array_equal(p2, sats)


def test_saastamoinen_and_niell():
    zhd, zwd = saastamoinen_zenith(np.radians(45.0), 0.0)
    # 0.0022768 * 1013.25 hPa (no latitude term at 45 deg, sea level)
    assert zhd == pytest.approx(0.0022768 * 1013.25, rel=1e-9)
    assert 0.05 < zwd < 0.3
    zhd_high, _ = saastamoinen_zenith(np.radians(45.0), 1600.0)
    assert zhd_high == pytest.approx(zhd * (1 - 2.2557e-5 * 1600) ** 5.2568
                                     / (1 - 0.00028 * 1.6), rel=1e-9)
    mh, mw = niell_mapping(np.radians(90.0), np.radians(40.0), 0.0, 200.0)
    assert mh == pytest.approx(1.0, abs=1e-12) and mw == pytest.approx(1.0, abs=1e-12)
    # close to 1/sin(el) high up; below it near the horizon (Earth curvature: -3.5 % at 10 deg)
    for el, tol in ((10.0, 0.05), (30.0, 0.01), (60.0, 0.002)):
        mh, mw = niell_mapping(np.radians(el), np.radians(40.0), 1600.0, 240.0)
        assert -tol < mh * np.sin(np.radians(el)) - 1 < 0.0
        assert -tol < mw * np.sin(np.radians(el)) - 1 < 0.0
    mh5, _ = niell_mapping(np.radians(5.0), np.radians(45.0), 0.0, 28.0)
    assert 9.5 < mh5 < 10.6  # Niell 1996 Fig. 4: about 10 at 5 degrees
    assert tropo_delay(np.radians(90.0), 0.7, 0.0, 1.0) == pytest.approx(sum(
        saastamoinen_zenith(0.7, 0.0)))


def test_klobuchar_night_floor_and_frequency_scaling():
    alpha = (2.142e-8, 2.235e-8, -1.192e-7, -1.192e-7)
    beta = (129024.0, 65536.0, -196608.0, 327680.0)
    lat, lon = np.radians(40.1), np.radians(-105.15)
    # 02:00 local time at the IPP -> the 5 ns night floor times the obliquity factor
    tow_night = np.mod(2 * 3600.0 - 43200.0 * (lon / np.pi), 86400.0)
    d = klobuchar_delay(lat, lon, np.pi / 2, 0.0, tow_night, alpha, beta)
    assert d == pytest.approx(C_LIGHT * 5e-9 * (1 + 16 * 0.03**3), rel=1e-9)
    # 14:00 local: maximum, 5 ns + AMP(phi_m)
    tow_day = np.mod(14 * 3600.0 - 43200.0 * (lon / np.pi), 86400.0)
    dday = klobuchar_delay(lat, lon, np.pi / 2, 0.0, tow_day, alpha, beta)
    psi = 0.0137 / (0.5 + 0.11) - 0.022  # Earth-centred angle at the zenith (azimuth 0)
    phi_m = lat / np.pi + psi + 0.064 * np.cos((lon / np.pi - 1.617) * np.pi)
    amp = sum(alpha[k] * phi_m**k for k in range(4))
    assert dday == pytest.approx(C_LIGHT * (1 + 16 * 0.03**3) * (5e-9 + amp), rel=1e-9)
    assert klobuchar_delay(lat, lon, np.pi / 2, 0.0, tow_day, alpha, beta, F_L2) == \
        pytest.approx(dday * (F_L1 / F_L2) ** 2)
    # low elevation: slant delay about 3x the vertical one
    low = klobuchar_delay(lat, lon, np.radians(10.0), 0.0, tow_day, alpha, beta)
    assert 2.0 < low / dday < 3.5
