"""RINEX 3 observation and navigation files, read with ``georinex`` (imported lazily: it
loads xarray, ~0.5 s).

- :func:`read_rinex_obs`: the observation table of :func:`insgnss.gnss.read_ubx`
  (``C``/``L``/``D``/``S`` observables of each signal become ``pr cp doppler cn0``);
  epochs are taken as GPST (RINEX 3 files of GPS/mixed receivers use GPS time; a header
  ``TIME OF FIRST OBS`` in another system is refused).
- :func:`read_rinex_nav`: the ephemeris table of :func:`insgnss.gnss.decode_subframes` for
  GPS, QZSS, Galileo (I/NAV records; F/NAV ones are skipped) and BeiDou; GLONASS/SBAS state
  vectors are not supported (skipped, counted in ``attrs["skipped_systems"]``). The header's
  GPS Klobuchar coefficients (``GPSA``/``GPSB``) give the ionosphere table.

References: RINEX 3.05 (IGS/RTCM 2020), tables A2-A4 (observations), A6-A14 (navigation).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputFormatError
from ..io.gpstime import gps_seconds_from_datetime64
from .constants import BDT_MINUS_GPST, carrier_frequency
from .navmsg import EPH_COLUMNS, ION_COLUMNS, nearest_week_time, sisa_from_index
from .ubx import OBS_COLUMNS


def _load(path, **kw):
    import georinex  # lazy

    path = Path(path)
    if not path.is_file():
        raise InputFormatError("RINEX file not found", file=path)
    try:
        with warnings.catch_warnings():
            # georinex 1.16 uses xarray.merge defaults that newer xarray deprecates
            warnings.simplefilter("ignore", FutureWarning)
            return georinex.load(path, **kw)
    except Exception as exc:  # georinex raises assorted ValueError/KeyError/IndexError
        raise InputFormatError(f"cannot read RINEX file: {exc}", file=path) from exc


def read_rinex_obs(path) -> pd.DataFrame:
    """Read a RINEX 3 observation file into the raw observation table (see module docstring).

    Returns
    -------
    DataFrame
        Index ``time`` [GPS s], columns :data:`insgnss.gnss.ubx.OBS_COLUMNS`; ``pr_std``,
        ``cp_std``, ``doppler_std``, ``lock_time`` are NaN (RINEX has none), ``pr_valid`` is
        True where a pseudorange exists, ``cp_valid`` where the phase has no loss-of-lock flag.
    """
    ds = _load(path, useindicators=True)
    ts = ds.attrs.get("time_system", "GPS")
    if str(ts).strip().upper() not in ("GPS", "", "NONE"):
        raise InputFormatError("RINEX observation epochs are not in GPS time", file=path,
                               column="TIME OF FIRST OBS", expected="GPS", found=ts)
    times = gps_seconds_from_datetime64(ds["time"].values)
    svs = [str(s) for s in ds["sv"].values]
    parts = []
    codes = sorted({v[1:3] for v in ds.data_vars if v[0] in "CLDS" and len(v) == 3})
    for code in codes:
        get = {k: (ds[f"{k}{code}"].values if f"{k}{code}" in ds else None) for k in "CLDS"}
        if get["C"] is None:
            continue
        lli = ds[f"L{code}lli"].values if f"L{code}lli" in ds else None
        T, S = np.meshgrid(np.arange(times.size), np.arange(len(svs)), indexing="ij")
        pr = get["C"]
        ok = np.isfinite(pr)
        if not ok.any():
            continue
        ti, si = T[ok], S[ok]
        system = np.array([svs[i][0] for i in si], object)
        prn = np.array([int(svs[i][1:]) for i in si])

        def val(a, ok=ok):
            return a[ok].astype(float) if a is not None else np.full(ok.sum(), np.nan)

        cp = val(get["L"])
        ll = val(lli) if lli is not None else np.zeros(cp.size)
        df = pd.DataFrame({
            "sat": [svs[i] for i in si], "system": system, "prn": prn, "signal": code,
            "freq": [carrier_frequency(s, code) for s in system],
            "pr": val(pr), "cp": cp, "doppler": val(get["D"]), "cn0": val(get["S"]),
            "pr_std": np.nan, "cp_std": np.nan, "doppler_std": np.nan, "lock_time": np.nan,
            "pr_valid": True, "cp_valid": np.isfinite(cp) & ~(np.nan_to_num(ll).astype(int) & 1 > 0),
            "half_cycle": ~(np.nan_to_num(ll).astype(int) & 2 > 0), "glonass_k": np.nan,
        }, index=pd.Index(times[ti], name="time"))
        parts.append(df)
    if not parts:
        raise InputFormatError("no pseudorange observations in the RINEX file", file=path)
    obs = pd.concat(parts).sort_index(kind="stable")[OBS_COLUMNS]
    obs.index.name = "time"
    obs.attrs.update(source=str(path), format="rinex_obs", time_base="gps", time_column="epoch")
    return obs


_COMMON = {"Crs": "crs", "DeltaN": "delta_n", "M0": "m0", "Cuc": "cuc", "Eccentricity": "e",
           "Cus": "cus", "sqrtA": "sqrt_a", "Cic": "cic", "Omega0": "omega0", "Cis": "cis",
           "Io": "i0", "Crc": "crc", "omega": "omega", "OmegaDot": "omega_dot", "IDOT": "idot",
           "SVclockBias": "af0", "SVclockDrift": "af1", "SVclockDriftRate": "af2"}


def read_rinex_nav(path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Read a RINEX 3 navigation file into (ephemeris table, ionosphere table)."""
    ds = _load(path)
    rows = []
    skipped = set()
    svs = [str(s) for s in ds["sv"].values]
    toc_all = ds["time"].values
    for j, sv in enumerate(svs):
        sysl = sv[0]
        if sysl not in "GJEC":
            skipped.add(sysl)
            continue
        sub = ds.isel(sv=j)
        ok = np.isfinite(sub["sqrtA"].values)
        for i in np.nonzero(ok)[0]:
            g = {k: float(sub[k].values[i]) for k in sub.data_vars
                 if np.issubdtype(sub[k].dtype, np.number)}
            toc = float(gps_seconds_from_datetime64(toc_all[i:i + 1])[0])
            off = BDT_MINUS_GPST if sysl == "C" else 0.0
            toc -= off  # BDT epoch -> GPST
            r = dict.fromkeys(EPH_COLUMNS, 0.0)
            r.update({v: g[k] for k, v in _COMMON.items()})
            r.update(sat=sv, system=sysl, prn=int(sv[1:]), time_received=np.nan, toc=toc,
                     isc_1C=np.nan, isc_2L=np.nan, isc_5I=np.nan, isc_5Q=np.nan, tgd2=np.nan,
                     a_dot=0.0, delta_n_dot=0.0)
            r["toe_sow"] = g["Toe"]
            r["toe"] = nearest_week_time(g["Toe"], toc, off)
            tt = g.get("TransTime", np.nan)
            r["time_received"] = nearest_week_time(tt, toc, off) if np.isfinite(tt) else toc
            if sysl in "GJ":
                r.update(source="lnav", iode=int(g["IODE"]), iodc=int(g.get("IODC", 0)),
                         tgd=g["TGD"], health=int(g["health"]), ura=g["SVacc"])
            elif sysl == "E":
                src = int(g.get("DataSrc", 1))
                if not (src & 0b101):  # F/NAV only
                    continue
                h = int(g["health"])
                r.update(source="inav", iode=int(g["IODnav"]), iodc=int(g["IODnav"]),
                         tgd=g["BGDe5a"], tgd2=g["BGDe5b"],
                         health=(h & 7) | (((h >> 7) & 3) << 3) | (((h >> 6) & 1) << 2),
                         ura=g["SISA"] if g["SISA"] >= 0 else sisa_from_index(255))
            else:
                r.update(source="d1", iode=int(g["AODE"]), iodc=int(g["AODC"]), tgd=g["TGD1"],
                         tgd2=g["TGD2"], health=int(g["SatH1"]), ura=g["SVacc"])
            rows.append(r)
    eph = pd.DataFrame(rows, columns=EPH_COLUMNS).sort_values("toe", kind="stable")
    eph = eph.reset_index(drop=True)
    ion_rows = []
    corr = ds.attrs.get("ionospheric_corr_GPS")
    if corr is not None and len(corr) >= 8:
        ion_rows.append(dict(system="G", source="rinex",
                             **{f"alpha{k}": float(corr[k]) for k in range(4)},
                             **{f"beta{k}": float(corr[4 + k]) for k in range(4)}))
    t0 = float(eph["toe"].min()) if len(eph) else np.nan
    ion = pd.DataFrame(ion_rows, columns=ION_COLUMNS,
                       index=pd.Index([t0] * len(ion_rows), name="time", dtype=float))
    for df in (eph, ion):
        df.attrs.update(source=str(path), format="rinex_nav", time_base="gps",
                        skipped_systems=sorted(skipped))
    return eph, ion
