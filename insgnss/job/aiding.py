"""Aiding measurements of a job (``[aiding]``, docs/jobs.md): the measurement models the filter
engine applies - GNSS position and velocity (outage windows withheld, quality flags weighted by
``q_scale``; a receiver that reports the horizontal velocity only, NMEA, gives a 2-D velocity
measurement, :class:`HorizontalGnssVelocity`) or, with ``aiding.gnss = "tight"``, per-satellite
pseudoranges and Dopplers (outage windows withheld or thinned to the highest satellites;
docs/tight.md), ZUPT and ZARU at the detected or declared still times (speed gated), NHC, CUPT at
control points, odometer speed.

The models themselves (``z, H, R``) are in :mod:`insgnss.filter.measurements`; this module
builds them from the job and the data, and keeps for each source the count of epochs each
filter step leaves between the input and the filter (:class:`Source`). A job that asks for a
source of which nothing can be applied stops with a :class:`~insgnss.errors.NoUsableAidingError`
naming the step that removed the last epoch - before the filter runs when the inputs show it
(:meth:`Aiding.require`), after it when the innovation gate rejected everything
(:func:`applied_check`). When most of a source is not applied the run finishes with an
:class:`~insgnss.errors.InsgnssWarning` and the summary flags it (``"aiding_warnings"``).

Summary counts (``summary.json`` ``"measurements"``, per measurement type)::

    offered    epochs handed to the filter (inside the IMU span, after the initial epoch,
               outside the outage windows)
    unusable   offered epochs the model cannot use (quality flag not admitted by
               aiding.q_scale, non-finite values or sigmas)
    applied    updates the filter made (innovation log ``accepted``)
    rejected   epochs the innovation gate rejected (``accepted`` false)
    recovered  applied updates forced by the gate recovery (``recovered``)

Offered epochs that are neither applied, rejected nor unusable were skipped while the filter
ran (the speed gate of ZUPT/ZARU, or after a filter that stopped early).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..config import Job
from ..errors import ConfigError, InputFormatError, NoUsableAidingError
from ..filter.heading_reinit import CourseTrack
from ..filter.measurements import (
    BodyVelocity,
    Cupt,
    GnssPosition,
    GnssVelocity,
    Measurement,
    Zaru,
    Zupt,
)
from ..filter.schedule import snap
from ..validate import check_gnss_in_imu_span, warn
from .inputs import Inputs
from .windows import describe_windows, outside_windows

#: share of a source's offered epochs that may be unusable or rejected before the run warns
MOST_REJECTED = 0.5


class SpeedGated:
    """Mixin of a still-time measurement (ZUPT, ZARU) applied only while the nominal speed is
    below ``max_speed`` (0: always).

    An IMU stillness detector cannot tell steady straight motion from rest (both give constant
    specific force and no rotation; only vibration differs), so a vehicle at constant speed can
    be flagged still. The nominal speed of the filter (GNSS-aided, or a short dead-reckoning
    extrapolation during outages) resolves that ambiguity.
    """

    max_speed = 0.0

    @property
    def skip_reason(self) -> tuple[str, str]:
        """Why nothing was applied when the gate skipped every epoch (message, job key)."""
        return (f"the nominal speed was above aiding.zupt_max_speed = {self.max_speed:g} m/s "
                "at every still time", "aiding.zupt_max_speed")

    def evaluate(self, i, nav):
        if self.max_speed and np.linalg.norm(nav.vel) > self.max_speed:
            return None
        return super().evaluate(i, nav)


class SpeedGatedZupt(SpeedGated, Zupt):
    """ZUPT applied only while the nominal speed is below ``max_speed`` (:class:`SpeedGated`)."""

    def __init__(self, times, std, max_speed: float, **kw):
        super().__init__(times, std=std, **kw)
        self.max_speed = float(max_speed)


class SpeedGatedZaru(SpeedGated, Zaru):
    """ZARU applied only while the nominal speed is below ``max_speed`` (:class:`SpeedGated`)."""

    def __init__(self, times, max_speed: float, **kw):
        super().__init__(times, **kw)
        self.max_speed = float(max_speed)


class HorizontalGnssVelocity(GnssVelocity):
    """GNSS velocity of a receiver that reports only the horizontal velocity (NMEA: speed and
    course over ground, RMC/VTG): the east and north rows of :class:`GnssVelocity` (the same
    lever-arm model), a 2-D measurement.

    ``data`` holds ``vel_e vel_n`` and optionally ``vel_e_std vel_n_std``; other parameters
    as :class:`GnssVelocity`.
    """

    def __init__(self, data: pd.DataFrame, **kw):
        d = data.copy()
        d["vel_u"] = 0.0  # not measured: its row is dropped in evaluate
        if "vel_e_std" in d.columns and "vel_n_std" in d.columns:
            d["vel_u_std"] = 1.0
        super().__init__(d, **kw)

    def evaluate(self, i, nav):
        out = super().evaluate(i, nav)
        if out is None:
            return None
        z, H, R = out
        return z[:2], H[:2], R[:2, :2]


#: the default stillness detector of a vehicle: acceleration moving variance over 0.5 s,
#: below 0.1 m/s^2 (raised to the still noise a static window shows: :func:`still_threshold`)
VEHICLE_DETECTOR = {"method": "amv", "window": 0.5, "threshold": 0.1, "min_stance": 1.0,
                    "margin": 0.3}
#: the default threshold sits this factor above the median of the detector statistic over the
#: static window (the still level with the engine running; the median, not a high percentile:
#: a door shut or a passenger moving in the parked car is no still noise)
STILL_MARGIN = 2.0


def still_threshold(static: pd.DataFrame, limit: float) -> float:
    """Threshold [m/s^2] of the default vehicle detector from the still noise measured in the
    static window ``static``: ``STILL_MARGIN`` x the median of its AMV statistic over
    regular samples (windows touching a bridged sample left out), at least the default 0.1 and
    at most ``limit`` (the stillness limit the static initialization accepted).

    An idling engine shakes a parked car by 0.13-0.35 m/s^2: a fixed 0.1 would never detect
    it still, while the static start accepted it.
    """
    from ..detect import amv_statistic, imu_rates, regular_samples, sample_count

    t, _, f = imu_rates(static)
    base = float(VEHICLE_DETECTOR["threshold"])
    if t.size < 3:
        return base
    w = sample_count(VEHICLE_DETECTOR["window"], float(np.median(np.diff(t))))
    stat = amv_statistic(np.require(f, float, ["C", "W"]), w)
    bad = ~regular_samples(t)
    near = np.convolve(bad.astype(float), np.ones(w + 1), mode="same") > 0
    if near.all():
        return base
    level = float(np.median(stat[~near]))
    return float(min(max(base, STILL_MARGIN * level), max(base, limit)))


def stillness_times(job: Job, imu: pd.DataFrame, static: pd.DataFrame | None = None,
                    moving: list[tuple[float, float]] | None = None
                    ) -> tuple[np.ndarray, float | None]:
    """Times (at the ZUPT interval) when the IMU is still, from the detector and/or declared
    static intervals, and the threshold of the default detector (None when the job sets the
    detector or only declares intervals). With the static window ``static`` of the
    initialization and ``aiding.zupt_threshold_from_static`` the default threshold follows
    its still noise (:func:`still_threshold`). ``moving``: intervals where the GNSS shows the
    antenna moving; the detector's still times inside them are dropped (a smooth pull-away
    changes neither the specific-force magnitude nor the rates the detector sees), declared
    intervals are kept."""
    a = job["aiding"]
    t = imu.index.to_numpy(float)
    still = np.zeros(t.size, bool)
    thr = None
    if a["detector"] or not a["static_intervals"]:
        from ..detect import DetectorConfig, detect_stillness, in_intervals

        if a["detector"]:
            cfg = DetectorConfig.from_dict(a["detector"])
        else:
            spec = dict(VEHICLE_DETECTOR)
            if static is not None and a["zupt_threshold_from_static"]:
                spec["threshold"] = still_threshold(
                    static, job["initialization"]["static_max_accel_std"])
            thr = float(spec["threshold"])
            cfg = DetectorConfig(**spec)
        still |= detect_stillness(imu, cfg).still.to_numpy(bool) & ~in_intervals(t, moving or ())
    for a0, a1 in a["static_intervals"] or []:
        still |= (t >= a0) & (t <= a1)
    ts = t[still]
    if not ts.size:
        return ts, thr
    step = a["zupt_interval"]
    keep = np.concatenate([[True], np.diff(np.floor((ts - ts[0]) / step)) > 0])
    return ts[keep], thr


@dataclass
class Step:
    """One filter step between an aiding source's input and the filter.

    ``left`` epochs remain after it, described by ``kept`` (``"outside the outage windows"``);
    ``cause`` is the message when it removes the last one, ``removed`` says in a few words what
    it removes, ``column`` is the column or job key the cause names.
    """

    left: int
    kept: str
    cause: str = ""
    column: str | None = None
    removed: str = ""


@dataclass
class Source:
    """An aiding source the job asks for (``key``, e.g. ``"aiding.gnss_position"``), its
    measurement type (``kind``, as in the logs), the filter steps from its input to the filter
    and the model built from what is left (None when nothing is left)."""

    key: str
    kind: str
    what: str
    steps: list[Step]
    model: Measurement | None = None
    file: str | None = None
    #: index of the step whose epochs are the model's epochs (the filter is offered them)
    offered_step: int = -1
    #: the data must provide it (GNSS, odometer, control points: a run without any is not
    #: what the job asks for); ZUPT/ZARU depend on the vehicle stopping, and a run without a
    #: stop only warns
    required: bool = True

    @property
    def usable(self) -> int:
        """Epochs left after every step."""
        return self.steps[-1].left if self.steps else 0

    def trail(self, upto: int | None = None) -> str:
        steps = self.steps if upto is None else self.steps[:upto + 1]
        return ", ".join(f"{s.left} {s.kept}" for s in steps)

    def failure(self) -> NoUsableAidingError | None:
        """The error of a source of which nothing is left (None if something is)."""
        if self.usable:
            return None
        k = next(i for i, s in enumerate(self.steps) if s.left == 0)
        s = self.steps[k]
        return NoUsableAidingError(
            f"{self.key} = true asks for {self.what}, but none can be applied: {s.cause} "
            f"(epochs left after each step: {self.trail(k)})", file=self.file, column=s.column)

    def unusable_causes(self) -> str:
        """Why offered epochs are unusable (the steps after the offered one that remove any)."""
        out = []
        prev = self.steps[self.offered_step].left
        for s in self.steps[self.offered_step + 1:]:
            if s.left < prev:
                out.append(f"{prev - s.left} {s.removed}")
            prev = s.left
        return "; ".join(out)


@dataclass
class Aiding:
    """The aiding sources of a job and their measurement models."""

    sources: list[Source] = field(default_factory=list)
    #: threshold of the default stillness detector [m/s^2] (None: not used)
    still_threshold: float | None = None
    #: the GNSS epochs the loosely coupled sources may use (after the span, outage and Q
    #: steps; None without them): the course of the heading re-initialisation
    gnss_used: pd.DataFrame | None = None

    @property
    def models(self) -> list[Measurement]:
        return [s.model for s in self.sources if s.model is not None]

    def require(self) -> None:
        """Stop (:class:`~insgnss.errors.NoUsableAidingError`) when a required source the job
        asks for has nothing left to apply (:attr:`Source.required`)."""
        for s in self.sources:
            err = s.failure() if s.required else None
            if err is not None:
                raise err


def _source_file(table) -> str | None:
    return None if table is None else table.attrs.get("source")


def _gnss_sources(job: Job, gnss: pd.DataFrame, lever_arm, windows, imu: pd.DataFrame
                  ) -> tuple[list[Source], pd.DataFrame | None]:
    """GNSS position / velocity sources: IMU span -> after the initial epoch -> outside the
    outage windows -> quality flag admitted by ``q_scale`` -> finite values and sigmas; and
    the GNSS epochs left before the last step (None without epochs)."""
    a = job["aiding"]
    file = _source_file(gnss)
    tg = gnss.index.to_numpy(float)
    t0, t1 = float(imu.index[0]), float(imu.index[-1])
    if not tg.size:
        empty = [Step(0, "epochs in the GNSS data", "the GNSS data holds no epoch", "time")]
        return [Source(key, kind, what, empty, None, file, 0) for key, kind, what in
                (("aiding.gnss_position", "gnss_pos", "GNSS positions"),
                 ("aiding.gnss_velocity", "gnss_vel", "GNSS velocities")) if a[key[7:]]], None
    steps = [Step(len(gnss), "epochs in the GNSS data")]
    n_span = int(np.count_nonzero((tg >= t0) & (tg <= t1)))
    steps.append(Step(n_span, "inside the IMU time span",
                      f"every GNSS epoch lies outside the IMU time span {t0:.3f} .. {t1:.3f} s "
                      f"(GNSS {tg[0]:.3f} .. {tg[-1]:.3f} s: different time bases or a time "
                      "offset?)", gnss.attrs.get("time_column", "time")))
    if n_span:
        g = check_gnss_in_imu_span(gnss, imu, policy="trim")  # warns, names the file/lines
    else:
        g = gnss.iloc[:0]
    # the initial position comes from the GNSS at the first IMU time: an epoch there would
    # be used twice (initial state and update), with correlated errors
    g = g[g.index > imu.index[0] + 1e-6]
    steps.append(Step(len(g), "after the initial epoch",
                      f"the only epoch left is at the initialization time {t0:.3f} s (used for "
                      "the initial state)", "initialization"))
    g = outside_windows(g, windows)
    steps.append(Step(len(g), "outside the outage windows",
                      f"every remaining epoch lies inside an outage window "
                      f"({describe_windows(windows)})", "outages"))
    scale = {int(float(k)): float(v) for k, v in a["q_scale"].items()}
    use_q = list(scale) if "q" in g.columns else None
    if use_q is not None:
        q = g["q"].to_numpy()
        found = sorted({int(v) for v in q[np.isfinite(q)]} - set(use_q))
        steps.append(Step(int(np.isin(q, use_q).sum()), "with a Q admitted by aiding.q_scale",
                          f"every remaining epoch has Q = {', '.join(map(str, found))} (column "
                          f"'q') and aiding.q_scale admits only Q = "
                          f"{', '.join(map(str, sorted(use_q)))}", "q",
                          "with a Q not admitted by aiding.q_scale"))
    q_steps = steps
    used = g[np.isin(g["q"].to_numpy(), use_q)] if use_q is not None else g
    out = []
    if a["gnss_position"]:
        std = a["gnss_position_std"]
        if std is None and not all(c in g.columns for c in GnssPosition.STD_COLS):
            raise ConfigError(
                "the GNSS file gives no position sigmas (east_std north_std up_std; NMEA: no "
                "GST sentence and no HDOP): set aiding.gnss_position_std [m]", file=file,
                column="aiding.gnss_position_std")
        gp = g
        if std is not None:
            gp = gp.drop(columns=[c for c in GnssPosition.STD_COLS if c in gp.columns])
        kw = {"std": std} if std is not None else {}
        if a["gnss_std_scale"] != 1.0 and std is None:
            gp = gp.copy()
            for c in GnssPosition.STD_COLS:
                gp[c] = gp[c] * a["gnss_std_scale"]
        m = GnssPosition(gp, lever_arm=lever_arm, std_scale=scale if use_q else None,
                         use_q=use_q, min_std=a["gnss_min_std"], **kw)
        st = q_steps + [Step(int(m.valid.sum()), "with a finite position and sigma",
                             "every remaining epoch has a non-finite position or sigma, or a "
                             "sigma <= 0 (an NMEA epoch without GST or HDOP has no sigma: set "
                             "aiding.gnss_position_std)", "east_std" if std is None else
                             "aiding.gnss_position_std", "with a non-finite position or sigma")]
        out.append(Source("aiding.gnss_position", m.name, "GNSS positions", st, m, file, 3))
    if a["gnss_velocity"]:
        if "vel_e" not in g.columns:
            raise InputFormatError("GNSS velocity aiding requested but the GNSS data has no "
                                   "velocity", file=file, column="vel_e")
        std = a["gnss_velocity_std"]
        # NMEA gives the horizontal velocity only (speed and course): a 2-D measurement
        model = GnssVelocity if "vel_u" in g.columns else HorizontalGnssVelocity
        n_std = 3 if model is GnssVelocity else 2
        have = [c for c in model.STD_COLS[:n_std] if c in g.columns]
        if std is None and len(have) < n_std:
            raise ConfigError(
                "the GNSS file gives no velocity sigmas (vel_e_std vel_n_std"
                + (" vel_u_std" if model is GnssVelocity else "; NMEA has none") +
                "): set aiding.gnss_velocity_std [m/s]", file=file,
                column="aiding.gnss_velocity_std")
        gv = velocity_table(g, windows)
        if std is not None:
            gv = gv.drop(columns=[c for c in GnssVelocity.STD_COLS if c in gv.columns])
        elif a["gnss_velocity_std_scale"] != 1.0:
            gv = gv.copy()
            for c in have:
                gv[c] = gv[c] * a["gnss_velocity_std_scale"]
        m = model(gv, lever_arm=lever_arm, std_scale=scale if use_q else None,
                  use_q=use_q, **({"std": std} if std is not None else {}))
        st = q_steps + [Step(int(m.valid.sum()), "with a finite velocity and sigma",
                             "every remaining epoch has a non-finite velocity or sigma, or a "
                             "sigma <= 0", "vel_e_std" if std is None else
                             "aiding.gnss_velocity_std", "with a non-finite velocity or sigma")]
        out.append(Source("aiding.gnss_velocity", m.name, "GNSS velocities", st, m, file, 3))
    return out, used


def course_track(job: Job, used: pd.DataFrame, windows) -> CourseTrack | None:
    """The GNSS course samples of the heading re-initialisation (docs/filter.md) from the
    GNSS epochs the run may use: from the velocity (at its own time, :func:`velocity_table`)
    when the file has one, else from the central difference of successive positions less than
    2 s apart (per-axis sigma ``sqrt(2) sigma_pos / dt``); the course sigma adds the side slip
    (``initialization.course_heading_std_deg``). None when no sample remains."""
    from ..align import heading_from_velocity
    from ..earth import geodetic_to_enu

    a = job["aiding"]
    slip = np.radians(job["initialization"]["course_heading_std_deg"])
    vmin = float(a["heading_reinit_min_speed"])
    if used is None or len(used) < 3:
        return None
    if "vel_e" in used.columns and "vel_n" in used.columns:
        g = velocity_table(used, windows)
        ve, vn = g["vel_e"].to_numpy(float), g["vel_n"].to_numpy(float)
        if a["gnss_velocity_std"] is not None:
            sv = np.full(ve.shape, float(a["gnss_velocity_std"]))
        elif "vel_e_std" in g.columns and "vel_n_std" in g.columns:
            sv = np.sqrt(0.5 * (g["vel_e_std"].to_numpy(float) ** 2
                                + g["vel_n_std"].to_numpy(float) ** 2))
        else:  # NMEA gives no velocity sigma: a Doppler velocity of a consumer receiver
            sv = np.full(ve.shape, 0.1)
        t = g.index.to_numpy(float)
    else:
        t0 = used.index.to_numpy(float)
        lat, lon, h = (used[c].to_numpy(float) for c in ("lat", "lon", "height"))
        e, n, _ = geodetic_to_enu(lat, lon, h, float(lat[0]), float(lon[0]), float(h[0]))
        dt = t0[2:] - t0[:-2]
        ok = dt < 2.0
        t = t0[1:-1][ok]
        ve, vn = ((x[2:] - x[:-2])[ok] / dt[ok] for x in (e, n))
        sp = float(a["gnss_position_std"]) if a["gnss_position_std"] is not None else None
        if sp is None and "east_std" in used.columns:
            sp_all = np.hypot(used["east_std"].to_numpy(float),
                              used["north_std"].to_numpy(float)) / np.sqrt(2.0)
            sp_all = sp_all[1:-1][ok]
        else:
            sp_all = np.full(t.shape, 1.0 if sp is None else sp)
        sv = np.sqrt(2.0) * sp_all / dt[ok]
    track = CourseTrack.from_velocity(t, ve, vn, sv, heading_from_velocity(ve, vn, vmin), slip)
    return track if track.t.size else None


def reception_times(prepared: pd.DataFrame, spp: pd.DataFrame) -> pd.DataFrame:
    """``prepared`` re-indexed from the receiver's time tags to GPS time of reception, ``tag -
    b / c`` with the receiver clock ``b`` of the single-point solution (its ``receiver_time``
    column against its GPS-time index; interpolated between, held beyond its epochs): the
    tags are off by the clock (1.5 ms on the walk), which the IMU's GPS time stamps are not."""
    tag, t_gps = spp["receiver_time"].to_numpy(float), spp.index.to_numpy(float)
    ok = np.isfinite(tag) & np.isfinite(t_gps)
    t = prepared.index.to_numpy(float)
    if not ok.any():
        return prepared
    off = np.interp(t, tag[ok], (tag - t_gps)[ok])
    out = prepared.set_axis(pd.Index(t - off, name=prepared.index.name), axis=0)
    out.attrs.update(prepared.attrs)
    return out


def _raw_sources(job: Job, inputs: Inputs, windows, imu: pd.DataFrame) -> list[Source]:
    """Tightly coupled GNSS (``aiding.gnss = "tight"``): one pseudorange and one Doppler
    source over the satellite rows of the raw data (:mod:`insgnss.filter.gnss_raw`): rows with
    a usable signal and ephemeris -> inside the IMU span after the initial epoch -> outside
    the outage windows, or among the ``outages.keep_satellites`` highest satellites inside."""
    from ..filter.gnss_raw import Doppler, Pseudorange, ReceiverClock
    from ..gnss import prepare_observations
    from ..gnss.observations import keep_highest_satellites
    from .inputs import gnss_model_config

    raw, sol = inputs.gnss_raw, inputs.spp
    file = job.resolve(job["inputs"]["gnss_raw"]["path"])
    file = None if file is None else str(file)
    if raw is None:
        raise ConfigError('aiding.gnss = "tight" needs raw observations (inputs.gnss_raw.path)',
                          file=job.path, column="aiding.gnss")
    cfg = gnss_model_config(job)
    prep = prepare_observations(raw.observations, raw.ephemeris, cfg)
    steps = [Step(len(prep), "satellite measurements with a usable signal and ephemeris",
                  "no observation has a signal, C/N0 and healthy ephemeris the model can use "
                  "(inputs.gnss_raw.cn0_mask; the stream's navigation data)",
                  "inputs.gnss_raw.cn0_mask")]
    if len(prep) and sol is not None and len(sol):
        prep = reception_times(prep, sol)
    t = prep.index.to_numpy(float)
    prep = prep[(t > float(imu.index[0]) + 1e-6) & (t <= float(imu.index[-1]))]
    steps.append(Step(len(prep), "inside the IMU time span after the initial epoch",
                      f"every one lies outside the IMU time span {float(imu.index[0]):.3f} .. "
                      f"{float(imu.index[-1]):.3f} s or at the initial epoch", "time"))
    n_keep = int(job["outages"]["keep_satellites"])
    if len(prep) and windows:
        ranked = outside_windows(sol, windows)  # elevations from positions the run may use
        prep = keep_highest_satellites(prep, windows, n_keep, ranked)
    steps.append(Step(len(prep), "outside the outage windows" + (
        f" or among the {n_keep} highest satellites inside" if n_keep else ""),
        f"every remaining one lies inside an outage window ({describe_windows(windows)})",
        "outages"))
    if not len(prep):
        return [Source("aiding.gnss", "pseudorange", "pseudoranges", steps, None, file, 2)]
    clock = ReceiverClock.from_spp(sol, float(imu.index[0]))
    isb = {s: float(np.nanmedian(sol[f"clock_bias_{s}"] - sol[f"clock_bias_{clock_ref(sol)}"]))
           for s in pd.unique(prep["system"]) if f"clock_bias_{s}" in sol.columns}
    kw = dict(ionosphere=raw.ionosphere, lever_arm=inputs.lever_arm, config=cfg, clock=clock,
              reference_system=clock_ref(sol))
    pr = Pseudorange(prep, isb_initial=isb, **kw)
    out = [Source("aiding.gnss", pr.name, "pseudoranges", steps, pr, file, 2)]
    if job["aiding"]["doppler"]:
        dp = Doppler(prep, **kw)
        n_dop = int(np.isfinite(prep["doppler"].to_numpy(float)).sum())
        out.append(Source("aiding.doppler", dp.name, "Doppler range rates", steps + [
            Step(n_dop, "with a Doppler", "no remaining row has a Doppler measurement",
                 "doppler", "without a Doppler")], dp, file, 2))
    return out


def clock_ref(spp: pd.DataFrame) -> str:
    """Reference system of the receiver clock: GPS when the solution has its clock."""
    systems = [c[len("clock_bias_"):] for c in spp.columns if c.startswith("clock_bias_")]
    return "G" if "G" in systems or not systems else systems[0]


def velocity_table(gnss: pd.DataFrame, windows) -> pd.DataFrame:
    """The GNSS velocities at their own time: tags moved back by the lag the preprocessing
    estimated (``attrs["velocity_lag"]``, :func:`insgnss.preprocess.estimate_velocity_lag`).
    A velocity whose moved time falls inside an outage window is withheld too: it averages
    over an interval that reaches into the window."""
    lag = float(gnss.attrs.get("velocity_lag") or 0.0)
    if not lag:
        return gnss
    out = gnss.set_axis(gnss.index - lag, axis=0)
    out.attrs = dict(gnss.attrs)
    return outside_windows(out, windows)


def _in_span(n_all: int, n_in: int, what: str, t0: float, t1: float, column: str) -> list[Step]:
    return [Step(n_all, what),
            Step(n_in, "inside the IMU time span",
                 f"every one lies outside the IMU time span {t0:.3f} .. {t1:.3f} s", column)]


def build_aiding(job: Job, inputs: Inputs, windows, imu: pd.DataFrame,
                 static: pd.DataFrame | None = None) -> Aiding:
    """The aiding sources of the job over the IMU table ``imu`` (the filter's span): GNSS with
    the outage windows withheld, ZUPT, ZARU, NHC, CUPT, odometer. ``static``: the static
    window of the initialization (its still noise sets the default ZUPT detector threshold,
    recorded in ``still_threshold``)."""
    a = job["aiding"]
    src = Aiding()
    t = imu.index.to_numpy(float)
    t0, t1 = float(t[0]), float(t[-1])
    if a["gnss"] == "tight":
        src.sources += _raw_sources(job, inputs, windows, imu)
    elif inputs.gnss is not None:
        gs, src.gnss_used = _gnss_sources(job, inputs.gnss, inputs.lever_arm, windows, imu)
        src.sources += gs
    if a["zupt"] or a["zaru"]:
        from .initialization import gnss_moving_intervals

        ts, src.still_threshold = stillness_times(job, imu, static,
                                                  gnss_moving_intervals(inputs.gnss, windows,
                                                                        displacement_sigmas=3.0))
        how = "the stillness detector ([aiding.detector])" if a["detector"] or \
            not a["static_intervals"] else "aiding.static_intervals"
        vmax = a["zupt_max_speed"]
        for key, on in (("aiding.zupt", a["zupt"]), ("aiding.zaru", a["zaru"])):
            if not on:
                continue
            m = None
            if ts.size and key == "aiding.zupt":
                m = SpeedGatedZupt(ts, a["zupt_std"], vmax) if vmax else \
                    Zupt(ts, std=a["zupt_std"])
            elif ts.size:
                m = SpeedGatedZaru(ts, vmax) if vmax else Zaru(ts)
            kind = "zupt" if key == "aiding.zupt" else "zaru"
            src.sources.append(Source(
                key, kind, "zero-velocity updates" if kind == "zupt" else
                "zero angular-rate updates",
                [Step(int(ts.size), "still times",
                      f"{how} found no still period in the IMU data {t0:.3f} .. {t1:.3f} s",
                      "aiding.detector" if how.startswith("the") else "aiding.static_intervals")],
                m, _source_file(imu), 0, required=False))
    nhc_at = len(src.sources)  # listed after ZUPT/ZARU, placed once every epoch is known
    if a["cupt"]:
        cp = inputs.control_points
        if cp is None:
            raise ConfigError("CUPT needs inputs.control_points.path", file=job.path,
                              column="aiding.cupt")
        m = Cupt.from_table(cp, **({} if "east_std" in cp.columns else
                                   {"std": job["inputs"]["control_points"]["std"]}))
        tc = np.asarray(m.times, float)
        n_in = int(np.count_nonzero((tc > t0) & (tc <= t1)))
        src.sources.append(Source(
            "aiding.cupt", m.name, "control point updates",
            _in_span(len(cp), n_in, "control points", t0, t1, "time"),
            m if n_in else None, _source_file(cp), 1))
    if a["odometer"]:
        o = inputs.odometer
        if o is None or "speed" not in o.columns:
            raise ConfigError("odometer aiding needs an odometer speed table", file=job.path,
                              column="aiding.odometer")
        n_all = len(o)
        o = o[(o.index > imu.index[0]) & (o.index <= imu.index[-1])]
        m = BodyVelocity(o.index.to_numpy(float), o["speed"].to_numpy(float), axes=(1,),
                         std=a["odometer_std"], scale_state="odometer_scale", name="odometer")
        src.sources.append(Source(
            "aiding.odometer", "odometer", "odometer speeds",
            _in_span(n_all, len(o), "odometer epochs", t0, t1, "time"),
            m if len(o) else None, _source_file(inputs.odometer), 1))
    if a["nhc"]:
        src.sources.insert(nhc_at, _nhc_source(job, imu, src.models))
    return src


def constraint_times(t0: float, t1: float, interval: float, epochs) -> np.ndarray:
    """Times of a pseudo-measurement every ``interval`` seconds over ``(t0, t1)`` (a
    constraint such as the NHC), each grid time moved onto the nearest of ``epochs`` (the
    times the filter stops at anyway: GNSS, odometer) closer than ``interval / 2``.

    The constraint holds at any time, so where it is applied is free; applied at an epoch the
    filter has anyway it is one more row of that epoch's update, not an epoch of its own (a
    mechanization step, a covariance propagation and a smoother node fewer: with 4 Hz GNSS
    and a 4 Hz NHC, a quarter to a third of the epochs of a car run). The spacing stays
    within half an interval of the grid's.
    """
    grid = t0 + np.arange(1, int((t1 - t0) / interval)) * interval
    ep = np.unique(np.asarray(epochs, float))
    ep = ep[(ep > t0) & (ep < t1)]
    if not (grid.size and ep.size):
        return grid
    # strictly closer than half the interval: no two grid times (an interval apart) take one
    # epoch, and the times stay in order
    return snap(ep, grid, np.nextafter(0.5 * interval, 0.0))


def _nhc_source(job: Job, imu: pd.DataFrame, models: list) -> Source:
    """The non-holonomic constraints (``aiding.nhc``) over the IMU table, every
    ``aiding.nhc_interval`` seconds at the epochs of ``models`` where there is one
    (:func:`constraint_times`)."""
    a = job["aiding"]
    t = imu.index.to_numpy(float)
    t0, t1 = float(t[0]), float(t[-1])
    epochs = [np.asarray(m.times, float) for m in models if not getattr(m, "high_rate", False)]
    tn = constraint_times(t0, t1, float(a["nhc_interval"]),
                          np.concatenate(epochs) if epochs else np.empty(0))
    strapdown = job["filter"]["process_model"] == "strapdown"
    # time-correlated violations as Gauss-Markov states of sigma nhc_std (strapdown)
    tau = float(a["nhc_correlation_time"]) if strapdown else 0.0
    viol = {"violation_state": "nhc_violation", "violation_std": a["nhc_std"],
            "violation_tau": tau} if tau > 0 else {}
    m = BodyVelocity(tn, 0.0, axes=(0, 2), std=a["nhc_white_std"] if tau > 0 else
                     a["nhc_std"], name="nhc", **viol,
                     lever_arm=a["nhc_lever_arm"], slip_gradient=a["nhc_slip_gradient"],
                     # strapdown error states (RISS takes no extra states: not used there)
                     misalignment_state="nhc_misalignment" if a["nhc_misalignment"]
                     and strapdown else None,
                     pitch_compliance_state="nhc_pitch_compliance"
                     if a["nhc_pitch_compliance"] and strapdown else None)
    return Source(
        "aiding.nhc", "nhc", "non-holonomic constraints",
        [Step(int(tn.size), "constraint epochs",
              f"the IMU data ({t1 - t0:.3f} s) is shorter than two aiding.nhc_interval",
              "aiding.nhc_interval")], m if tn.size else None, _source_file(imu), 0)


def check_aiding(job: Job, inputs: Inputs, windows) -> None:
    """Before the initialization: stop when the inputs show that a source the job asks for
    has nothing to apply over the whole IMU table (the initialization would otherwise fail
    with a message about its own symptom, or the run would go on unaided)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the build after the initialization warns
        build_aiding(job, inputs, windows, inputs.imu).require()


def build_measurements(job: Job, inputs: Inputs, windows, imu: pd.DataFrame) -> list:
    """Aiding measurement models of the job (GNSS with outages removed, ZUPT, ZARU, NHC, CUPT,
    odometer); see :func:`build_aiding`."""
    return build_aiding(job, inputs, windows, imu).models


def measurement_counts(aiding: Aiding, innovations: pd.DataFrame) -> dict:
    """Offered, applied, rejected, recovered and unusable epochs per measurement type (module
    docstring), from the models and the filter's innovation log."""
    out = {}
    for s in aiding.sources:
        m = s.model
        offered = 0 if m is None else int(len(m))
        valid = getattr(m, "valid", None)
        unusable = 0 if valid is None else int(offered - np.count_nonzero(valid))
        log = innovations[innovations["type"] == s.kind] if len(innovations) else innovations
        acc = log["accepted"].to_numpy(bool) if len(log) else np.zeros(0, bool)
        rec = log["recovered"].to_numpy(bool) if len(log) and "recovered" in log else acc[:0]
        out[s.kind] = {"offered": offered, "applied": int(acc.sum()),
                       "rejected": int((~acc).sum()), "recovered": int(rec.sum()),
                       "unusable": unusable}
    return out


def applied_check(job: Job, aiding: Aiding, counts: dict, innovations: pd.DataFrame,
                  complete: bool) -> tuple[NoUsableAidingError | None, list[str]]:
    """After the filter: the error of a required source of which the filter applied nothing
    (the gate rejected everything, or a run-time gate skipped everything), and a warning text
    for each source of which most was not applied, and for each source that is not required
    (ZUPT, ZARU) of which nothing was applied (also emitted as
    :class:`~insgnss.errors.InsgnssWarning`). A filter that stopped early is judged by its
    health error, not here."""
    failure, notes = None, []
    for s in aiding.sources:
        c = counts.get(s.kind)
        err = s.failure()
        if err is not None:  # not required (else require() stopped the run): a warning
            notes.append(f"{s.kind}: none applied: {err.message}")
            warn(notes[-1], file=s.file, column=err.column, stacklevel=2)
            continue
        if s.model is None or c is None or not c["offered"]:
            continue
        if complete and not c["applied"] and failure is None and not s.required:
            cause, column = getattr(s.model, "skip_reason", (
                "the filter evaluated none of them", None))
            if c["rejected"]:
                cause, column = f"the innovation gate rejected all {c['rejected']}", \
                    "filter.gate_probability"
            notes.append(f"{s.kind}: none of the {c['offered']} offered epochs applied: {cause}")
            warn(notes[-1], file=s.file, column=column, stacklevel=2)
            continue
        if complete and not c["applied"] and failure is None:
            if c["rejected"]:
                log = innovations[innovations["type"] == s.kind]
                ratio = log["nis"].to_numpy(float) / log["threshold"].to_numpy(float)
                cause = (f"the innovation gate (filter.gate_probability = "
                         f"{job['filter']['gate_probability']:g}) rejected all {c['rejected']} "
                         f"evaluated epochs (median NIS {float(np.nanmedian(ratio)):.3g} times "
                         "its threshold) and the gate recovery did not restore them")
                column = "filter.gate_probability"
            else:
                cause, column = getattr(s.model, "skip_reason", (
                    "the filter evaluated none of them", None))
            failure = NoUsableAidingError(
                f"{s.key} = true asks for {s.what}, but the filter applied none of the "
                f"{c['offered']} offered epochs: {cause}", file=s.file, column=column)
            continue
        lost = c["unusable"] + c["rejected"]
        if lost > MOST_REJECTED * c["offered"]:
            why = []
            if c["unusable"]:
                why.append(f"{c['unusable']} unusable ({s.unusable_causes()})")
            if c["rejected"]:
                why.append(f"{c['rejected']} rejected by the innovation gate")
            text = (f"{s.kind}: {lost} of {c['offered']} offered epochs not applied "
                    f"({', '.join(why)}); the solution rests on the other {c['applied']}")
            notes.append(text)
            warn(text, file=s.file, column=s.key, stacklevel=2)
    return failure, notes


__all__ = ["MOST_REJECTED", "Aiding", "HorizontalGnssVelocity", "Source", "SpeedGated",
           "SpeedGatedZaru", "SpeedGatedZupt", "Step",
           "applied_check", "build_aiding", "build_measurements", "check_aiding", "clock_ref",
           "reception_times",
           "measurement_counts", "stillness_times"]
