"""RTKLIB solution files (``.pos``) and time-tag files (``.tag``).

``.pos`` (RTKLIB ``outsol`` text format)
----------------------------------------
Comment/header lines start with ``%``; the last one before the data names the columns, e.g.::

    %  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m) ...

Supported variants:

- time: calendar ``yyyy/mm/dd hh:mm:ss.sss`` or GPS ``week  seconds-of-week``; time system
  GPST, UTC (leap seconds applied) or JST (UTC + 9 h), from the header label;
- position: ``latitude(deg) longitude(deg) height(m)`` (decimal degrees), the same in
  degrees-minutes-seconds (``latitude(d'")``, three fields each), or ``x-ecef(m) y-ecef(m)
  z-ecef(m)``; ENU baselines are rejected (no absolute position);
- columns ``Q ns sdn sde sdu sdne sdeu sdun age ratio`` (or ``sdx sdy sdz sdxy sdyz sdzx``),
  optionally followed by velocities ``vn ve vu sdvn sdve sdvu ...`` (or ``vx vy vz sdvx ...``).

Without a header line the default decimal-degree layout is assumed. RTKLIB writes the
off-diagonal terms as signed square roots (``sdne = sign(c) sqrt(|c|)``); ECEF covariances are
rotated into ENU with :func:`insgnss.earth.ecef_to_enu_matrix` and ECEF velocities likewise.

Output: GNSS table (DESIGN.md) indexed by time, columns ``lat lon height`` [rad, m],
``east_std north_std up_std`` [m], ``q ns age ratio``, and when present
``vel_e vel_n vel_u vel_e_std vel_n_std vel_u_std``. Time is GPS seconds (continuous since
1980-01-06) unless ``time_base`` asks for ``"sow"`` or ``"unix_gpst"``; ``attrs``: ``time_base``,
``gps_week`` (of the first epoch), ``time_system`` (label of the file), ``source``,
``source_rows``, ``dropped_duplicates``.

``.tag`` (RTKLIB stream time tags, binary little-endian)
-------------------------------------------------------
64-byte header: text ``"TIMETAG RTKLIB <version>"`` padded with NULs, the last 4 bytes the tick
count at open (uint32 ``tick_f``); then ``uint32 time`` + ``float64 sec``: the GPST start as
Unix-style seconds; then records ``(uint32 tick [ms since start], file position)`` with a 4-byte
(RTKLIB demo5) or 8-byte file position. For this binary file the error "row" is the 1-based
record number.
"""

from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..earth import ecef_to_enu_matrix, ecef_to_geodetic
from ..errors import ConfigError, InputFormatError, InvalidValueError, TimeOrderError
from ..validate import (
    check_allowed,
    check_finite,
    check_range,
    check_time_order,
    finish_attrs,
    parse_numeric,
    read_text,
    split_lines,
)
from .gpstime import (
    UNIX_GPST_OFFSET,
    from_gps_seconds,
    gps_minus_utc,
    gps_seconds_from_week_sow,
    week_sow_from_gps_seconds,
)

LLH_NAMES = ["latitude(deg)", "longitude(deg)", "height(m)", "Q", "ns", "sdn(m)", "sde(m)",
             "sdu(m)", "sdne(m)", "sdeu(m)", "sdun(m)", "age(s)", "ratio"]
VEL_NAMES = ["vn(m/s)", "ve(m/s)", "vu(m/s)", "sdvn", "sdve", "sdvu", "sdvne", "sdveu", "sdvun"]
TIME_SYSTEMS = ("GPST", "UTC", "JST")
RTKLIB_Q = (1, 2, 3, 4, 5, 6)
_STAMP = re.compile(r"^(\d{4})/(\d{1,2})/(\d{1,2})\s+(\d{1,2}):(\d{1,2}):(\d{1,2}(?:\.\d*)?)$")


def _key(name: str) -> str:
    return name.split("(")[0].lower()


def _header(comments, first_data_line: int) -> tuple[str, list[str]] | None:
    """Time-system label and column names of the last column-header comment before the data."""
    for line_no, text in reversed(comments):
        if line_no > first_data_line:
            continue
        tok = text.lstrip("%").split()
        if tok and tok[0].upper() in TIME_SYSTEMS and len(tok) > 1:
            return tok[0].upper(), tok[1:]
    return None


def _days_from_civil(y, m, d):
    """Days since 1970-01-01 of proleptic Gregorian dates (vectorised integer arithmetic)."""
    y = y - (m <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    doy = (153 * (m + np.where(m > 2, -3, 9)) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def _header_line(rows) -> int | None:
    before = [n for n, _ in rows.comments if n < int(rows.line_no[0])]
    return before[-1] if before else None


def _calendar_seconds(stamps, line_no, file, system: str) -> np.ndarray:
    """GPS seconds of ``"yyyy/mm/dd hh:mm:ss.sss"`` stamps in ``system`` (GPST, UTC, JST)."""
    parts = []
    for i, s in enumerate(stamps):
        m = _STAMP.match(s)
        if m is None:
            raise InputFormatError("invalid date/time", file=file, row=int(line_no[i]),
                                   column=system, expected="yyyy/mm/dd hh:mm:ss.sss",
                                   found=repr(s[:40]))
        parts.append(m.groups())
    y, mo, d, h, mi = (np.array([int(p[k]) for p in parts], np.int64) for k in range(5))
    sec = np.array([float(p[5]) for p in parts])
    days = _days_from_civil(y, mo, d)
    ny, nm = np.where(mo == 12, y + 1, y), np.where(mo == 12, 1, mo + 1)
    month_len = _days_from_civil(ny, nm, np.ones_like(d)) - _days_from_civil(y, mo, np.ones_like(d))
    bad = (mo < 1) | (mo > 12) | (d < 1) | (d > month_len) | (h > 23) | (mi > 59) | (sec >= 61) \
        | (y < 1980)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputFormatError("invalid date/time", file=file, row=int(line_no[i]), column=system,
                               expected="a valid calendar time after 1980", found=repr(stamps[i]))
    whole = days * 86400 + h * 3600 + mi * 60  # seconds since 1970-01-01 on the file's scale
    if system == "JST":
        whole = whole - 9 * 3600
    if system == "GPST":
        return (whole - int(UNIX_GPST_OFFSET)) + sec
    leap = gps_minus_utc(whole.astype("datetime64[s]"))
    return (whole - int(UNIX_GPST_OFFSET)) + sec + leap


def read_rtklib_pos(path: str | os.PathLike, *, time_base: str = "gps",
                    duplicates: str = "drop") -> pd.DataFrame:
    """Read an RTKLIB ``.pos`` solution into a GNSS table (see the module docstring).

    Parameters
    ----------
    path : path
    time_base : {"gps", "sow", "unix_gpst"}
        Time base of the returned index (default GPS seconds).
    duplicates : {"drop", "error"}
        Repeated epochs: dropped with a warning (recorded) or an error.
    """
    if time_base not in ("gps", "sow", "unix_gpst"):
        raise ConfigError("unknown time base", column="time_base",
                          expected="'gps', 'sow' or 'unix_gpst'", found=repr(time_base))
    rows = split_lines(read_text(path), path, comment=("%",))
    head = _header(rows.comments, int(rows.line_no[0]))
    system, names = head if head else ("GPST", None)
    first = rows.lines[0].split()
    calendar = bool(first) and "/" in first[0]
    time_names = ["date", "time"] if calendar else ["week", "tow"]
    if names is None:
        n = len(first) - 2
        names = LLH_NAMES + VEL_NAMES if n == len(LLH_NAMES) + len(VEL_NAMES) else LLH_NAMES
    k0 = _key(names[0])
    if names[0].startswith("latitude(d'"):
        fields = [f"{names[0]} {p}" for p in ("deg", "min", "sec")] + \
                 [f"{names[1]} {p}" for p in ("deg", "min", "sec")] + names[2:]
        pos = "dms"
    elif k0 == "latitude":
        fields, pos = list(names), "llh"
    elif k0 == "x-ecef":
        fields, pos = list(names), "ecef"
    else:
        raise InputFormatError("unsupported solution format", file=path,
                               row=_header_line(rows) or 1,
                               column=names[0],
                               expected="latitude/longitude/height or x/y/z-ecef columns",
                               found=repr(names[0]))
    ntok = 2 + len(fields)
    values = parse_numeric(rows, fields, delimiter=None, usecols=range(2, ntok), ncols=ntok)
    file = path
    line_no = rows.line_no
    check_finite(values, fields, line_no, file)
    if calendar:
        stamps = [" ".join(s.split(None, 2)[:2]) for s in rows.lines]
        t = _calendar_seconds(stamps, line_no, file, system)
    else:
        wt = parse_numeric(rows, time_names, delimiter=None, usecols=[0, 1], ncols=ntok)
        check_finite(wt, time_names, line_no, file)
        check_range(wt[:, 0], 0, 9999, "week", line_no, file)
        check_range(wt[:, 1], 0, 604800, "tow", line_no, file, unit="s")
        t = gps_seconds_from_week_sow(wt[:, 0], wt[:, 1])
        if system != "GPST":
            raise InputFormatError("week/seconds time must be GPST", file=path,
                                   row=_header_line(rows), column=system, expected="GPST",
                                   found=system)
    col = {_key(f): i for i, f in enumerate(fields)}
    need = {"llh": ("latitude", "longitude", "height"), "dms": ("height",),
            "ecef": ("x-ecef", "y-ecef", "z-ecef")}[pos]
    for name in need:
        if name not in col:
            raise InputFormatError("missing column", file=path, row=_header_line(rows),
                                   column=name, expected=f"a column {name!r}",
                                   found=", ".join(fields))

    def get(name):
        return values[:, col[name]] if name in col else None

    out = {}
    if pos == "ecef":
        xyz = np.column_stack([get("x-ecef"), get("y-ecef"), get("z-ecef")])
        r = np.linalg.norm(xyz, axis=1)
        check_range(r, 6.0e6, 7.0e6, "x-ecef(m)", line_no, file, unit="m from the Earth's centre")
        lat, lon, h = ecef_to_geodetic(xyz[:, 0], xyz[:, 1], xyz[:, 2])
        R = np.stack([ecef_to_enu_matrix(a, b) for a, b in zip(lat, lon, strict=True)])
        out.update(lat=lat, lon=lon, height=h)
        std_names = ("sdx", "sdy", "sdz", "sdxy", "sdyz", "sdzx")
    else:
        if pos == "dms":
            lat_d = _dms(values[:, 0:3])
            lon_d = _dms(values[:, 3:6])
            lat_name, lon_name = fields[0], fields[3]
        else:
            lat_d, lon_d = get("latitude"), get("longitude")
            lat_name, lon_name = fields[0], fields[1]
        check_range(lat_d, -90, 90, lat_name, line_no, file, unit="deg")
        check_range(lon_d, -180, 360, lon_name, line_no, file, unit="deg")
        out.update(lat=np.radians(lat_d), lon=np.radians(lon_d), height=get("height"))
        std_names = ("sdn", "sde", "sdu", "sdne", "sdeu", "sdun")
    check_range(out["height"], -1e4, 1e6, "height(m)" if pos != "ecef" else "z-ecef(m)",
                line_no, file, unit="m")
    for name in std_names[:3]:
        if name not in col:
            raise InputFormatError("missing column", file=path, row=_header_line(rows), column=name,
                                   expected=f"a column {name!r}", found=", ".join(fields))
        check_range(get(name), 0, 1e7, fields[col[name]], line_no, file, unit="m")
    sd = [get(n) if n in col else np.zeros(len(t)) for n in std_names]
    if pos == "ecef":
        cov = _cov_from_sd(*sd)
        cov_enu = R @ cov @ np.swapaxes(R, 1, 2)
        out["east_std"], out["north_std"], out["up_std"] = (
            np.sqrt(np.maximum(cov_enu[:, i, i], 0.0)) for i in range(3))
    else:
        out["east_std"], out["north_std"], out["up_std"] = sd[1], sd[0], sd[2]
    for name, dst in (("q", "q"), ("ns", "ns")):
        if name in col:
            out[dst] = get(name)
    if "q" in out:
        check_allowed(out["q"], RTKLIB_Q, fields[col["q"]], line_no, file)
        out["q"] = out["q"].astype(np.int64)
    if "ns" in out:
        check_range(out["ns"], 0, 255, fields[col["ns"]], line_no, file)
        out["ns"] = np.round(out["ns"]).astype(np.int64)
    vel_keys = ("vx", "vy", "vz") if pos == "ecef" else ("vn", "ve", "vu")
    if all(k in col for k in vel_keys):
        v = np.column_stack([get(k) for k in vel_keys])
        vs_names = ("sdvx", "sdvy", "sdvz", "sdvxy", "sdvyz", "sdvzx") if pos == "ecef" else \
            ("sdvn", "sdve", "sdvu", "sdvne", "sdveu", "sdvun")
        for name in vs_names[:3]:
            if name in col:
                check_range(get(name), 0, 1e4, fields[col[name]], line_no, file, unit="m/s")
        vsd = [get(n) if n in col else np.zeros(len(t)) for n in vs_names]
        if pos == "ecef":
            venu = np.einsum("nij,nj->ni", R, v)
            cov = R @ _cov_from_sd(*vsd) @ np.swapaxes(R, 1, 2)
            vstd = [np.sqrt(np.maximum(cov[:, i, i], 0.0)) for i in range(3)]
        else:
            venu = np.column_stack([v[:, 1], v[:, 0], v[:, 2]])  # (vn, ve, vu) -> (ve, vn, vu)
            vstd = [vsd[1], vsd[0], vsd[2]]
        out.update(vel_e=venu[:, 0], vel_n=venu[:, 1], vel_u=venu[:, 2],
                   vel_e_std=vstd[0], vel_n_std=vstd[1], vel_u_std=vstd[2])
    for name in ("age", "ratio"):
        if name in col:
            out[name] = get(name)

    keep, dropped = check_time_order(t, line_no, file, column=system, duplicates=duplicates)
    df = pd.DataFrame(out, index=pd.Index(t, name="time"))
    if dropped:
        df = df.loc[keep]
        line_no = line_no[keep]
    week0 = int(week_sow_from_gps_seconds(df.index[:1].to_numpy())[0][0])
    df.index = pd.Index(from_gps_seconds(df.index.to_numpy(), time_base, week0), name="time")
    return finish_attrs(df, file=path, fmt="rtklib-pos", time_base=time_base, line_no=line_no,
                        time_column=system, gps_week=week0, time_system=system,
                        dropped_duplicates=dropped)


def _dms(v: np.ndarray) -> np.ndarray:
    sign = np.where((v[:, 0] < 0) | ((v[:, 0] == 0) & (np.signbit(v[:, 0]))), -1.0, 1.0)
    return sign * (np.abs(v[:, 0]) + v[:, 1] / 60.0 + v[:, 2] / 3600.0)


def _cov_from_sd(s1, s2, s3, s12, s23, s31) -> np.ndarray:
    """Covariance matrices from RTKLIB standard deviations (off-diagonals as signed roots)."""
    c = np.empty((len(s1), 3, 3))
    c[:, 0, 0], c[:, 1, 1], c[:, 2, 2] = s1 * s1, s2 * s2, s3 * s3
    c12, c23, c31 = (np.sign(s) * s * s for s in (s12, s23, s31))
    c[:, 0, 1] = c[:, 1, 0] = c12
    c[:, 1, 2] = c[:, 2, 1] = c23
    c[:, 2, 0] = c[:, 0, 2] = c31
    return c


# --------------------------------------------------------------------------------------------
# time tags
# --------------------------------------------------------------------------------------------

TAG_HEADER_LEN = 64
TAG_MAGIC = b"TIMETAG RTKLIB"


@dataclass(frozen=True)
class TimeTag:
    """Contents of an RTKLIB ``.tag`` file.

    Attributes
    ----------
    file : Path
    version : str
        Header text after ``TIMETAG RTKLIB``.
    tick_f : int
        Tick count at file open (as written).
    start : float
        GPS seconds of tick 0 (the stream's start time).
    ticks : (N,) int array
        Milliseconds since ``start`` of each record.
    fpos : (N,) int array
        File position of each record in the tagged stream.
    """

    file: Path
    version: str
    tick_f: int
    start: float
    ticks: np.ndarray
    fpos: np.ndarray

    @property
    def end(self) -> float:
        """GPS seconds of the last record: ``start + ticks[-1] / 1000``."""
        return self.start + float(self.ticks[-1]) / 1000.0

    @property
    def start_unix_gpst(self) -> float:
        """Start as Unix-style GPST seconds (as stored in the file)."""
        return self.start + UNIX_GPST_OFFSET


def read_rtklib_tag(path: str | os.PathLike) -> TimeTag:
    """Read an RTKLIB time-tag file (see the module docstring)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputFormatError("time-tag file not found", file=path) from None
    except OSError as e:
        raise InputFormatError(f"cannot read the file ({e.strerror or e})", file=path) from None
    if not data.startswith(TAG_MAGIC):
        raise InputFormatError("not an RTKLIB time-tag file", file=path, column="header",
                               expected=repr(TAG_MAGIC.decode()), found=repr(data[:14]))
    if len(data) < TAG_HEADER_LEN + 12:
        raise InputFormatError("truncated time-tag file", file=path, column="header",
                               expected=f"at least {TAG_HEADER_LEN + 12} bytes",
                               found=f"{len(data)} bytes")
    version = data[len(TAG_MAGIC):TAG_HEADER_LEN - 4].split(b"\x00")[0].decode("ascii", "replace")
    tick_f = struct.unpack_from("<I", data, TAG_HEADER_LEN - 4)[0]
    time_s, sec = struct.unpack_from("<Id", data, TAG_HEADER_LEN)
    if not (np.isfinite(sec) and 0.0 <= sec < 1.0 and time_s >= UNIX_GPST_OFFSET):
        raise InvalidValueError("invalid start time in the time-tag header", file=path,
                                column="time", expected="GPST after 1980 and 0 <= sec < 1",
                                found=f"time={time_s}, sec={sec!r}")
    body = data[TAG_HEADER_LEN + 12:]
    if not body:
        raise InputFormatError("no time-tag records", file=path, column="records",
                               expected="at least one (tick, file position) record", found="none")
    sizes = [size for size in (8, 12) if len(body) % size == 0]
    if not sizes:
        raise InputFormatError("truncated time-tag record", file=path, row=len(body) // 8 + 1,
                               column="records", expected="8- or 12-byte records",
                               found=f"{len(body)} bytes of records")
    failure = None
    for size in sizes:
        rec = np.frombuffer(body, dtype=np.dtype([("tick", "<u4"),
                                                  ("fpos", "<u4" if size == 8 else "<u8")]))
        ticks, fpos = rec["tick"].astype(np.int64), rec["fpos"].astype(np.int64)
        bad_t = np.flatnonzero(np.diff(ticks) < 0)
        bad_f = np.flatnonzero(np.diff(fpos) < 0)
        if not bad_t.size and not bad_f.size:
            break
        if failure is None:
            k = int(bad_t[0] if bad_t.size else bad_f[0]) + 1
            arr = ticks if bad_t.size else fpos
            failure = (k, "tick" if bad_t.size else "fpos", int(arr[k - 1]), int(arr[k]))
    else:
        k, name, prev, cur = failure
        raise TimeOrderError("time-tag records out of order", file=path, row=k + 1, column=name,
                             expected=f">= {prev}", found=str(cur))
    start = float(time_s) - UNIX_GPST_OFFSET + float(sec)
    return TimeTag(path, version.strip(), int(tick_f), start, ticks, fpos)
