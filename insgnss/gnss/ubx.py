"""u-blox UBX reader: raw observations (UBX-RXM-RAWX), broadcast navigation words
(UBX-RXM-SFRBX) and the receiver's own fix (UBX-NAV-PVT).

``pyubx2`` frames the stream (sync, length; interleaved NMEA/RTCM skipped) with ``parsing=0``
(the checksum is verified here: pyubx2 checks it only when parsing); the three payloads are
decoded with fixed numpy layouts, ~10x faster than pyubx2's per-field parsing (0.4 s instead
of 5 s for the 1.5 MB walk stream).
Payload layouts: u-blox "Interface Description" (F9/X20 HPG), UBX-RXM-RAWX, UBX-RXM-SFRBX,
UBX-NAV-PVT.

Tables (see docs/formats.md, "Raw GNSS"):

- observations: one row per (epoch, satellite, signal), index ``time`` (GPS seconds of the
  receiver time tag, repeated for the satellites of an epoch);
- subframes: one row per SFRBX message, ``time`` = the preceding RAWX epoch (the message was
  received within one measurement interval before it), ``words`` = the 32-bit data words;
- nav_pvt: the receiver's fix in the GNSS table layout of the other readers.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputFormatError, InsgnssWarning
from ..io.gpstime import WEEK_SECONDS, gps_seconds_from_utc
from .constants import UBX_SIGNALS, UBX_SYSTEMS, carrier_frequency, satellite_name

_RAWX_MEAS = np.dtype([("pr", "<f8"), ("cp", "<f8"), ("doppler", "<f4"), ("gnss", "u1"),
                       ("sv", "u1"), ("sig", "u1"), ("freq_id", "u1"), ("lock", "<u2"),
                       ("cno", "u1"), ("pr_dev", "u1"), ("cp_dev", "u1"), ("do_dev", "u1"),
                       ("trk", "u1"), ("res", "u1")])

OBS_COLUMNS = ["sat", "system", "prn", "signal", "freq", "pr", "cp", "doppler", "cn0", "pr_std",
               "cp_std", "doppler_std", "lock_time", "pr_valid", "cp_valid", "half_cycle",
               "glonass_k"]
SUBFRAME_COLUMNS = ["sat", "system", "prn", "signal", "words"]


@dataclass
class UbxData:
    """Contents of a UBX stream.

    Attributes
    ----------
    observations : DataFrame
        Index ``time`` [GPS s]; columns :data:`OBS_COLUMNS` (``pr`` [m], ``cp`` [cycles],
        ``doppler`` [Hz, positive when the range shortens], ``cn0`` [dB-Hz], ``*_std`` the
        receiver's estimates [m, cycles, Hz], ``lock_time`` [s], flags as bool).
    subframes : DataFrame
        Index ``time`` [GPS s]; columns :data:`SUBFRAME_COLUMNS`.
    nav_pvt : DataFrame
        The receiver's solution as a GNSS table (``lat lon height`` [rad, m, ellipsoidal],
        ``east_std north_std up_std``, ``vel_e vel_n vel_u`` + ``*_std``, ``q``, ``ns``,
        ``height_msl``, ``pdop``, ``fix_type``).
    epochs : DataFrame
        One row per RAWX epoch: ``n_meas``, ``leap_seconds``, ``clock_reset``.
    """

    observations: pd.DataFrame
    subframes: pd.DataFrame
    nav_pvt: pd.DataFrame
    epochs: pd.DataFrame


def read_ubx(path) -> UbxData:
    """Read a u-blox UBX stream (RAWX, SFRBX, NAV-PVT; other messages are skipped).

    Raises
    ------
    InputFormatError
        Missing or empty file, or no UBX-RXM-RAWX epoch in it. Messages with a bad checksum
        are skipped with an :class:`~insgnss.errors.InsgnssWarning` (``attrs["bad_messages"]``).
    """
    from pyubx2 import UBXReader  # lazy: only UBX users pay the import

    path = Path(path)
    if not path.is_file():
        raise InputFormatError("UBX file not found", file=path)
    bad: list[str] = []
    obs_parts, epochs, subframes, pvts = [], [], [], []
    last_time = np.nan
    with open(path, "rb") as f:
        reader = UBXReader(f, protfilter=2, quitonerror=1, parsing=0, validate=1,
                           errorhandler=lambda e: bad.append(str(e)))
        k = -1
        while True:
            pos = f.tell()
            try:
                raw, _ = reader.read()
            except (UnicodeDecodeError, ValueError, IndexError, KeyError) as exc:
                # pyubx2 lets the decoding errors of damaged NMEA lines escape; skip them
                bad.append(f"byte {pos}: {exc}")
                if f.tell() <= pos:
                    f.seek(pos + 1)
                continue
            if raw is None:
                break
            k += 1
            if len(raw) < 8:
                continue
            if not _checksum_ok(raw):
                bad.append(f"message {k + 1}: checksum error")
                continue
            cls_id = raw[2:4]
            payload = raw[6:-2]
            if cls_id == b"\x02\x15":  # RXM-RAWX
                last_time = _decode_rawx(payload, k, path, obs_parts, epochs)
            elif cls_id == b"\x02\x13":  # RXM-SFRBX
                _decode_sfrbx(payload, last_time, subframes)
            elif cls_id == b"\x01\x07" and len(payload) >= 92:  # NAV-PVT
                pvts.append(payload[:92])
    if bad:
        warnings.warn(InsgnssWarning(f"{len(bad)} UBX messages skipped (checksum or framing): "
                                     f"{bad[0]}", file=path), stacklevel=2)
    if not epochs:
        raise InputFormatError("no UBX-RXM-RAWX epoch in the stream", file=path,
                               expected="RXM-RAWX messages", found="none")
    obs = _observation_table(obs_parts)
    ep = pd.DataFrame(epochs, columns=["time", "n_meas", "leap_seconds", "clock_reset"]
                      ).set_index("time")
    sf = pd.DataFrame(subframes, columns=["time", *SUBFRAME_COLUMNS]).set_index("time")
    pvt = _nav_pvt_table(pvts, ep.index.to_numpy(float))
    for df, fmt in ((obs, "ubx_rawx"), (sf, "ubx_sfrbx"), (pvt, "ubx_nav_pvt"), (ep, "ubx_rawx")):
        df.index.name = "time"
        df.attrs.update(source=str(path), format=fmt, time_base="gps", time_column="rcvTow")
        if len(ep):
            df.attrs["gps_week"] = int(ep.index[0] // WEEK_SECONDS)
        df.attrs["bad_messages"] = len(bad)
    return UbxData(obs, sf, pvt, ep)


def _checksum_ok(raw: bytes) -> bool:
    """UBX 8-bit Fletcher checksum over class, id, length and payload (pyubx2 validates it
    only when it parses)."""
    a = np.cumsum(np.frombuffer(raw, np.uint8, len(raw) - 4, 2), dtype=np.int64)
    return (int(a[-1]) & 0xFF) == raw[-2] and (int(a.sum()) & 0xFF) == raw[-1]


def _decode_rawx(payload: bytes, k: int, path, obs_parts: list, epochs: list) -> float:
    if len(payload) < 16:
        raise InputFormatError("truncated UBX-RXM-RAWX", file=path, row=k + 1,
                               expected=">= 16 bytes", found=len(payload))
    tow = np.frombuffer(payload, "<f8", 1, 0)[0]
    week = int(np.frombuffer(payload, "<u2", 1, 8)[0])
    leap = int(np.frombuffer(payload, "i1", 1, 10)[0])
    n = payload[11]
    rec_stat = payload[12]
    if len(payload) < 16 + 32 * n:
        raise InputFormatError("truncated UBX-RXM-RAWX", file=path, row=k + 1,
                               expected=f"{16 + 32 * n} bytes", found=len(payload))
    t = week * WEEK_SECONDS + float(tow)
    epochs.append((t, n, leap, bool(rec_stat & 2)))
    if n:
        obs_parts.append((t, np.frombuffer(payload, _RAWX_MEAS, n, 16)))
    return t


def _observation_table(parts: list) -> pd.DataFrame:
    """One DataFrame from the (time, RAWX measurement records) of all epochs."""
    if not parts:
        return pd.DataFrame(columns=OBS_COLUMNS, index=pd.Index([], name="time", dtype=float))
    m = np.concatenate([p[1] for p in parts])
    t = np.repeat([p[0] for p in parts], [p[1].size for p in parts])
    key = m["gnss"].astype(np.int64) * 256 + m["sig"]
    sys_of = {g: s for g, s in UBX_SYSTEMS.items()}
    systems = np.array([sys_of.get(int(g), "?") for g in m["gnss"]], object)
    sig_of = {g * 256 + s: c for (g, s), c in UBX_SIGNALS.items()}
    signals = np.array([sig_of.get(int(k), "") for k in key], object)
    k_glo = np.where(m["gnss"] == 6, m["freq_id"].astype(float) - 7.0, np.nan)
    prn = m["sv"].astype(int)
    freq = np.array([carrier_frequency(s, g, kk) for s, g, kk in zip(systems, signals, k_glo,
                                                                     strict=True)])
    trk = m["trk"]
    df = pd.DataFrame({
        "sat": [satellite_name(s, int(p)) for s, p in zip(systems, prn, strict=True)],
        "system": systems, "prn": prn, "signal": signals, "freq": freq,
        "pr": m["pr"], "cp": m["cp"], "doppler": m["doppler"].astype(float),
        "cn0": m["cno"].astype(float),
        "pr_std": 0.01 * 2.0 ** (m["pr_dev"] & 0x0F),
        "cp_std": 0.004 * (m["cp_dev"] & 0x0F),
        "doppler_std": 0.002 * 2.0 ** (m["do_dev"] & 0x0F),
        "lock_time": m["lock"] * 1e-3,
        "pr_valid": (trk & 1) > 0, "cp_valid": (trk & 2) > 0, "half_cycle": (trk & 4) > 0,
        "glonass_k": k_glo,
    }, index=pd.Index(t, name="time"))
    return df[(systems != "?") & (signals != "")]


def _decode_sfrbx(payload: bytes, last_time: float, out: list) -> None:
    if len(payload) < 8:
        return
    g, sv, sig, nw = payload[0], payload[1], payload[2], payload[4]
    if len(payload) < 8 + 4 * nw or g not in UBX_SYSTEMS:
        return
    words = tuple(int(w) for w in np.frombuffer(payload, "<u4", nw, 8))
    system = UBX_SYSTEMS[g]
    out.append((last_time, satellite_name(system, sv), system, int(sv),
                UBX_SIGNALS.get((g, sig), ""), words))


def _nav_pvt_table(pvts: list, rawx_times: np.ndarray) -> pd.DataFrame:
    cols = ["lat", "lon", "height", "east_std", "north_std", "up_std", "vel_e", "vel_n", "vel_u",
            "vel_e_std", "vel_n_std", "vel_u_std", "q", "ns", "height_msl", "pdop", "fix_type"]
    if not pvts:
        return pd.DataFrame(columns=cols, index=pd.Index([], name="time", dtype=float))
    b = np.frombuffer(b"".join(pvts), np.uint8).reshape(-1, 92)

    def f(off, dt):
        return b[:, off:off + np.dtype(dt).itemsize].copy().view(dt).ravel()

    itow = f(0, "<u4") * 1e-3
    utc = (pd.to_datetime(pd.DataFrame({"year": f(4, "<u2"), "month": f(6, "u1"),
                                        "day": f(7, "u1"), "hour": f(8, "u1"),
                                        "minute": f(9, "u1"), "second": f(10, "u1")}))
           .to_numpy("datetime64[ns]") + f(16, "<i4").astype("timedelta64[ns]"))
    t_utc = gps_seconds_from_utc(utc)
    # the GPS week from the UTC date (valid even without a RAWX epoch), refined so that the
    # exact iTOW is kept
    week = np.round((t_utc - itow) / WEEK_SECONDS)
    t = week * WEEK_SECONDS + itow
    flags = f(21, "u1")
    fix = f(20, "u1")
    carr = (flags >> 6) & 3
    q = np.where(carr == 2, 1, np.where(carr == 1, 2, np.where(flags & 2, 4, 5))).astype(float)
    q[(fix < 2) | ((flags & 1) == 0)] = np.nan
    h_acc, v_acc, s_acc = f(40, "<u4") * 1e-3, f(44, "<u4") * 1e-3, f(68, "<u4") * 1e-3
    df = pd.DataFrame({
        "lat": np.radians(f(28, "<i4") * 1e-7), "lon": np.radians(f(24, "<i4") * 1e-7),
        "height": f(32, "<i4") * 1e-3,
        # hAcc is the receiver's horizontal accuracy estimate: split equally on east and north
        "east_std": h_acc / np.sqrt(2.0), "north_std": h_acc / np.sqrt(2.0), "up_std": v_acc,
        "vel_e": f(52, "<i4") * 1e-3, "vel_n": f(48, "<i4") * 1e-3, "vel_u": -f(56, "<i4") * 1e-3,
        "vel_e_std": s_acc / np.sqrt(3.0), "vel_n_std": s_acc / np.sqrt(3.0),
        "vel_u_std": s_acc / np.sqrt(3.0),
        "q": q, "ns": f(23, "u1").astype(float), "height_msl": f(36, "<i4") * 1e-3,
        "pdop": f(76, "<u2") * 0.01, "fix_type": fix.astype(int),
    }, index=pd.Index(t, name="time"))
    df = df[np.isfinite(df["q"])]
    return df[~df.index.duplicated()]
