"""Drift comparison: the same IMU data free-inertial, with ZUPT, ZUPT+ZARU, ZUPT+CUPT and (when
present) GNSS aiding; one error table and the drift figures.

Runs
----
``free``        no aiding: the strapdown from the initial state (the filter with no
                measurements, so the nominal is exactly the free-inertial mechanization);
``zupt``        zero-velocity updates on the samples the stillness detector (or the declared
                static intervals) marks still, at ``zupt_interval``;
``zupt_zaru``   the same plus zero-angular-rate updates (observes the gyro biases, the vertical
                one included, which ZUPT alone does not);
``zupt_cupt``   ZUPT plus coordinate updates at control points (time-triggered when the point
                has a time, else position-triggered: at the still interval whose ZUPT-run
                position lies within ``cupt_radius`` of the point);
``gnss``        the GNSS position (and velocity) aiding of the data, when there is GNSS.

Vehicles use the error-state filter of :mod:`insgnss.filter` with the measurement models
``Zupt``, ``Zaru``, ``Cupt``, ``GnssPosition``/``GnssVelocity``. A stillness detector cannot
tell steady straight motion from rest, so vehicle ZUPT/ZARU are gated by the nominal speed
(``max_speed``, as in the processing pipeline). The foot-mounted comparison
(:func:`compare_foot_runs`) uses the compiled pedestrian filter of :mod:`insgnss.foot`.

Gating: the updates a run is about (ZUPT, ZARU, CUPT) are not gated (``gate_zupt``); the
GNSS run and the job's own runs keep the filter's gate. Every table shows per run how many
measurements the innovation gate rejected (``rejected``, by type in ``rejected_types``), so a
run that did not get the updates its name says is visible.

Errors
------
Against a truth trajectory (``lat lon height vel_e vel_n vel_u roll pitch heading``, e.g. a
simulation): horizontal and vertical position error (ENU at the truth point), velocity error
norm and heading error, at the truth epochs (decimated to ``eval_rate``). Against a position-only
truth in an arbitrary local frame (``x y z``, e.g. the Vicon of the PyShoe trials): both tracks
are shifted to start at the origin and the estimate is rotated about the vertical so that its
position at the first sample >= 0.8 m from the start points like the truth's (PyShoe's
alignment), then the horizontal error.

Growth exponent: least-squares line through ``log10(e_h)`` against ``log10(t - t_0)`` on 40
log-spaced times in ``fit_window`` (default 10-300 s). Unaided INS position error grows as
``t^2`` (accelerometer bias, initial tilt and velocity errors give ``t^2`` and ``t``) and ``t^3``
(gyro bias through tilt; Groves 2013 section 14.1.1, Titterton & Weston 2004 ch. 12) until the
Schuler period (84 min) bounds the horizontal channels.

The figure a user puts in a report: :func:`plot_drift` (log-log horizontal error of every run
with ``t``, ``t^2``, ``t^3`` reference slopes anchored on the free-inertial run) and
:func:`plot_errors` (position, velocity and heading error against time).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .attitude import wrap_pi
from .detect import Stillness
from .errors import ConfigError
from .evaluate import position_errors
from .filter.engine import FilterConfig, FilterResult, run_filter
from .filter.measurements import Cupt, GnssPosition, GnssVelocity
from .job.aiding import SpeedGatedZaru, SpeedGatedZupt
from .mechanization.strapdown import NAV_COLS, NavState, mechanize

RUNS = ("free", "zupt", "zupt_zaru", "zupt_cupt", "gnss", "job", "job_smoothed", "riss",
        "riss_smoothed")
LABELS = {"free": "free inertial", "zupt": "ZUPT", "zupt_zaru": "ZUPT+ZARU",
          "zupt_cupt": "ZUPT+CUPT", "gnss": "GNSS-aided",
          "job": "job aiding (forward)", "job_smoothed": "job aiding (smoothed)",
          "riss": "RISS, job aiding (forward)", "riss_smoothed": "RISS, job aiding (smoothed)"}
COLORS = {"free": "tab:red", "zupt": "tab:blue", "zupt_zaru": "tab:green",
          "zupt_cupt": "tab:purple", "gnss": "tab:gray",
          "job": "tab:cyan", "job_smoothed": "tab:brown", "riss": "tab:olive",
          "riss_smoothed": "tab:pink"}
STYLES = {"zupt_zaru": "--"}


@dataclass
class CompareSettings:
    """Settings of a drift comparison (SI units).

    Attributes
    ----------
    zupt_std, zaru_std : float
        ZUPT sigma [m/s]; ZARU sigma [rad/s] (None: the engine's default, the gyro white noise
        averaged over the update window).
    zupt_interval : float
        Time between ZUPT/ZARU updates while still [s].
    max_speed : float
        Vehicle ZUPT/ZARU only while the nominal speed is below this [m/s] (0: always). A
        detector that sees the vibration of a moving vehicle needs no speed gate; the gate
        helps when steady cruising looks still, but after a long free-inertial stretch the
        nominal speed is itself wrong by more than the gate and the stops get no update.
    gate_zupt : bool
        Chi-square gating of ZUPT, ZARU and control-point updates (the filter's default gate).
        Off by default: after a free-inertial stretch the covariance is optimistic against
        unmodelled errors (scale factors, misalignment), so the gate rejects exactly the
        updates the comparison is about (a consumer IMU reaches a control point with a NIS of
        60-80 against a 0.9999 gate of 21 for 3 degrees of freedom, and "ZUPT+CUPT" became
        ZUPT only); the detector (with its ``margin``) and the surveyed points decide. The
        table's ``rejected`` column counts what the gate rejected in each run.
    cupt_std : float
        Default control-point sigma [m] when the table has no ``east_std`` ...
    cupt_radius : float
        Position-triggered CUPT: largest distance between a still interval's ZUPT-run position
        and a control point [m].
    fit_window : (float, float)
        Time window (since the start) of the growth-exponent fit [s].
    eval_rate : float
        Rate of the error series [Hz].
    solution : {"forward", "smoothed"}
        Which solution is compared (forward: the causal drift).
    stop_settle : float
        Velocity error "during stops" is taken over still samples at least this long after the
        start of their still interval [s] (the detector and the first updates need that time).
    """

    zupt_std: float = 0.01
    zaru_std: float | None = None
    zupt_interval: float = 0.1
    max_speed: float = 0.0
    gate_zupt: bool = False
    cupt_std: float = 0.02
    cupt_radius: float = 30.0
    fit_window: tuple[float, float] = (10.0, 300.0)
    eval_rate: float = 10.0
    solution: str = "forward"
    stop_settle: float = 0.5

    def __post_init__(self):
        if self.solution not in ("forward", "smoothed"):
            raise ConfigError("solution must be forward or smoothed", column="solution",
                              found=self.solution)
        self.fit_window = (float(self.fit_window[0]), float(self.fit_window[1]))
        if not 0 < self.fit_window[0] < self.fit_window[1]:
            raise ConfigError("fit_window must be 0 < t0 < t1", column="fit_window",
                              found=self.fit_window)


@dataclass
class CompareResult:
    """Output of :func:`compare_runs` / :func:`compare_foot_runs`.

    ``solutions[run]`` are the compared trajectories (``NAV_COLS``), ``errors[run]`` the error
    series (``horizontal`` [m], and with a full truth ``up`` [m], ``velocity`` [m/s],
    ``heading`` [rad]), ``table`` one row per run (see :func:`summary_table`), ``growth[run]``
    the fitted ``(exponent, log10 coefficient)``; ``still`` the stillness mask at the IMU rate
    and ``cupt_times`` the control-point update times used.
    """

    runs: list[str]
    solutions: dict[str, pd.DataFrame]
    errors: dict[str, pd.DataFrame]
    table: pd.DataFrame
    growth: dict[str, tuple[float, float]]
    still: np.ndarray
    cupt_times: np.ndarray = field(default_factory=lambda: np.empty(0))
    filter_results: dict[str, FilterResult] = field(default_factory=dict)
    settings: CompareSettings = field(default_factory=CompareSettings)
    t0: float = 0.0


# --- measurements ----------------------------------------------------------------------------
def still_update_times(t: np.ndarray, still: np.ndarray, interval: float) -> np.ndarray:
    """Times of the still samples thinned to one per ``interval`` (the first kept)."""
    ts = np.asarray(t, float)[np.asarray(still, bool)]
    if not ts.size:
        return ts
    keep = np.concatenate([[True], np.diff(np.floor((ts - ts[0]) / interval + 1e-6)) > 0])
    return ts[keep]


def still_intervals(t: np.ndarray, still: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[a, b)`` of the runs of ``still``."""
    d = np.diff(np.concatenate([[0], np.asarray(still, np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def cupt_times_from_positions(solution: pd.DataFrame, still: np.ndarray,
                              points: pd.DataFrame, radius: float) -> pd.DataFrame:
    """Position-triggered CUPT: for every still interval whose mean position in ``solution``
    is within ``radius`` of a control point, one coordinate update at the middle of the
    interval, for the nearest point. Returns the control-point rows indexed by those times."""
    from .earth import geodetic_to_enu

    t = solution.index.to_numpy(float)
    lat0, lon0, h0 = (float(solution[c].iloc[0]) for c in ("lat", "lon", "height"))
    sol_enu = np.column_stack(geodetic_to_enu(solution["lat"].to_numpy(), solution["lon"].to_numpy(),
                                              solution["height"].to_numpy(), lat0, lon0, h0))
    pts_enu = np.column_stack(geodetic_to_enu(points["lat"].to_numpy(), points["lon"].to_numpy(),
                                              points["height"].to_numpy(), lat0, lon0, h0))
    rows, times = [], []
    for a, b in still_intervals(t, still):
        p = sol_enu[a:b].mean(axis=0)
        d = np.hypot(*(pts_enu[:, :2] - p[:2]).T)
        k = int(np.argmin(d)) if d.size else -1
        if k >= 0 and d[k] <= radius:
            rows.append(k)
            times.append(t[(a + b - 1) // 2])
    out = points.iloc[rows].copy()
    out.index = pd.Index(np.asarray(times, float), name="time")
    return out


def control_points_at_stops(truth: pd.DataFrame, min_duration: float = 2.0, std: float = 0.02,
                            rng: np.random.Generator | int | None = 0) -> pd.DataFrame:
    """Simulated surveyed points: the truth position at the middle of every stationary
    interval of at least ``min_duration`` s (truth column ``stationary``), with survey noise
    of ``std`` [m] per axis. Indexed by the middle time (time-triggered CUPT)."""
    from .earth import enu_displacement_to_geodetic

    rng = np.random.default_rng(rng)
    t = truth.index.to_numpy(float)
    st = truth["stationary"].to_numpy() > 0.5
    idx = [(a + b - 1) // 2 for a, b in still_intervals(t, st) if t[b - 1] - t[a] >= min_duration]
    cp = truth.iloc[idx][["lat", "lon", "height"]].copy()
    noise = rng.normal(0.0, std, (len(idx), 3))
    lat = cp["lat"].to_numpy()
    dlat, dlon, dh = enu_displacement_to_geodetic(lat, cp["height"].to_numpy(), noise[:, 0],
                                                  noise[:, 1], noise[:, 2])
    cp["lat"] = lat + dlat
    cp["lon"] = cp["lon"].to_numpy() + dlon
    cp["height"] = cp["height"].to_numpy() + dh
    for c in ("east_std", "north_std", "up_std"):
        cp[c] = std
    cp.index = pd.Index(t[idx], name="time")
    return cp


def _cupt(points: pd.DataFrame, std: float) -> Cupt:
    if all(c in points.columns for c in GnssPosition.STD_COLS):
        return Cupt.from_table(points)
    return Cupt.from_table(points, std=std)


# --- errors ----------------------------------------------------------------------------------
def _decimate(df: pd.DataFrame, rate: float) -> pd.DataFrame:
    t = df.index.to_numpy(float)
    if t.size < 3:
        return df
    step = max(1, int(round(1.0 / (rate * float(np.median(np.diff(t)))))))
    return df.iloc[::step]


def align_yaw(est_xy: np.ndarray, truth_xy: np.ndarray, dist: float = 0.8) -> np.ndarray:
    """Estimate shifted to start at the origin and rotated about the vertical so that its
    position at the first sample >= ``dist`` from the start points like the truth's (PyShoe's
    alignment of foot-mounted tracks; the truth is also shifted to the origin by the caller)."""
    e = est_xy - est_xy[0]
    g = truth_xy - truth_xy[0]
    r = np.hypot(e[:, 0], e[:, 1])
    i = int(np.argmax(r >= dist)) if r.max() >= dist else min(300, len(e) - 1)
    a = np.arctan2(g[i, 1], g[i, 0]) - np.arctan2(e[i, 1], e[i, 0])
    c, s = np.cos(a), np.sin(a)
    return e @ np.array([[c, s], [-s, c]])


def error_series(solution: pd.DataFrame, truth: pd.DataFrame, eval_rate: float = 10.0,
                 ) -> pd.DataFrame:
    """Error series of a solution against a truth (see the module docstring)."""
    if {"lat", "lon", "height"} <= set(truth.columns):
        ref = _decimate(truth, eval_rate)
        pe = position_errors(solution, ref)
        out = pd.DataFrame({"horizontal": pe["horizontal"], "up": pe["up"]}, index=ref.index)
        ts = solution.index.to_numpy(float)
        tr = ref.index.to_numpy(float)
        if {"vel_e", "vel_n", "vel_u"} <= set(truth.columns):
            dv = np.column_stack([np.interp(tr, ts, solution[c].to_numpy()) - ref[c].to_numpy()
                                  for c in ("vel_e", "vel_n", "vel_u")])
            out["velocity"] = np.linalg.norm(dv, axis=1)
        if "heading" in truth.columns:
            hs = np.unwrap(solution["heading"].to_numpy())
            out["heading"] = wrap_pi(np.interp(tr, ts, hs) - ref["heading"].to_numpy())
        return out
    if {"x", "y"} <= set(truth.columns):
        if not {"east", "north"} <= set(solution.columns):
            raise ConfigError("a local x/y truth needs a solution with east/north columns",
                              column="east")
        ti = truth.index.to_numpy(float)
        ts = solution.index.to_numpy(float)
        est = np.column_stack([np.interp(ti, ts, solution[c].to_numpy()) for c in ("east", "north")])
        xy = align_yaw(est, truth[["x", "y"]].to_numpy(float))
        g = truth[["x", "y"]].to_numpy(float)
        g = g - g[0]
        out = pd.DataFrame({"horizontal": np.hypot(*(xy - g).T)}, index=truth.index)
        return _decimate(out, eval_rate)
    raise ConfigError("truth needs lat/lon/height or x/y columns", column="truth",
                      found=list(truth.columns))


def growth_exponent(t_rel: np.ndarray, err: np.ndarray, window=(10.0, 300.0),
                    n: int = 40) -> tuple[float, float]:
    """Slope and intercept of ``log10(err)`` against ``log10(t_rel)`` on ``n`` log-spaced
    times in ``window`` (clipped to the data); NaN if fewer than 10 usable points."""
    t_rel = np.asarray(t_rel, float)
    err = np.asarray(err, float)
    ok = np.isfinite(err) & (err > 0) & (t_rel > 0)
    if ok.sum() < 10:
        return np.nan, np.nan
    t_rel, err = t_rel[ok], err[ok]
    lo, hi = max(window[0], t_rel[0]), min(window[1], t_rel[-1])
    if not hi > lo * 1.5:
        return np.nan, np.nan
    tg = np.logspace(np.log10(lo), np.log10(hi), n)
    lg = np.log10(np.interp(tg, t_rel, err))
    b, a = np.polyfit(np.log10(tg), lg, 1)
    return float(b), float(a)


def rejected_counts(rejected: pd.DataFrame | None) -> tuple[int, str]:
    """Number of measurements the innovation gate rejected and the count per type
    (``"cupt 2, gnss_pos 1"``; "" when none) of a filter's rejection log."""
    if rejected is None or not len(rejected):
        return 0, ""
    per = rejected["type"].value_counts().sort_index() if "type" in rejected.columns else {}
    return int(len(rejected)), ", ".join(f"{k} {int(v)}" for k, v in per.items())


def summary_table(errors: dict[str, pd.DataFrame], growth: dict, still_mask: pd.Series | None,
                  settings: CompareSettings, rejected: dict | None = None) -> pd.DataFrame:
    """One row per run: final / max / RMS horizontal error [m], final vertical error [m], RMS
    and final velocity error [m/s], max velocity error while still [m/s], final heading error
    [deg], the growth exponent and the measurements the innovation gate rejected (``rejected``,
    ``rejected_types``; ``rejected`` maps a run to its rejection log)."""
    rows = []
    for run, e in errors.items():
        h = e["horizontal"].dropna()
        n_rej, types = rejected_counts((rejected or {}).get(run))
        row = {"run": run, "label": LABELS.get(run, run), "rejected": n_rej,
               "rejected_types": types,
               "final_h_err_m": float(h.iloc[-1]), "max_h_err_m": float(h.max()),
               "rms_h_err_m": float(np.sqrt(np.mean(h.to_numpy() ** 2)))}
        if "up" in e:
            row["final_v_err_m"] = float(abs(e["up"].dropna().iloc[-1]))
        if "velocity" in e:
            v = e["velocity"].dropna()
            row["rms_vel_err_m_s"] = float(np.sqrt(np.mean(v.to_numpy() ** 2)))
            row["final_vel_err_m_s"] = float(v.iloc[-1])
            if still_mask is not None:
                m = np.interp(v.index.to_numpy(float), still_mask.index.to_numpy(float),
                              still_mask.to_numpy(float)) > 0.999
                row["max_stop_vel_err_m_s"] = float(v[m].max()) if m.any() else np.nan
        if "heading" in e:
            row["final_heading_err_deg"] = float(np.degrees(abs(e["heading"].dropna().iloc[-1])))
        row["growth_exponent"] = growth.get(run, (np.nan, np.nan))[0]
        rows.append(row)
    return pd.DataFrame(rows).set_index("run")


def _settled_still(t: np.ndarray, still: np.ndarray, settle: float) -> np.ndarray:
    """Still samples at least ``settle`` seconds after the start of their still run."""
    out = np.zeros(t.size, bool)
    for a, b in still_intervals(t, still):
        out[a:b] = t[a:b] - t[a] >= settle
    return out


def _finish(runs, solutions, truth, still, t, settings, filter_results, cupt_times, t0,
            truth_lever_arm=None, rejected=None):
    from .evaluate import move_point

    errors, growth = {}, {}
    for run in runs:
        sol = solutions[run]
        if truth_lever_arm is not None and np.any(truth_lever_arm):
            sol = move_point(sol, truth_lever_arm)  # the reference measures another point
        e = error_series(sol, truth, settings.eval_rate)
        errors[run] = e
        growth[run] = growth_exponent(e.index.to_numpy(float) - t0,
                                      e["horizontal"].to_numpy(float), settings.fit_window)
    mask = None
    if still is not None and still.any():
        mask = pd.Series(_settled_still(t, still, settings.stop_settle), index=t)
        if truth is not None and "stationary" in truth.columns:  # really at rest, too
            tt = truth.index.to_numpy(float)
            mask &= np.interp(t, tt, truth["stationary"].to_numpy(float)) > 0.5
    rejected = {**{r: res.rejected for r, res in filter_results.items()}, **(rejected or {})}
    table = summary_table(errors, growth, mask, settings, rejected)
    return CompareResult(list(runs), solutions, errors, table, growth,
                         np.zeros(t.size, bool) if still is None else still,
                         cupt_times, filter_results, settings, t0)


# --- vehicles: the error-state filter ---------------------------------------------------------
def compare_runs(
    imu: pd.DataFrame,
    initial: NavState,
    truth: pd.DataFrame,
    *,
    still: np.ndarray | pd.Series | Stillness | None = None,
    control_points: pd.DataFrame | None = None,
    gnss: pd.DataFrame | None = None,
    gnss_lever_arm=(0.0, 0.0, 0.0),
    runs: list[str] | tuple[str, ...] | None = None,
    config: FilterConfig | None = None,
    settings: CompareSettings | None = None,
    progress: bool = False,
    job_solutions: dict[str, pd.DataFrame] | None = None,
    truth_lever_arm=None,
    job_rejected: dict[str, pd.DataFrame] | None = None,
) -> CompareResult:
    """Run the same IMU data with each aiding set and compare the errors against ``truth``.

    Parameters
    ----------
    imu : DataFrame
        IMU table (body RFU), first row at ``initial.time``.
    initial : NavState
        Common initial state of every run.
    truth : DataFrame
        Truth trajectory (``NAV_COLS``, optional ``stationary``) or local ``x y`` positions.
    still : bool array / Series / Stillness, optional
        Stillness at the IMU rate (detector output or declared intervals); needed by the
        ZUPT runs (they are skipped without it).
    control_points : DataFrame, optional
        ``lat lon height`` [rad, m] (+ optional ``east_std north_std up_std``), indexed by time
        (time-triggered) or with a NaN / missing index time (position-triggered, see
        :func:`cupt_times_from_positions`). Needed by ``zupt_cupt``.
    gnss : DataFrame, optional
        GNSS table (insgnss conventions) for the ``gnss`` run.
    runs : sequence of str, optional
        Subset of :data:`RUNS` (default: every run the inputs allow).
    config : FilterConfig, optional
        Filter configuration shared by all runs.
    settings : CompareSettings, optional
    job_solutions : dict, optional
        ``{"job": forward, "job_smoothed": smoothed}`` of the job's own processing (all its
        aiding and outages, :func:`insgnss.pipeline.run_job`), and ``riss``/``riss_smoothed``
        for the same job with the RISS process model, compared like the other runs.
    truth_lever_arm : 3-vector, optional
        Body-frame offset [m, RFU] from the IMU to the point the truth measures (e.g. a GNSS
        antenna for an RTK reference); the solutions are moved there before comparing.
    job_rejected : dict, optional
        The rejection logs of the ``job_solutions`` runs (``FilterResult.rejected``), for the
        table's ``rejected`` column.

    Returns
    -------
    CompareResult
    """
    from dataclasses import replace

    s = settings or CompareSettings()
    cfg = replace(config) if config is not None else FilterConfig()
    if s.solution == "smoothed":
        cfg.smoother = True
    if not s.gate_zupt:  # the updates the comparison is about are not gated (CompareSettings)
        cfg.gate_probabilities = {**cfg.gate_probabilities, "zupt": 0.0, "zaru": 0.0,
                                  Cupt.name: 0.0}
    t = imu.index.to_numpy(float)
    if isinstance(still, Stillness):
        still = still.still
    still_arr = None if still is None else np.asarray(still, bool)
    if still_arr is not None and still_arr.size != t.size:
        raise ConfigError("stillness mask length differs from the IMU table", column="still",
                          expected=t.size, found=still_arr.size)
    available = ["free"]
    if still_arr is not None and still_arr.any():
        available += ["zupt", "zupt_zaru"]
        if control_points is not None and len(control_points):
            available.append("zupt_cupt")
    if gnss is not None and len(gnss):
        available.append("gnss")
    job_solutions = {k: v for k, v in (job_solutions or {}).items() if v is not None}
    available += [k for k in ("job", "job_smoothed", "riss", "riss_smoothed")
                  if k in job_solutions]
    runs = [r for r in (runs or RUNS) if r in available]
    unknown = set(runs) - set(RUNS)
    if unknown:
        raise ConfigError("unknown comparison run", column="runs", expected=list(RUNS),
                          found=sorted(unknown))
    ts = still_update_times(t, still_arr, s.zupt_interval) if still_arr is not None else None
    solutions, results = {}, {}
    cupt_times = np.empty(0)

    def run_one(name, meas):
        res = run_filter(imu, initial, meas, cfg, progress=progress)
        results[name] = res
        sol = res.smoothed if s.solution == "smoothed" and res.smoothed is not None \
            else res.forward
        solutions[name] = sol[NAV_COLS]
        return sol

    for run in runs:
        if run == "free":
            run_one(run, [])
        elif run == "zupt":
            run_one(run, [SpeedGatedZupt(ts, s.zupt_std, s.max_speed)])
        elif run == "zupt_zaru":
            run_one(run, [SpeedGatedZupt(ts, s.zupt_std, s.max_speed),
                          SpeedGatedZaru(ts, s.max_speed, std=s.zaru_std)])
        elif run == "zupt_cupt":
            cp = control_points
            times = np.asarray(cp.index, float) if cp.index.name == "time" else \
                np.full(len(cp), np.nan)
            if np.isnan(times).any():  # position-triggered: locate with the ZUPT-only run
                if "zupt" not in solutions:
                    run_one("_zupt_locate", [SpeedGatedZupt(ts, s.zupt_std, s.max_speed)])
                    base = solutions.pop("_zupt_locate")
                    results.pop("_zupt_locate")
                else:
                    base = solutions["zupt"]
                cp = cupt_times_from_positions(base, still_arr, cp, s.cupt_radius)
            cupt_times = np.asarray(cp.index, float)
            meas = [SpeedGatedZupt(ts, s.zupt_std, s.max_speed)]
            if len(cp):
                meas.append(_cupt(cp, s.cupt_std))
            run_one(run, meas)
        elif run == "gnss":
            meas = [GnssPosition(gnss, lever_arm=gnss_lever_arm)]
            if {"vel_e", "vel_n", "vel_u"} <= set(gnss.columns):
                meas.append(GnssVelocity(gnss, lever_arm=gnss_lever_arm))
            run_one(run, meas)
        elif run in ("job", "job_smoothed", "riss", "riss_smoothed"):
            solutions[run] = job_solutions[run].loc[t[0]:][NAV_COLS]
    return _finish(runs, solutions, truth, still_arr, t, s, results, cupt_times, float(t[0]),
                   truth_lever_arm, {k: v for k, v in (job_rejected or {}).items() if k in runs})


# --- foot-mounted: the compiled pedestrian filter ---------------------------------------------
def compare_foot_runs(
    imu: pd.DataFrame,
    truth: pd.DataFrame,
    config=None,
    *,
    runs: list[str] | tuple[str, ...] | None = None,
    settings: CompareSettings | None = None,
    lat: float = 0.0,
    lon: float = 0.0,
    height: float = 0.0,
) -> CompareResult:
    """Foot-mounted comparison: free inertial, ZUPT and ZUPT+ZARU with the foot preset
    (:func:`insgnss.foot.run_foot_ins`) on one IMU table, against a truth (``NAV_COLS`` or
    local ``x y``). ``config`` is a :class:`insgnss.foot.FootConfig` (default: the preset)."""
    from dataclasses import replace

    from .foot import FootConfig, run_foot_ins

    s = settings or CompareSettings(fit_window=(1.0, 30.0))
    cfg = config or FootConfig()
    runs = [r for r in (runs or ("free", "zupt", "zupt_zaru")) if r in ("free", "zupt",
                                                                       "zupt_zaru")]
    smooth = s.solution == "smoothed"
    base = run_foot_ins(imu, replace(cfg, smooth=smooth), lat=lat, lon=lon, height=height)
    still = base.stillness.still.to_numpy(bool)
    solutions = {}
    for run in runs:
        if run == "free":
            nav = mechanize(imu, base.initial, gravity_model=cfg.gravity_model)
            from .earth import geodetic_to_enu

            e, n, u = geodetic_to_enu(nav["lat"].to_numpy(), nav["lon"].to_numpy(),
                                      nav["height"].to_numpy(), base.initial.lat,
                                      base.initial.lon, base.initial.height)
            nav["east"], nav["north"], nav["up"] = e, n, u
            solutions[run] = nav
        elif run == "zupt":
            r = run_foot_ins(imu, replace(cfg, zaru=False, smooth=smooth), still=base.stillness,
                             initial=base.initial, lat=lat, lon=lon, height=height)
            solutions[run] = r.trajectory
        else:
            solutions[run] = base.trajectory
    t = imu.index.to_numpy(float)
    return _finish(runs, solutions, truth, still, t, s, {}, np.empty(0), float(t[0]))


# --- figures ---------------------------------------------------------------------------------
def plot_drift(result: CompareResult, path: str | Path, title: str = "") -> Path:
    """Log-log horizontal position error of every run against the time since the start, with
    ``t``, ``t^2``, ``t^3`` reference slopes through the free-inertial error at the start of the
    fit window."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    for run in result.runs:
        e = result.errors[run]["horizontal"]
        tr = e.index.to_numpy(float) - result.t0
        ok = (tr > 0) & (e.to_numpy() > 0)
        b = result.growth[run][0]
        lab = LABELS.get(run, run) + (f" (slope {b:.2f})" if run == "free" and np.isfinite(b)
                                      else "")
        ax.loglog(tr[ok], e.to_numpy()[ok], color=COLORS.get(run), ls=STYLES.get(run, "-"),
                  lw=1.3, label=lab)
    if "free" in result.errors:
        e = result.errors["free"]["horizontal"]
        tr = e.index.to_numpy(float) - result.t0
        t_a, t_b = result.settings.fit_window
        t_b = min(t_b, tr[-1])
        e_a = float(np.interp(t_a, tr, e.to_numpy()))
        if e_a > 0 and t_b > t_a:
            tt = np.logspace(np.log10(t_a), np.log10(t_b), 20)
            for p, ls in ((1, ":"), (2, "--"), (3, "-.")):
                ax.loglog(tt, e_a * (tt / t_a) ** p, color="k", ls=ls, lw=0.8,
                          label=f"$t^{p}$" if p > 1 else "$t$")
            ax.axvspan(t_a, t_b, color="0.92", zorder=0)
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("horizontal position error [m]")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or "Drift: free inertial vs aided")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_errors(result: CompareResult, path: str | Path, title: str = "") -> Path:
    """Position, velocity and heading errors of every run against time (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in ("horizontal", "velocity", "heading")
            if any(k in e for e in result.errors.values())]
    fig, axs = plt.subplots(len(keys), 1, figsize=(8, 2.6 * len(keys)), sharex=True,
                            squeeze=False)
    units = {"horizontal": "horizontal position error [m]", "velocity": "velocity error [m/s]",
             "heading": "|heading error| [deg]"}
    for ax, k in zip(axs[:, 0], keys, strict=True):
        for run in result.runs:
            e = result.errors[run]
            if k not in e:
                continue
            y = np.abs(e[k].to_numpy(float))
            if k == "heading":
                y = np.degrees(y)
            ax.semilogy(e.index.to_numpy(float) - result.t0, np.maximum(y, 1e-6),
                        color=COLORS.get(run), ls=STYLES.get(run, "-"), lw=1.0,
                        label=LABELS.get(run, run))
        ax.set_ylabel(units[k], fontsize=8)
        ax.grid(True, which="both", lw=0.3)
    axs[0, 0].legend(fontsize=8, ncol=3)
    axs[-1, 0].set_xlabel("time since start [s]")
    if title:
        axs[0, 0].set_title(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def format_table(table: pd.DataFrame) -> str:
    """Plain-text rendering of :func:`summary_table` for the terminal."""
    cols = [c for c in ("final_h_err_m", "max_h_err_m", "rms_h_err_m", "final_v_err_m",
                        "rms_vel_err_m_s", "max_stop_vel_err_m_s", "final_heading_err_deg",
                        "growth_exponent") if c in table.columns]
    head = f"{'run':14s}" + "".join(f"{c:>22s}" for c in cols) + f"{'rejected':>10s}"
    lines = [head]
    for run, row in table.iterrows():
        rej = int(row.get("rejected", 0))
        types = row.get("rejected_types") or ""
        lines.append(f"{run:14s}" + "".join(f"{row[c]:22.4g}" for c in cols) + f"{rej:10d}"
                     + (f"  ({types})" if types else ""))
    return "\n".join(lines)


def settings_dict(s: CompareSettings) -> dict:
    return asdict(s)
