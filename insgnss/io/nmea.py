"""NMEA 0183 GNSS logs (GGA, RMC, VTG, GST) via pynmea2.

Epochs are the GGA sentences (position, fix quality, satellites, HDOP, height). The other
sentences add, matched by UTC time of day:

- RMC: the UTC date (and speed over ground + true course -> ``vel_e vel_n``);
- VTG (no time field): speed and course of the epoch it follows;
- GST: position error standard deviations -> ``north_std east_std up_std``;
- GSA (no time field): the VDOP of the epoch it follows.

Position sigmas: from GST where the epoch has one; else (``uere``, default :data:`UERE`) from
the dilution of precision and a user equivalent range error (UERE, the 1-sigma error of one
pseudorange after the receiver's corrections) of the fix type:
``east_std = north_std = HDOP * UERE / sqrt(2)`` (HDOP^2 = (sigma_E^2 + sigma_N^2) / UERE^2,
split equally) and ``up_std = VDOP * UERE``, with VDOP from GSA, else ``2 * HDOP`` (VDOP is
1.5-2 times HDOP with satellites above the horizon only; the larger ratio keeps the vertical
from being over-weighted). Epochs with neither hold NaN; ``attrs["std_source"]`` counts the
epochs per source (``gst``, ``hdop``, ``none``). The receiver's own GST estimate is always
preferable: the UERE table describes a typical receiver of each fix type, not yours.

Velocity: NMEA gives only the horizontal velocity (speed and course over ground): ``vel_e
vel_n``, no ``vel_u`` and no velocity sigma.

Height: GGA gives the height above the geoid; with the geoid separation field present the
ellipsoidal height ``altitude + geo_sep`` is returned (``attrs["height_reference"] =
"ellipsoid"``), else the orthometric height (``"msl"``).

Time: UTC date + time of day -> GPS seconds with leap seconds
(:func:`insgnss.io.gpstime.gps_seconds_from_utc`). The date comes from RMC sentences (the
same epoch, else the nearest dated epoch, with midnight roll-over), else from ``date=``; with
neither the index is UTC seconds of the first day (``attrs["time_base"] = "utc_sod"``).

Fix quality: the GGA indicator is kept in ``fix_quality`` and mapped onto RTKLIB's Q in ``q``
(4 RTK fixed -> 1, 5 RTK float -> 2, 2 DGPS -> 4, 1 and 3 single -> 5). Epochs without a GNSS fix
(0 invalid, 6 dead reckoning, 7 manual, 8 simulation) are dropped and listed in
``attrs["dropped_no_fix"]``.

Lines that are not valid NMEA (bad checksum, garbage, unparsable fields) are skipped with a
warning and listed in ``attrs["skipped_lines"]`` (``bad_lines="skip"``), or raise
InputFormatError (``bad_lines="error"``). Velocity and standard-deviation columns are present
when any epoch has them; epochs without them hold NaN there (listed in ``attrs``
``"missing_velocity_rows"`` / ``"missing_std_rows"``).
"""

from __future__ import annotations

import datetime as _dt
import os

import numpy as np
import pandas as pd
import pynmea2

from ..errors import ConfigError, InputFormatError
from ..validate import check_time_order, finish_attrs, read_text, warn
from .gpstime import gps_seconds_from_utc

KNOT = 1852.0 / 3600.0  #: knot -> m/s
#: GGA fix quality -> user equivalent range error [m, 1 sigma] for sigmas from the DOP:
#: 1/3 single point (L1 C/A code: satellite clock/orbit, residual ionosphere after the broadcast
#: model, troposphere, multipath and noise, about 5 m; Kaplan & Hegarty, Understanding GPS,
#: 2nd ed. 2006, ch. 7), 2/9 code differential or SBAS (the corrections remove the satellite
#: and most atmospheric errors: about 1 m of multipath and noise), 5 RTK float (about 0.3 m),
#: 4 RTK fixed (carrier phase: about 0.02 m)
UERE = {1: 5.0, 3: 5.0, 2: 1.0, 9: 1.0, 5: 0.3, 4: 0.02}
#: VDOP / HDOP when no GSA sentence gives the VDOP
VDOP_PER_HDOP = 2.0
#: GGA fix quality -> RTKLIB Q
NMEA_TO_Q = {1: 5, 2: 4, 3: 5, 4: 1, 5: 2, 9: 4}
_BAD = (ValueError, TypeError, IndexError, AttributeError, KeyError, ArithmeticError)


def _tod(ts) -> float:
    """Seconds of day of a datetime.time."""
    if ts is None:
        raise ValueError("no time")
    return ts.hour * 3600.0 + ts.minute * 60.0 + ts.second + ts.microsecond * 1e-6


def _date(date) -> np.datetime64 | None:
    if date is None:
        return None
    try:
        if isinstance(date, (_dt.date, np.datetime64)):
            return np.datetime64(date, "D")
        if isinstance(date, str):
            return np.datetime64(date, "D")
    except ValueError:
        pass
    raise ConfigError("invalid date", column="date", expected="'YYYY-MM-DD'", found=repr(date))


def read_nmea(path: str | os.PathLike, *, date=None, bad_lines: str = "skip",
              duplicates: str = "drop", uere: dict | None = UERE) -> pd.DataFrame:
    """Read an NMEA log into a GNSS table (see the module docstring).

    Parameters
    ----------
    path : path
    date : str or date, optional
        UTC date ``YYYY-MM-DD`` of the first epoch when the log has no RMC sentences.
    bad_lines : {"skip", "error"}
        Lines that are not valid NMEA: skipped with a warning, or an error.
    duplicates : {"drop", "error"}
        Repeated GGA epochs.
    uere : dict, optional
        GGA fix quality -> UERE [m] for the position sigmas of epochs without GST (module
        docstring); None: GST only.
    """
    if bad_lines not in ("skip", "error"):
        raise ConfigError("unknown bad-line policy", column="bad_lines",
                          expected="'skip' or 'error'", found=repr(bad_lines))
    date0 = _date(date)
    text = read_text(path)
    gga = []  # (order, line, tod, lat, lon, h, has_sep, quality, ns, hdop)
    rmc = {}  # tod -> list of (order, date or None, vel_e, vel_n or None)
    vtg = {}  # order of the preceding timed sentence -> (vel_e, vel_n)
    gst = {}  # tod -> (n, e, u)
    gsa = {}  # order of the preceding GGA -> VDOP (DOPs change slowly: the nearest epoch)
    last_gga = None
    skipped = []
    last_timed = None
    for k, raw in enumerate(text.split("\n")):
        line = raw.strip()
        if not line:
            continue
        row = k + 1
        start = line.find("$")
        try:
            if start < 0:
                raise ValueError("no '$'")
            msg = pynmea2.parse(line[start:])
            kind = getattr(msg, "sentence_type", None)
            if kind == "GGA":
                q = int(msg.gps_qual) if msg.gps_qual not in (None, "") else 0
                tod = _tod(msg.timestamp)
                if q in NMEA_TO_Q:
                    lat, lon = float(msg.latitude), float(msg.longitude)
                    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and msg.altitude is not None):
                        raise ValueError("position out of range")
                    sep = msg.geo_sep
                    h = float(msg.altitude) + (float(sep) if sep not in (None, "") else 0.0)
                    if not np.isfinite(h):
                        raise ValueError("height")
                    ns = float(msg.num_sats) if msg.num_sats not in (None, "") else np.nan
                    hdop = float(msg.horizontal_dil) if msg.horizontal_dil not in (None, "") \
                        else np.nan
                else:
                    lat = lon = h = ns = hdop = np.nan
                    sep = ""
                gga.append((k, row, tod, lat, lon, h, sep not in (None, ""), q, ns, hdop))
                last_timed = last_gga = k
            elif kind == "RMC":
                tod = _tod(msg.timestamp)
                d = msg.datestamp
                d = np.datetime64(d, "D") if d is not None else None
                ve = vn = None
                if msg.status == "A" and msg.spd_over_grnd not in (None, ""):
                    s = float(msg.spd_over_grnd) * KNOT
                    c = np.radians(float(msg.true_course)) if msg.true_course not in (None, "") \
                        else 0.0
                    ve, vn = s * np.sin(c), s * np.cos(c)
                    if not (np.isfinite(ve) and np.isfinite(vn)):
                        raise ValueError("velocity")
                rmc.setdefault(tod, []).append((k, d, ve, vn))
                last_timed = k
            elif kind == "VTG":
                if msg.spd_over_grnd_kmph not in (None, "") and last_timed is not None:
                    s = float(msg.spd_over_grnd_kmph) / 3.6
                    c = np.radians(float(msg.true_track)) if msg.true_track not in (None, "") \
                        else 0.0
                    if np.isfinite(s) and np.isfinite(c):
                        vtg[last_timed] = (s * np.sin(c), s * np.cos(c))
            elif kind == "GSA":
                if msg.vdop not in (None, "") and last_gga is not None:
                    gsa.setdefault(last_gga, float(msg.vdop))
            elif kind == "GST":
                tod = _tod(msg.timestamp)
                sd = (float(msg.std_dev_latitude), float(msg.std_dev_longitude),
                      float(msg.std_dev_altitude))
                if all(np.isfinite(x) and x >= 0 for x in sd):
                    gst[tod] = sd
        except _BAD as e:
            reason = str(e)[:80] or type(e).__name__
            if bad_lines == "error":
                raise InputFormatError("invalid NMEA sentence", file=path, row=row,
                                       expected="a valid NMEA sentence", found=repr(line[:60])
                                       ) from None
            skipped.append({"row": row, "reason": reason})
    if skipped:
        warn(f"{len(skipped)} line(s) that are not valid NMEA skipped", file=path,
             row=skipped[0]["row"], found=skipped[0]["reason"])
    if not gga:
        raise InputFormatError("no GGA position sentences", file=path, row=1,
                               expected="NMEA GGA sentences", found="none")

    order = np.array([g[0] for g in gga])
    line_no = np.array([g[1] for g in gga], np.int64)
    tod = np.array([g[2] for g in gga])
    quality = np.array([g[7] for g in gga], np.int64)
    fixed = np.isin(quality, list(NMEA_TO_Q))
    dropped_no_fix = [{"row": int(r), "quality": int(q)}
                      for r, q in zip(line_no[~fixed], quality[~fixed], strict=True)]
    if dropped_no_fix:
        warn(f"{len(dropped_no_fix)} GGA epoch(s) without a GNSS fix dropped", file=path,
             row=dropped_no_fix[0]["row"], column="quality",
             found=str(dropped_no_fix[0]["quality"]))

    # dates: same-epoch RMC, else propagated with midnight roll-over
    days = np.full(tod.size, np.iinfo(np.int64).min, np.int64)
    vel = np.full((tod.size, 2), np.nan)
    for i in range(tod.size):
        cands = rmc.get(tod[i], [])
        if cands:
            o, d, ve, vn = min(cands, key=lambda c: abs(c[0] - order[i]))
            if d is not None:
                days[i] = d.astype(np.int64)
            if ve is not None:
                vel[i] = (ve, vn)
        if np.isnan(vel[i, 0]) and order[i] in vtg:
            vel[i] = vtg[order[i]]
    known = days != np.iinfo(np.int64).min
    base = "gps"
    if not known.any():
        if date0 is None:
            base = "utc_sod"
            days[:] = 0
        else:
            days[0] = date0.astype(np.int64)
            known[0] = True
    if known.any():
        first = int(np.flatnonzero(known)[0])
        for i in range(first + 1, tod.size):  # forward
            if not known[i]:
                days[i] = days[i - 1] + (1 if tod[i] < tod[i - 1] - 43200 else 0)
        for i in range(first - 1, -1, -1):  # backward
            days[i] = days[i + 1] - (1 if tod[i] > tod[i + 1] + 43200 else 0)
    elif base == "utc_sod":
        for i in range(1, tod.size):
            days[i] = days[i - 1] + (1 if tod[i] < tod[i - 1] - 43200 else 0)

    if base == "gps":
        utc = days.astype("datetime64[D]").astype("datetime64[ns]") + \
            np.round(tod * 1e9).astype(np.int64).astype("timedelta64[ns]")
        t = gps_seconds_from_utc(utc)
    else:
        t = days * 86400.0 + tod
    t, line_no, vel, sel = t[fixed], line_no[fixed], vel[fixed], np.flatnonzero(fixed)
    if not t.size:
        raise InputFormatError("no GGA epoch with a GNSS fix", file=path, row=int(line_no.min())
                               if line_no.size else 1, column="quality",
                               expected="fix quality 1-5 or 9", found="only 0/6/7/8")
    g = [gga[i] for i in sel]
    out = {"lat": np.radians([x[3] for x in g]), "lon": np.radians([x[4] for x in g]),
           "height": np.array([x[5] for x in g], float)}
    sd = np.array([gst.get(x[2], (np.nan,) * 3) for x in g], float).reshape(-1, 3)
    qn = np.array([x[7] for x in g], np.int64)
    from_gst = np.isfinite(sd).all(axis=1)
    from_dop = np.zeros(len(g), bool)
    if uere is not None:  # sigmas from the DOP where GST gives none (module docstring)
        hdop = np.array([x[9] for x in g], float)
        vdop = np.array([gsa.get(x[0], np.nan) for x in g], float)
        vdop = np.where(np.isfinite(vdop), vdop, VDOP_PER_HDOP * hdop)
        ue = np.array([uere.get(int(v), np.nan) for v in qn], float)
        from_dop = ~from_gst & np.isfinite(hdop * ue) & (hdop > 0)
        h = hdop * ue / np.sqrt(2.0)
        sd[from_dop] = np.column_stack([h, h, vdop * ue])[from_dop]
    extra = {"std_source": {"gst": int(from_gst.sum()), "hdop": int(from_dop.sum()),
                            "none": int((~from_gst & ~from_dop).sum())}}
    if np.isfinite(sd).any():
        out.update(east_std=sd[:, 1], north_std=sd[:, 0], up_std=sd[:, 2])
        extra["missing_std_rows"] = [int(r) for r in line_no[~np.isfinite(sd[:, 0])]]
    out["q"] = np.array([NMEA_TO_Q[int(v)] for v in qn], np.int64)
    out["fix_quality"] = qn
    out["ns"] = np.array([x[8] for x in g], float)
    out["hdop"] = np.array([x[9] for x in g], float)
    if np.isfinite(vel).any():
        out.update(vel_e=vel[:, 0], vel_n=vel[:, 1])
        extra["missing_velocity_rows"] = [int(r) for r in line_no[~np.isfinite(vel[:, 0])]]
    keep, dups = check_time_order(t, line_no, path, column="time", duplicates=duplicates)
    df = pd.DataFrame(out, index=pd.Index(t, name="time"))
    if dups:
        df, line_no = df.loc[keep], line_no[keep]
    with_sep = all(x[6] for x in g)
    return finish_attrs(df, file=path, fmt="nmea", time_base=base, line_no=line_no,
                        time_column="time", dropped_duplicates=dups, skipped_lines=skipped,
                        dropped_no_fix=dropped_no_fix,
                        height_reference="ellipsoid" if with_sep else "msl", **extra)
