"""The processing window of a job (``[job] start`` / ``end``, like KF-GINS's ``starttime`` /
``endtime``): the part of the recording a run processes. Every input (IMU, GNSS, odometer,
reference, control points, a simulation's truth) is cut to it before anything else happens,
so the initialization, the aiding, the evaluation and the outputs see only the window.

A window end is given as

- a number: a time in the job's time base, the numbers of the files' time stamps [s] (GPS
  seconds, seconds of week, ...);
- ``"+SECONDS"``: that many seconds after the first IMU sample of the recording;
- a GPS time ``"YYYY-MM-DD hh:mm:ss[.fff]"`` (GPST, not UTC) for the time bases that know the
  date: ``gps`` (GPS seconds since 1980-01-06), ``sow`` (seconds of that GPS week) and
  ``unix_gpst``.

Outage windows stay where the whole recording puts them (``outages.relative_to =
"first_gnss"`` counts from the first GNSS epoch of the file, not of the window), so a
benchmark's outages do not move when the window does.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..config import Job
from ..errors import ConfigError
from .inputs import Inputs

#: the inputs cut to the window (the IMU first)
TABLES = ("imu", "gnss", "odometer", "reference", "control_points", "truth", "sensor_truth")


def window_time(value, t_first: float, time_base: str, key: str, file=None) -> float | None:
    """A window end (module docstring) as a time in the job's time base [s]."""
    from ..io.gpstime import UNIX_GPST_OFFSET, WEEK_SECONDS, gps_seconds_from_datetime64

    if value is None:
        return None
    if not isinstance(value, str):
        return float(value)
    text = value.strip()
    if text.startswith("+"):
        return t_first + float(text[1:])
    if time_base not in ("gps", "sow", "unix_gpst"):
        raise ConfigError("a GPS time needs a job time base that knows the date", file=file,
                          column=key, expected="job.time_base = 'gps', 'sow' or 'unix_gpst', "
                          "or a number / '+SECONDS'", found=f"{value!r} with time_base = "
                          f"{time_base!r}")
    t = float(gps_seconds_from_datetime64(np.array([np.datetime64(text.replace(" ", "T"),
                                                                  "ns")]))[0])
    if time_base == "sow":
        return t % WEEK_SECONDS
    if time_base == "unix_gpst":
        return t + UNIX_GPST_OFFSET
    return t


def processing_window(job: Job, imu: pd.DataFrame) -> tuple[float, float] | None:
    """``(start, end)`` of ``[job] start`` / ``end`` over the IMU table (None: the whole
    recording). Raises :class:`~insgnss.errors.ConfigError` naming the key when the window
    holds no IMU data or ends before it starts."""
    j = job["job"]
    if j["start"] is None and j["end"] is None:
        return None
    file = None if job.path is None else str(job.path)
    t = imu.index.to_numpy(float)
    base = job["job"]["time_base"]
    t0 = window_time(j["start"], float(t[0]), base, "job.start", file)
    t1 = window_time(j["end"], float(t[0]), base, "job.end", file)
    if t0 is not None and t1 is not None and not t0 < t1:
        raise ConfigError("the processing window ends before it starts", file=file,
                          column="job.end", expected=f"end > start = {t0!r}", found=repr(t1))
    t0 = float(t[0]) if t0 is None else t0
    t1 = float(t[-1]) if t1 is None else t1
    n = int(np.count_nonzero((t >= t0) & (t <= t1)))
    if n < 2:
        raise ConfigError("the processing window holds no IMU data", file=file,
                          column="job.start" if t0 > t[-1] else "job.end",
                          expected=f"a window overlapping the IMU data {t[0]!r} .. {t[-1]!r}",
                          found=f"{t0!r} .. {t1!r}")
    return t0, t1


def cut_inputs(inputs: Inputs, window: tuple[float, float]) -> Inputs:
    """``inputs`` with every table cut to ``window`` (their ``attrs`` kept)."""
    t0, t1 = window
    for name in TABLES:
        df = getattr(inputs, name)
        if df is None or not len(df):
            continue
        t = df.index.to_numpy(float)
        if not np.all(np.isfinite(t)):  # position-triggered control points: no time
            continue
        cut = df[(t >= t0) & (t <= t1)]
        cut.attrs = dict(df.attrs)
        if "source_rows" in df.attrs and len(df.attrs["source_rows"]) == len(df):
            cut.attrs["source_rows"] = np.asarray(df.attrs["source_rows"])[(t >= t0) & (t <= t1)]
        setattr(inputs, name, cut)
    return inputs


__all__ = ["cut_inputs", "processing_window", "window_time"]
