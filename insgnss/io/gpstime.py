"""GPS time scales used by the readers.

insgnss readers of absolutely time-stamped data return time as **GPS seconds**: seconds since
the GPS epoch 1980-01-06T00:00:00 GPST, continuous (no leap seconds), as float64 (resolution
about 0.2 us today). The table's ``attrs["time_base"]`` says which base a table uses:

``"gps"``
    GPS seconds (default of the absolute-time readers);
``"sow"``
    GPS seconds of week; ``attrs["gps_week"]`` holds the week of the first sample (a table that
    crosses a week boundary keeps counting past 604800 s so that time stays continuous);
``"unix_gpst"``
    "Unix-style GPST": seconds since 1970-01-01 on the GPST scale, as RTKLIB ``.tag`` files and
    the rtklibexplorer scripts use (``gps = unix_gpst - 315964800``);
``"utc_sod"``
    UTC seconds of day (NMEA without a date);
``"relative"`` / ``"unspecified"``
    a sensor's own clock, declared by the user.

UTC is converted to GPST with the leap-second table below (GPS - UTC = 18 s since 2017-01-01).
"""

from __future__ import annotations

import numpy as np

#: seconds in a GPS week
WEEK_SECONDS = 604800.0
#: GPS epoch as numpy datetime64
GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
#: GPS seconds = Unix-style GPST seconds - UNIX_GPST_OFFSET
UNIX_GPST_OFFSET = 315964800.0
#: time bases a table may declare in ``attrs["time_base"]``
TIME_BASES = ("gps", "sow", "unix_gpst", "utc_sod", "relative", "unspecified")

#: (UTC date from which it applies, GPS - UTC [s])
LEAP_SECONDS = (
    ("1981-07-01", 1), ("1982-07-01", 2), ("1983-07-01", 3), ("1985-07-01", 4),
    ("1988-01-01", 5), ("1990-01-01", 6), ("1991-01-01", 7), ("1992-07-01", 8),
    ("1993-07-01", 9), ("1994-07-01", 10), ("1996-01-01", 11), ("1997-07-01", 12),
    ("1999-01-01", 13), ("2006-01-01", 14), ("2009-01-01", 15), ("2012-07-01", 16),
    ("2015-07-01", 17), ("2017-01-01", 18),
)
_LEAP_DATES = np.array([np.datetime64(d, "ns") for d, _ in LEAP_SECONDS])
_LEAP_VALUES = np.array([v for _, v in LEAP_SECONDS], dtype=float)


def gps_seconds_from_datetime64(t: np.ndarray) -> np.ndarray:
    """GPS seconds from GPST calendar times (``datetime64``, any unit)."""
    ns = (np.asarray(t, dtype="datetime64[ns]") - GPS_EPOCH).astype(np.int64)
    whole, frac = np.divmod(ns, 1_000_000_000)
    return whole.astype(float) + frac * 1e-9


def datetime64_from_gps_seconds(t) -> np.ndarray:
    """GPST calendar times (``datetime64[ns]``) from GPS seconds."""
    t = np.asarray(t, float)
    whole = np.floor(t)
    ns = whole.astype(np.int64) * 1_000_000_000 + np.round((t - whole) * 1e9).astype(np.int64)
    return GPS_EPOCH + ns.astype("timedelta64[ns]")


def gps_minus_utc(t_utc: np.ndarray) -> np.ndarray:
    """GPS - UTC [s] at UTC calendar times ``t_utc`` (``datetime64``)."""
    t = np.asarray(t_utc, dtype="datetime64[ns]")
    k = np.searchsorted(_LEAP_DATES, t, side="right")
    return np.where(k > 0, _LEAP_VALUES[np.maximum(k - 1, 0)], 0.0)


def gps_seconds_from_utc(t_utc: np.ndarray) -> np.ndarray:
    """GPS seconds from UTC calendar times (``datetime64``), leap seconds applied."""
    return gps_seconds_from_datetime64(t_utc) + gps_minus_utc(t_utc)


def utc_from_gps_seconds(t) -> np.ndarray:
    """UTC calendar times (``datetime64[ns]``) from GPS seconds, leap seconds removed (the
    inverse of :func:`gps_seconds_from_utc`)."""
    gpst = datetime64_from_gps_seconds(t)
    leap = gps_minus_utc(gpst)  # GPS - UTC at a time at most 18 s late: iterate once
    leap = gps_minus_utc(gpst - (leap * 1e9).astype("timedelta64[ns]"))
    return gpst - (leap * 1e9).astype("timedelta64[ns]")


def gps_seconds_from_week_sow(week, sow) -> np.ndarray:
    """GPS seconds from GPS week and seconds of week."""
    return np.asarray(week, float) * WEEK_SECONDS + np.asarray(sow, float)


def week_sow_from_gps_seconds(t) -> tuple[np.ndarray, np.ndarray]:
    """GPS week (int) and seconds of week from GPS seconds."""
    t = np.asarray(t, float)
    week = np.floor(t / WEEK_SECONDS).astype(np.int64)
    return week, t - week * WEEK_SECONDS


def from_gps_seconds(t, base: str, week: int | None = None) -> np.ndarray:
    """Express GPS seconds ``t`` in ``base`` (``"gps"``, ``"sow"`` or ``"unix_gpst"``).

    For ``"sow"`` the week defaults to the week of the first sample.
    """
    t = np.asarray(t, float)
    if base == "gps":
        return t.copy()
    if base == "unix_gpst":
        return t + UNIX_GPST_OFFSET
    if base == "sow":
        if week is None:
            week = int(week_sow_from_gps_seconds(t[:1])[0][0]) if t.size else 0
        return t - week * WEEK_SECONDS
    raise ValueError(f"cannot express GPS seconds in time base {base!r}")


def to_gps_seconds(t, base: str, week: int | None = None) -> np.ndarray:
    """Convert times in ``base`` (``"gps"``, ``"sow"`` + ``week``, ``"unix_gpst"``) to GPS seconds."""
    t = np.asarray(t, float)
    if base == "gps":
        return t.copy()
    if base == "unix_gpst":
        return t - UNIX_GPST_OFFSET
    if base == "sow":
        if week is None:
            raise ValueError("time base 'sow' needs the GPS week")
        return t + week * WEEK_SECONDS
    raise ValueError(f"cannot convert time base {base!r} to GPS seconds")
