"""Test helpers for the raw GNSS code: minimal RINEX 3.04 writers (navigation records of GPS
LNAV, Galileo I/NAV and BeiDou D1 ephemerides; observations of chosen signals) to test the
RINEX readers against the UBX decoders, and synthetic Keplerian constellations."""

from __future__ import annotations

import numpy as np
import pandas as pd

from insgnss.gnss.constants import BDT_MINUS_GPST
from insgnss.gnss.navmsg import EPH_COLUMNS
from insgnss.gnss.observations import GnssModelConfig, iono_variance, pseudorange_variance, tropo_variance
from insgnss.io.gpstime import datetime64_from_gps_seconds

#: a time in the walk's GPS week, and broadcast Klobuchar coefficients of that day
T0 = 2381 * 604800.0 + 408600.0
ALPHA = (2.142e-8, 2.235e-8, -1.192e-7, -1.192e-7)
BETA = (129024.0, 65536.0, -196608.0, 327680.0)
ION = pd.DataFrame([dict(system="G", source="lnav", **{f"alpha{k}": ALPHA[k] for k in range(4)},
                         **{f"beta{k}": BETA[k] for k in range(4)})], index=[T0])
#: the measurement model of the simulations (no C/N0 mask)
CFG = GnssModelConfig(cn0_mask=0.0)


def pr_noise(el, cn0, ura, iono):
    """Pseudorange sigma the model assumes (receiver, URA, ionosphere and troposphere terms)."""
    return np.sqrt(pseudorange_variance(el, cn0, CFG) + ura**2 + iono_variance(iono)
                   + tropo_variance(el))


def _d(v: float) -> str:
    return f"{v:19.12E}".replace("E", "D")


def _label(text: str, label: str) -> str:
    return f"{text:<60s}{label}\n"


def _epoch(t_gps: float, offset: float = 0.0) -> str:
    dt = pd.Timestamp(datetime64_from_gps_seconds(np.array([t_gps + offset]))[0])
    return f"{dt.year:4d} {dt.month:02d} {dt.day:02d} {dt.hour:02d} {dt.minute:02d} {dt.second:02d}"


def write_rinex_nav(eph: pd.DataFrame, ion: pd.DataFrame | None, path) -> None:
    """RINEX 3.04 mixed navigation file of the LNAV / I/NAV / D1 rows of an ephemeris table."""
    lines = [_label("     3.04           N: GNSS NAV DATA    M: MIXED", "RINEX VERSION / TYPE")]
    if ion is not None:
        g = ion[(ion["system"] == "G") & ion["alpha0"].notna()]
        if len(g):
            r = g.iloc[-1]
            a = "".join(f"{r[f'alpha{k}']:12.4E}".replace("E", "D") for k in range(4))
            b = "".join(f"{r[f'beta{k}']:12.4E}".replace("E", "D") for k in range(4))
            lines.append(_label(f"GPSA {a}", "IONOSPHERIC CORR"))
            lines.append(_label(f"GPSB {b}", "IONOSPHERIC CORR"))
    lines.append(_label("", "END OF HEADER"))
    for _, r in eph.iterrows():
        if r["source"] not in ("lnav", "inav", "d1"):
            continue
        s = r["system"]
        off = BDT_MINUS_GPST if s == "C" else 0.0
        week = np.floor((r["toe"] + off) / 604800.0) - (1356 if s == "C" else 0)
        t_tx = np.mod(r["time_received"] + off, 604800.0)
        if s == "E":
            h = int(r["health"])
            rh = (h & 7) | (((h >> 2) & 1) << 6) | (((h >> 3) & 3) << 7)
            l5 = [r["idot"], 517.0, week, 0.0]
            l6 = [r["ura"], rh, r["tgd"], r["tgd2"]]
            l7 = [t_tx, 0.0, 0.0, 0.0]
        elif s == "C":
            l5 = [r["idot"], 0.0, week, 0.0]
            l6 = [2.0, r["health"], r["tgd"], r["tgd2"]]
            l7 = [t_tx, r["iodc"], 0.0, 0.0]
        else:
            l5 = [r["idot"], 1.0, week, 0.0]
            l6 = [r["ura"], r["health"], r["tgd"], r["iodc"]]
            l7 = [t_tx, 4.0, 0.0, 0.0]
        vals = [[r["af0"], r["af1"], r["af2"]],
                [r["iode"], r["crs"], r["delta_n"], r["m0"]],
                [r["cuc"], r["e"], r["cus"], r["sqrt_a"]],
                [r["toe_sow"], r["cic"], r["omega0"], r["cis"]],
                [r["i0"], r["crc"], r["omega"], r["omega_dot"]], l5, l6, l7]
        lines.append(f"{r['sat']} {_epoch(r['toc'], off)}" + "".join(_d(v) for v in vals[0]) + "\n")
        for v in vals[1:]:
            lines.append("    " + "".join(_d(x) for x in v) + "\n")
    with open(path, "w") as f:
        f.writelines(lines)


def write_rinex_obs(obs: pd.DataFrame, path, signals: dict) -> None:
    """RINEX 3.04 observation file (C/L/D/S of the given ``{system: (signal, ...)}``)."""
    types = {s: [f"{k}{g}" for g in sig for k in "CLDS"] for s, sig in signals.items()}
    lines = [_label("     3.04           OBSERVATION DATA    M", "RINEX VERSION / TYPE")]
    for s, ty in types.items():
        lines.append(_label(f"{s}  {len(ty):3d} " + " ".join(ty), "SYS / # / OBS TYPES"))
    t0 = float(obs.index[0])
    dt0 = pd.Timestamp(datetime64_from_gps_seconds(np.array([t0]))[0])
    lines.append(_label(f"  {dt0.year:4d}    {dt0.month:02d}    {dt0.day:02d}    {dt0.hour:02d}"
                        f"    {dt0.minute:02d}   {dt0.second + dt0.microsecond * 1e-6:10.7f}     GPS",
                        "TIME OF FIRST OBS"))
    lines.append(_label("", "END OF HEADER"))
    for t, ep in obs.groupby(level=0, sort=True):
        dt = pd.Timestamp(datetime64_from_gps_seconds(np.array([t]))[0])
        sats = [s for s in pd.unique(ep["sat"]) if s[0] in types]
        body = []
        for sat in sats:
            rows = ep[ep["sat"] == sat]
            rec = sat
            for ty in types[sat[0]]:
                r = rows[rows["signal"] == ty[1:]]
                col = {"C": "pr", "L": "cp", "D": "doppler", "S": "cn0"}[ty[0]]
                v = float(r[col].iloc[0]) if len(r) else np.nan
                rec += f"{v:14.3f}  " if np.isfinite(v) else " " * 16
            body.append(rec.rstrip() + "\n")
        sec = dt.second + dt.microsecond * 1e-6 + dt.nanosecond * 1e-9
        lines.append(f"> {dt.year:4d} {dt.month:02d} {dt.day:02d} {dt.hour:02d} {dt.minute:02d}"
                     f"{sec:11.7f}  0{len(body):3d}\n")
        lines.extend(body)
    with open(path, "w") as f:
        f.writelines(lines)


def synthetic_constellation(t_ref: float, n_gps: int = 24, n_gal: int = 18) -> pd.DataFrame:
    """Ephemeris table of a Walker-like GPS (6 planes, 55 deg) and Galileo (3 planes, 56 deg)
    constellation with toe = t_ref, small eccentricities, clock terms and harmonic corrections."""
    rows = []
    sow = float(np.mod(t_ref, 604800.0))
    for k in range(n_gps + n_gal):
        gal = k >= n_gps
        j = k - n_gps if gal else k
        per_plane = 6 if gal else 4
        plane, slot = divmod(j, per_plane)
        r = dict.fromkeys(EPH_COLUMNS, 0.0)
        r.update(sat=f"{'E' if gal else 'G'}{j + 1:02d}", system="E" if gal else "G", prn=j + 1,
                 source="inav" if gal else "lnav", time_received=t_ref - 60.0, toe=t_ref,
                 toc=t_ref, toe_sow=sow, iode=j, iodc=j, sqrt_a=5440.6 if gal else 5153.6,
                 e=0.002 + 0.004 * (j % 3), i0=np.radians(56.0 if gal else 55.0),
                 omega0=np.radians((120.0 * plane + 10.0) if gal else 60.0 * plane),
                 omega=0.4 * j,
                 m0=np.radians(360.0 / per_plane * slot + (20.0 if gal else 15.0) * plane) - 0.4 * j,
                 delta_n=4.5e-9, omega_dot=-8.0e-9, idot=1e-10, cuc=1e-6, cus=5e-6, crc=200.0,
                 crs=20.0, cic=1e-7, cis=-1e-7, af0=1e-5 * (j - 3), af1=1e-12, af2=0.0,
                 tgd=-5e-9, tgd2=-5.5e-9 if gal else np.nan, isc_1C=np.nan, isc_2L=np.nan,
                 isc_5I=np.nan, isc_5Q=np.nan, health=0, ura=2.0)
        rows.append(r)
    return pd.DataFrame(rows, columns=EPH_COLUMNS)


def simulate_observations(eph, times, r_fn, clock_fn, isb=None, iono=None, noise=None,
                          rng=None, signal="1C", cn0=45.0, doppler_noise=None):
    """Pseudoranges and Dopplers of every satellite of ``eph`` above 5 deg, generated by an
    independent light-time solution (iterated to 1e-12 s, satellite state at the transmission
    time, Earth rotation during the travel time).

    ``r_fn(t) -> ECEF position``, ``clock_fn(t) -> receiver clock bias [m]`` (true time t);
    ``isb`` ``{system: m}``; ``iono`` = (alpha, beta) adds the Klobuchar delay, the Saastamoinen
    /Niell troposphere is always added; ``noise(el, cn0, ura, iono_delay) -> sigma`` draws
    Gaussian pseudorange noise, ``doppler_noise(el, cn0) -> sigma`` range-rate noise [m/s].
    Returns the observation table (index = receiver time tag t + b/c) and the true states.
    """
    from insgnss.earth import ecef_to_enu_vectors, ecef_to_geodetic
    from insgnss.gnss.constants import C_LIGHT, F_L1, OMEGA_E_WGS84
    from insgnss.gnss.corrections import day_of_year, klobuchar_delay, tropo_delay
    from insgnss.gnss.ephemeris import group_delay, satellite_states

    isb = isb or {}
    rng = rng or np.random.default_rng(0)
    n = len(eph)
    gd = np.array([group_delay(s, eph.iloc[[k]], signal)[0] for k, s in enumerate(eph["system"])])

    def model(t):
        r = np.asarray(r_fn(t), float)
        tau = np.full(n, 0.07)
        for _ in range(30):
            st = satellite_states(eph, np.arange(n), t - tau)
            th = OMEGA_E_WGS84 * tau
            p = np.column_stack([np.cos(th) * st["pos"][:, 0] + np.sin(th) * st["pos"][:, 1],
                                 -np.sin(th) * st["pos"][:, 0] + np.cos(th) * st["pos"][:, 1],
                                 st["pos"][:, 2]])
            tau_new = np.linalg.norm(p - r, axis=1) / C_LIGHT
            if np.max(np.abs(tau_new - tau)) < 1e-13:
                break
            tau = tau_new
        lat, lon, h = ecef_to_geodetic(*r)
        los = (p - r) / np.linalg.norm(p - r, axis=1)[:, None]
        enu = ecef_to_enu_vectors(los, lat, lon)
        el = np.arcsin(enu[:, 2])
        az = np.arctan2(enu[:, 0], enu[:, 1])
        trop = tropo_delay(el, lat, h, day_of_year(t))
        io = np.zeros(n) if iono is None else klobuchar_delay(
            lat, lon, el, az, np.mod(t, 604800.0), iono[0], iono[1], F_L1)
        b = clock_fn(t) + np.array([isb.get(s, 0.0) for s in eph["system"]])
        pr = C_LIGHT * tau + b - C_LIGHT * (st["clock"] - gd) + trop + io
        return pr, el, io

    rows, truth = [], []
    lam = C_LIGHT / F_L1
    for t in times:
        pr, el, io = model(t)
        dt = 0.05
        rate = (model(t + dt)[0] - model(t - dt)[0]) / (2 * dt)
        vis = el > np.radians(5.0)
        sig = np.zeros(n) if noise is None else noise(el, cn0, eph["ura"].to_numpy(float), io)
        pr = pr + sig * rng.standard_normal(n)
        if doppler_noise is not None:
            rate = rate + doppler_noise(el, cn0) * rng.standard_normal(n)
        t_tag = t + clock_fn(t) / C_LIGHT
        for k in np.nonzero(vis)[0]:
            rows.append(dict(time=t_tag, sat=eph["sat"].iloc[k], system=eph["system"].iloc[k],
                             prn=int(eph["prn"].iloc[k]), signal=signal, freq=F_L1, pr=pr[k],
                             cp=np.nan, doppler=-rate[k] / lam, cn0=cn0, pr_std=np.nan,
                             cp_std=np.nan, doppler_std=np.nan, lock_time=10.0, pr_valid=True,
                             cp_valid=False, half_cycle=False, glonass_k=np.nan))
        truth.append(dict(t=t, t_tag=t_tag, r=np.asarray(r_fn(t), float), b=clock_fn(t)))
    obs = pd.DataFrame(rows).set_index("time")
    return obs, truth
