"""Satellite position, velocity and clock from broadcast Keplerian ephemerides.

Orbit (IS-GPS-200N Table 20-IV; CNAV extensions Table 30-II; Galileo OS SIS ICD 5.1.1;
BDS-SIS-ICD 5.2.4.12), vectorised over rows::

    A   = sqrt_a^2 + a_dot tk                     (a_dot = 0 for LNAV/I/NAV/D1)
    n   = sqrt(mu / sqrt_a^6) + delta_n + delta_n_dot tk / 2
    M   = m0 + n tk,  E - e sin E = M              (Newton iterations)
    nu  = atan2(sqrt(1 - e^2) sin E, cos E - e),  Phi = nu + omega
    u   = Phi + cus sin 2Phi + cuc cos 2Phi
    r   = A (1 - e cos E) + crs sin 2Phi + crc cos 2Phi
    i   = i0 + idot tk + cis sin 2Phi + cic cos 2Phi
    Om  = omega0 + (omega_dot - We) tk - We toe_sow
    x_ecef = R3(-Om) R1(-i) [r cos u, r sin u, 0]

with ``tk = t - toe`` and the system's mu and We (:mod:`.constants`). BeiDou GEO satellites
use ``Om = omega0 + omega_dot tk - We toe_sow`` in an inertial frame rotated into ECEF by
``Rz(We tk) Rx(-5 deg)``. Velocities are the analytic time derivatives of the same
expressions (tested against finite differences).

Clock (IS-GPS-200 20.3.3.3.3.1-2)::

    dt_sv(t) = af0 + af1 (t - toc) + af2 (t - toc)^2 + F e sqrt_a sin E - T_s

with the relativistic term ``F e sqrt(A) sin E`` (``F = -2 sqrt(mu) / c^2``) and the group
delay ``T_s`` of the signal tracked (:func:`group_delay`): GPS ``TGD`` (L1 C/A, LNAV; CNAV adds
``- ISC_L1CA``), ``gamma TGD`` for L2 P(Y), Galileo ``BGD(E1,E5b)`` for E1 with the I/NAV clock,
BeiDou ``TGD1`` for B1I and none for B3I (the reference signal of the BDS clock).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .constants import BDS_GEO_PRNS, F_E5B, F_L1, F_L2, F_REL, MAX_EPHEMERIS_AGE, MU, OMEGA_E

_KEPLER_COLS = ("toe", "toc", "toe_sow", "sqrt_a", "e", "i0", "omega0", "omega", "m0",
                "delta_n", "omega_dot", "idot", "cuc", "cus", "crc", "crs", "cic", "cis",
                "a_dot", "delta_n_dot", "af0", "af1", "af2")


def is_healthy(source, health, signal: str) -> np.ndarray:
    """Whether each ephemeris row is healthy for ``signal`` (RINEX code, e.g. ``"1C"``).

    LNAV, BeiDou D1 and RINEX: health word 0. CNAV: the L1/L2/L5 bit of the band. Galileo
    I/NAV: signal health status and data validity of E1-B (bits 0-1) for E1, of E5b (bits
    2-3) for E5b; the I/NAV clock is not used for E5a.
    """
    source = np.asarray(source, object)
    h = np.asarray(health, float)
    band = signal[:1]
    ok = h == 0
    cnav_bit = {"1": 4, "2": 2, "5": 1}.get(band, 7)
    ok = np.where(source == "cnav", (h.astype(int) & cnav_bit) == 0, ok)
    gal = (h.astype(int) & 3) == 0 if band == "1" else ((h.astype(int) >> 2) & 3) == 0 \
        if band == "7" else np.zeros(h.shape, bool)
    return np.where(source == "inav", gal, ok)


def group_delay(system: str, eph: pd.DataFrame | dict, signal: str) -> np.ndarray:
    """Group delay ``T_s`` [s] subtracted from the broadcast clock for ``signal``; NaN where
    the broadcast data do not define it (the satellite is then not used on that signal)."""
    tgd = np.asarray(eph["tgd"], float)
    band = signal[:1]
    if system in ("G", "J"):
        src = np.asarray(eph["source"], object)
        isc1 = np.asarray(eph["isc_1C"], float)
        if band == "1":
            # LNAV clock is L1 P(Y)-referenced: L1 C/A uses TGD (ISC_L1CA = 0 by definition
            # in LNAV); CNAV: dt_L1CA = dt - TGD + ISC_L1CA (IS-GPS-200 30.3.3.3.1.1.1)
            return np.where(src == "cnav", tgd - np.nan_to_num(isc1, nan=0.0), tgd)
        if band == "2":
            isc2 = np.asarray(eph["isc_2L"], float)
            return np.where(src == "cnav", tgd - isc2, (F_L1 / F_L2) ** 2 * tgd)
        if band == "5":
            isc5 = np.asarray(eph["isc_5Q" if signal[1:] in ("Q", "X") else "isc_5I"], float)
            return np.where(src == "cnav", tgd - isc5, np.nan)
    if system == "E":
        bgd_b = np.asarray(eph["tgd2"], float)
        if band == "1":
            return bgd_b
        if band == "7":
            return (F_L1 / F_E5B) ** 2 * bgd_b
        return np.full(tgd.shape, np.nan)
    if system == "C":
        if band == "6":
            return np.zeros(tgd.shape)
        if band == "2":
            return tgd
        if band == "7":
            return np.asarray(eph["tgd2"], float)
        return np.full(tgd.shape, np.nan)
    return np.full(tgd.shape, np.nan)


def assign_ephemeris(eph: pd.DataFrame, times, sats, signals, causal: bool = False) -> np.ndarray:
    """Row of ``eph`` to use for each observation (``-1``: none usable).

    For each (time, satellite, signal) the healthy data set with the smallest ``|t - toe|``
    within the system's :data:`~.constants.MAX_EPHEMERIS_AGE`; with ``causal=True`` only
    data sets received before ``t`` qualify (what a real-time receiver would have). The
    default (post-processing) also uses data sets received later, as a RINEX navigation
    file would.
    """
    times = np.asarray(times, float)
    sats = np.asarray(sats, object)
    signals = np.asarray(signals, object)
    out = np.full(times.size, -1, np.int64)
    if eph.empty or times.size == 0:
        return out
    toe = eph["toe"].to_numpy(float)
    t_rx = eph["time_received"].to_numpy(float)
    esat = eph["sat"].to_numpy(object)
    esys = eph["system"].to_numpy(object)
    for key in pd.unique(pd.Series(list(zip(sats, signals, strict=True)))):
        sat, sig = key
        rows = np.nonzero(esat == sat)[0]
        if rows.size == 0:
            continue
        sel = np.nonzero((sats == sat) & (signals == sig))[0]
        healthy = is_healthy(eph["source"].to_numpy(object)[rows], eph["health"].to_numpy()[rows],
                             sig)
        gd_ok = np.isfinite(group_delay(esys[rows[0]], eph.iloc[rows], sig))
        rows = rows[healthy & gd_ok]
        if rows.size == 0:
            continue
        dt = np.abs(times[sel, None] - toe[None, rows])
        bad = dt > MAX_EPHEMERIS_AGE.get(esys[rows[0]], 7200.0)
        if causal:
            bad |= t_rx[None, rows] > times[sel, None]
        dt = np.where(bad, np.inf, dt)
        j = np.argmin(dt, axis=1)
        ok = np.isfinite(dt[np.arange(sel.size), j])
        out[sel[ok]] = rows[j[ok]]
    return out


def _columns(eph: pd.DataFrame, rows: np.ndarray) -> dict:
    sub = eph.iloc[rows]
    d = {c: sub[c].to_numpy(float) for c in _KEPLER_COLS}
    d["system"] = sub["system"].to_numpy(object)
    d["prn"] = sub["prn"].to_numpy(int)
    return d


def satellite_states(eph: pd.DataFrame, rows, t) -> dict:
    """Position, velocity and clock of the satellites of ephemeris ``rows`` at GPST times ``t``.

    Returns
    -------
    dict of arrays
        ``pos`` (N, 3) and ``vel`` (N, 3) ECEF [m, m/s] (frame of the time ``t``), ``clock``
        [s] (polynomial + relativistic term, without group delay), ``clock_rate`` [s/s],
        ``relativity`` [s].
    """
    rows = np.asarray(rows, np.int64)
    t = np.broadcast_to(np.asarray(t, float), rows.shape)
    d = _columns(eph, rows)
    n = rows.size
    mu = np.array([MU.get(s, MU["G"]) for s in d["system"]])
    we = np.array([OMEGA_E.get(s, OMEGA_E["G"]) for s in d["system"]])
    frel = np.array([F_REL.get(s, F_REL["G"]) for s in d["system"]])
    geo = np.array([s == "C" and p in BDS_GEO_PRNS for s, p in zip(d["system"], d["prn"],
                                                                   strict=True)], bool)
    tk = t - d["toe"]
    e = d["e"]
    a0 = d["sqrt_a"] ** 2
    A = a0 + d["a_dot"] * tk
    n0 = np.sqrt(mu / a0**3)
    nn = n0 + d["delta_n"] + 0.5 * d["delta_n_dot"] * tk
    M = d["m0"] + nn * tk
    E = M.copy()
    for _ in range(10):  # Newton on E - e sin E - M
        E = E - (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
    sE, cE = np.sin(E), np.cos(E)
    den = 1.0 - e * cE
    nu = np.arctan2(np.sqrt(1.0 - e * e) * sE, cE - e)
    phi = nu + d["omega"]
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    u = phi + d["cus"] * s2 + d["cuc"] * c2
    r = A * den + d["crs"] * s2 + d["crc"] * c2
    inc = d["i0"] + d["idot"] * tk + d["cis"] * s2 + d["cic"] * c2
    # time derivatives
    E_dot = (n0 + d["delta_n"] + d["delta_n_dot"] * tk) / den  # dM/dt
    nu_dot = E_dot * np.sqrt(1.0 - e * e) / den
    u_dot = nu_dot * (1.0 + 2.0 * (d["cus"] * c2 - d["cuc"] * s2))
    r_dot = A * e * sE * E_dot + d["a_dot"] * den + 2.0 * (d["crs"] * c2 - d["crc"] * s2) * nu_dot
    i_dot = d["idot"] + 2.0 * (d["cis"] * c2 - d["cic"] * s2) * nu_dot
    xo, yo = r * np.cos(u), r * np.sin(u)
    xo_dot = r_dot * np.cos(u) - yo * u_dot
    yo_dot = r_dot * np.sin(u) + xo * u_dot
    om_rate = np.where(geo, d["omega_dot"], d["omega_dot"] - we)
    Om = d["omega0"] + om_rate * tk - we * d["toe_sow"]
    sO, cO, si, ci = np.sin(Om), np.cos(Om), np.sin(inc), np.cos(inc)
    X = xo * cO - yo * ci * sO
    Y = xo * sO + yo * ci * cO
    Z = yo * si
    Xd = xo_dot * cO - yo_dot * ci * sO + yo * si * sO * i_dot - Y * om_rate
    Yd = xo_dot * sO + yo_dot * ci * cO - yo * si * cO * i_dot + X * om_rate
    Zd = yo_dot * si + yo * ci * i_dot
    pos = np.column_stack([X, Y, Z])
    vel = np.column_stack([Xd, Yd, Zd])
    if np.any(geo):
        pos[geo], vel[geo] = _bds_geo_rotation(pos[geo], vel[geo], we[geo] * tk[geo], we[geo])
    dtc = t - d["toc"]
    rel = frel * e * d["sqrt_a"] * sE
    rel_rate = frel * e * d["sqrt_a"] * cE * E_dot
    clock = d["af0"] + d["af1"] * dtc + d["af2"] * dtc**2 + rel
    clock_rate = d["af1"] + 2.0 * d["af2"] * dtc + rel_rate
    if n == 0:
        pos = vel = np.zeros((0, 3))
    return {"pos": pos, "vel": vel, "clock": clock, "clock_rate": clock_rate, "relativity": rel}


def _bds_geo_rotation(p, v, ang, we):
    """BeiDou GEO: ``x_ecef = Rz(We tk) Rx(-5 deg) x_gk`` and its derivative."""
    c5, s5 = np.cos(np.radians(-5.0)), np.sin(np.radians(-5.0))
    # Rx(-5 deg) as in BDS-SIS-ICD (rotation of the coordinate frame)
    px, py, pz = p[:, 0], c5 * p[:, 1] + s5 * p[:, 2], -s5 * p[:, 1] + c5 * p[:, 2]
    vx, vy, vz = v[:, 0], c5 * v[:, 1] + s5 * v[:, 2], -s5 * v[:, 1] + c5 * v[:, 2]
    ca, sa = np.cos(ang), np.sin(ang)
    X = ca * px + sa * py
    Y = -sa * px + ca * py
    Xd = ca * vx + sa * vy + we * (-sa * px + ca * py)
    Yd = -sa * vx + ca * vy + we * (-ca * px - sa * py)
    return np.column_stack([X, Y, pz]), np.column_stack([Xd, Yd, vz])
