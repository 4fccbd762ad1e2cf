"""Job-level input policies: IMU gaps and duplicated samples.

The readers validate what they read (:mod:`insgnss.validate`, docs/formats.md); the pipeline
applies the same policies once more to the IMU table it is about to process, so that tables
that did not come from a reader (simulation, data modified in memory, a native CSV) get the same
treatment and every run reports what was repaired (``summary.json`` ``"imu"``):

- **time order**: a time stamp going backwards is a :class:`~insgnss.errors.TimeOrderError`;
  repeated stamps are dropped with a warning (``inputs.imu.duplicates = "drop"``, the first is
  kept) or are an error (``"error"``);
- **gaps**: an interval longer than 1.5 nominal sample intervals (``attrs["nominal_dt"]`` from
  the declared rate, else the median interval) is a gap, unless it is the clock's recurring
  time-stamp jitter (:func:`insgnss.validate.gap_threshold`). Gaps up to ``inputs.imu.max_gap``
  seconds are bridged with a warning (the mechanization integrates across them) and recorded.
  Longer gaps follow ``inputs.imu.gap_policy``: ``"error"`` (default) stops with a
  :class:`~insgnss.errors.DataGapError` naming the file and row after the gap, ``"bridge"``
  bridges them too, ``"split"`` processes the contiguous segments as separate runs
  (:mod:`insgnss.job.segments`);
- **single-sample spikes** (``inputs.imu.spike_policy``, :func:`apply_spike_policy`; off by
  default): a sample whose gyro or accelerometer vector departs from the mean of its two
  neighbours by more than :data:`SPIKE_FACTOR` times the recording's 99.9th percentile of the
  sample-to-sample change, while the two neighbours agree with each other to within
  ``1 / SPIKE_FACTOR`` of that departure, is a spike (a bit error, a logger glitch: no motion
  changes the rate for one sample only). ``"flag"`` warns and lists them (``summary.json``
  ``"imu"`` ``"spikes"``), ``"bridge"`` also replaces each by the mean of its neighbours.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from .config import Job
from .imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS, RATE_COLS
from .validate import GapPolicy, apply_gap_policy, check_time_order, find_gaps, warn

#: a single-sample spike departs from its neighbours by this many times the recording's
#: 99.9th percentile of the sample-to-sample change (module docstring)
SPIKE_FACTOR = 10.0


def gap_policy(job: Job) -> GapPolicy:
    """The job's IMU gap policy (``inputs.imu.gap_policy``, ``inputs.imu.max_gap``)."""
    spec = job["inputs"]["imu"]
    return GapPolicy(max_bridge=float(spec["max_gap"]), long=spec["gap_policy"])


def _where(imu: pd.DataFrame) -> tuple[str, np.ndarray]:
    """File label and row numbers for messages: the file's lines when the table is as read,
    else 1-based sample numbers of the table (data built or modified in memory)."""
    src = imu.attrs.get("source")
    rows = imu.attrs.get("source_rows")
    if src and rows is not None and len(rows) == len(imu):
        return str(src), np.asarray(rows, np.int64)
    label = f"IMU table from {src} (rows are sample numbers)" if src else \
        "IMU table (rows are sample numbers)"
    return label, np.arange(len(imu), dtype=np.int64) + 1


def check_imu_table(imu: pd.DataFrame, policy: GapPolicy, duplicates: str = "drop"
                    ) -> tuple[pd.DataFrame, dict]:
    """Apply the time-order, duplicate and gap policies to an IMU table about to be processed.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments) indexed by time [s].
    policy : GapPolicy
    duplicates : {"drop", "error"}

    Returns
    -------
    imu : DataFrame
        The table without dropped duplicates; ``attrs`` ``gaps``, ``segments`` and
        ``dropped_duplicates`` describe this table.
    report : dict
        ``{"gaps": [...], "dropped_duplicates": [...], "segments": [[t0, t1], ...],
        "nominal_dt": s}`` (rows are the file's lines when the table came from a reader, else
        1-based sample numbers). Warnings are emitted only for problems the reader has not
        already announced.
    """
    file, rows = _where(imu)
    t = np.asarray(imu.index, float)
    col = imu.attrs.get("time_column", "time")
    keep, dropped = check_time_order(t, rows, file, column=col, duplicates=duplicates)  # warns
    if dropped:
        attrs = dict(imu.attrs)
        imu = imu.loc[keep]
        imu.attrs = attrs
        t, rows = t[keep], rows[keep]
    dropped = list(imu.attrs.get("dropped_duplicates") or []) + dropped  # the reader's + these
    nominal = imu.attrs.get("nominal_dt")
    if not nominal or not np.isfinite(nominal) or nominal <= 0:
        nominal = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    gaps = find_gaps(t, rows, nominal, policy.factor) if t.size > 1 else []
    known = {round(float(g["start"]), 9) for g in imu.attrs.get("gaps") or []}
    new = [g for g in gaps if round(g["start"], 9) not in known]
    if new:
        apply_gap_policy(new, policy, file, float(t[0]), float(t[-1]), column=col)  # warns/raises
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gaps, segments = apply_gap_policy(gaps, policy, file, float(t[0]), float(t[-1]),
                                          column=col)
    out = imu.copy(deep=False)
    out.attrs = dict(imu.attrs)
    out.attrs.update(gaps=gaps, segments=segments, dropped_duplicates=dropped,
                     nominal_dt=float(nominal))
    report = {"nominal_dt": float(nominal), "gaps": gaps,
              "bridged_s": float(sum(g["duration"] for g in gaps if g["action"] == "bridged")),
              "dropped_duplicates": dropped,
              "segments": [[float(a), float(b)] for a, b in segments]}
    return out, report


def find_spikes(x: np.ndarray) -> np.ndarray:
    """Indices of the single-sample spikes of the vector series ``x`` (N, 3) (module
    docstring)."""
    x = np.asarray(x, float)
    if x.shape[0] < 5:
        return np.zeros(0, np.int64)
    step = np.linalg.norm(np.diff(x, axis=0), axis=1)
    level = float(np.nanpercentile(step, 99.9))
    dev = np.linalg.norm(x[1:-1] - 0.5 * (x[:-2] + x[2:]), axis=1)
    agree = np.linalg.norm(x[2:] - x[:-2], axis=1)
    spike = (dev > SPIKE_FACTOR * max(level, 1e-12)) & (agree * SPIKE_FACTOR < dev)
    return np.flatnonzero(spike) + 1


def sample_rates(imu: pd.DataFrame, sensor: str) -> tuple[list[str] | None, np.ndarray | None]:
    """The columns of ``sensor`` (``"gyro"`` or ``"accel"``) in an IMU table and its samples
    as rates (N, 3) [rad/s, m/s^2]: the rate columns as they are, increments over their own
    interval (the first over the median interval); ``(None, None)`` without them."""
    rates, incs = (GYRO_COLS, DTHETA_COLS) if sensor == "gyro" else (ACCEL_COLS, DV_COLS)
    if all(c in imu.columns for c in rates):
        return rates, imu[rates].to_numpy(float)
    if not all(c in imu.columns for c in incs) or len(imu) < 2:
        return None, None
    return incs, imu[incs].to_numpy(float) / _sample_intervals(imu)[:, None]


def _sample_intervals(imu: pd.DataFrame) -> np.ndarray:
    """Interval of each sample of an increment table (the first: the median interval)."""
    t = np.asarray(imu.index, float)
    return np.diff(t, prepend=t[0] - float(np.median(np.diff(t))))


def apply_spike_policy(imu: pd.DataFrame, policy: str) -> tuple[pd.DataFrame, list[dict]]:
    """``inputs.imu.spike_policy`` (module docstring): ``"off"`` returns the table as it is;
    ``"flag"`` warns and lists the spikes; ``"bridge"`` also replaces each spiking sensor's
    vector by the mean of its two neighbours. Returns ``(table, spikes)``, each spike ``{"time",
    "row", "sensor", "value", "neighbours", "action"}`` (value and neighbours' mean as vector
    norms in deg/s or m/s^2; an increment table's samples over their own interval)."""
    if policy == "off" or len(imu) < 5:
        return imu, []
    file, rows = _where(imu)
    t = np.asarray(imu.index, float)
    out = imu
    spikes: list[dict] = []
    for sensor, scale in (("gyro", np.degrees(1.0)), ("accel", 1.0)):
        cols, x = sample_rates(imu, sensor)
        if cols is None:
            continue
        k = find_spikes(x)
        if not k.size:
            continue
        mid = 0.5 * (x[k - 1] + x[k + 1])
        for i, kk in enumerate(k):
            spikes.append({"time": float(t[kk]), "row": int(rows[kk]), "sensor": sensor,
                           "value": float(np.linalg.norm(x[kk]) * scale),
                           "neighbours": float(np.linalg.norm(mid[i]) * scale),
                           "action": "bridged" if policy == "bridge" else "flagged"})
        if policy == "bridge":
            if out is imu:
                out = imu.copy()
                out.attrs = dict(imu.attrs)
            vals = out[cols].to_numpy(float, copy=True)
            vals[k] = mid if cols[0] in RATE_COLS else mid * _sample_intervals(imu)[k, None]
            out[cols] = vals
    if spikes:
        first = min(spikes, key=lambda d: d["time"])
        unit = "deg/s" if first["sensor"] == "gyro" else "m/s^2"
        warn(f"{len(spikes)} single-sample IMU spike(s) "
             f"({'replaced by the mean of their neighbours' if policy == 'bridge' else 'kept'}"
             f"; inputs.imu.spike_policy = {policy!r}); the first at t = {first['time']:.6f} s: "
             f"{first['sensor']} {first['value']:.4g} {unit} between neighbours of "
             f"{first['neighbours']:.4g} {unit}", file=file, row=first["row"],
             column="inputs.imu.spike_policy")
    return out, sorted(spikes, key=lambda d: d["time"])


#: moving-average length [s] that removes sensor noise and vibration from the rates before
#: their typical change over a gap is measured (gap_noise)
GAP_SMOOTHING = 0.1


def gap_noise(imu: pd.DataFrame, gaps: list[dict]) -> pd.DataFrame | None:
    """Extra process noise for the bridged gaps of a rate IMU table.

    Across a gap of ``T`` seconds the mechanization integrates the straight line between the
    samples on either side (trapezoid); the motion in between is unknown. The error of the
    mean rate is taken as half the larger of (a) the change across the gap of the rates
    smoothed over :data:`GAP_SMOOTHING` s (the samples' own noise is already in ARW/VRW) and (b)
    the RMS change over ``T`` of the rates smoothed over :data:`GAP_SMOOTHING` s, over the
    whole log (the vehicle's typical dynamics at that time scale, without the sensor noise
    that ARW/VRW already model). Per axis::

        att_std = T * max(|dw_ends|, rms_dw(T)) / 2     vel_std = T * max(|df_ends|, rms_df(T)) / 2
        pos_std = vel_std * T / 2

    Returns a table for :attr:`insgnss.filter.engine.FilterConfig.extra_noise` (time = end of
    each bridged gap) or None (no bridged gap, or an increment table: an accumulating sensor's
    first increment after a gap covers the gap).
    """
    from .imu import ACCEL_COLS, GYRO_COLS

    bridged = [g for g in gaps if g.get("action") == "bridged"]
    if not bridged or GYRO_COLS[0] not in imu.columns:
        return None
    t = np.asarray(imu.index, float)
    w = imu[GYRO_COLS].to_numpy(float)
    f = imu[ACCEL_COLS].to_numpy(float)
    dt = float(np.median(np.diff(t)))
    m = min(max(int(round(GAP_SMOOTHING / dt)), 1), t.size)

    def moving_mean(x):  # mean of x[i:i + m] for i = 0 .. N - m (no edge effects)
        c = np.concatenate([np.zeros((1, 3)), np.cumsum(x, 0)])
        return (c[m:] - c[:-m]) / m

    ws, fs = moving_mean(w), moving_mean(f)
    rows = []
    typical: dict = {}  # lag -> RMS change of the smoothed rates over that lag
    for g in bridged:
        k = int(np.searchsorted(t, g["end"]))
        if k <= 0 or k >= t.size:
            continue
        T = float(g["duration"])
        lag = max(int(round(T / dt)), 1)
        if lag not in typical:
            typical[lag] = (float(np.sqrt(np.mean((ws[lag:] - ws[:-lag]) ** 2))),
                            float(np.sqrt(np.mean((fs[lag:] - fs[:-lag]) ** 2)))) \
                if lag < len(ws) else (0.0, 0.0)
        rms_w, rms_f = typical[lag]
        # smoothed rates just before and just after the gap
        before, after = max(k - m, 0), min(k, len(ws) - 1)
        dw = float(np.max(np.abs(ws[after] - ws[before])))
        df = float(np.max(np.abs(fs[after] - fs[before])))
        vel = T * max(df, rms_f) / 2
        rows.append((t[k], vel * T / 2, vel, T * max(dw, rms_w) / 2))
    if not rows:
        return None
    a = np.asarray(rows)
    return pd.DataFrame({"pos_std": a[:, 1], "vel_std": a[:, 2], "att_std": a[:, 3]},
                        index=pd.Index(a[:, 0], name="time"))


def shift_report(report: dict, dt) -> dict:
    """The report of :func:`check_imu_table` with its times moved by ``dt`` [s], or mapped
    through ``dt`` when it is callable (:class:`insgnss.preprocess.TimeCorrection`: an IMU
    time correction applied after the check)."""
    if not dt:
        return report
    move = (lambda x: float(dt(x))) if callable(dt) else (lambda x: x + dt)
    out = dict(report)
    out["gaps"] = [dict(g, start=move(g["start"]), end=move(g["end"])) for g in report["gaps"]]
    out["dropped_duplicates"] = [dict(d, time=move(d["time"]))
                                 for d in report["dropped_duplicates"]]
    out["segments"] = [[move(a), move(b)] for a, b in report["segments"]]
    if "spikes" in report:
        out["spikes"] = [dict(d, time=move(d["time"])) for d in report["spikes"]]
    return out


__all__ = ["apply_spike_policy", "check_imu_table", "find_spikes", "gap_noise", "gap_policy",
           "sample_rates", "shift_report"]
