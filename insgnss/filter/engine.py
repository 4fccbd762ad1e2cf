"""Closed-loop error-state Kalman filter (INS/GNSS and friends) on filterpy.

Event loop
----------
Filter *epochs* are the measurement times (snapped to an IMU sample when within a
microsecond-scale tolerance) plus a grid every ``epoch_interval`` seconds (so that the
stored covariances and the smoother have nodes during long outages). Between consecutive
epochs:

1. :func:`.kernels.propagate_nominal` (numba) runs the strapdown mechanization
   (:func:`insgnss.mechanization.strapdown.strapdown_step`) over the IMU samples with the
   increments compensated by the current bias / scale-factor estimates, stores the nominal
   trajectory at the IMU rate and integrates the error dynamics F and the noise over
   covariance sub-intervals of ``propagation_interval`` seconds. An IMU interval that
   straddles an epoch is split (linear share of its increments).
2. :func:`.kernels.discretize` (numba) turns each sub-interval into ``Phi, Qd`` (second
   order or van Loan) and composes them over the segment.
3. ``filterpy.kalman.predict`` propagates ``x, P`` with the composed ``Phi, Qd`` (exactly
   the same P as propagating every sub-interval in turn).
4. Each measurement at the epoch gives ``(z, H, R)``; the innovation passes a chi-square
   gate (``NIS <= chi2.ppf(p, dof)``) or is rejected and logged; accepted ones are applied
   with ``filterpy.kalman.update`` (Joseph form ``(I-KH) P (I-KH)^T + K R K^T``).
5. Closed loop: the error estimate is fed back into the nominal state (position,
   velocity, attitude, biases, scale factors, extra states) and reset to zero.

Everything needed by the RTS smoother (:mod:`.smoother`) is stored per epoch.

Health: non-finite ``x``/``P`` or a ``P`` that is not positive definite raises
:class:`insgnss.errors.FilterHealthError` internally; so does a *runaway NIS*: when, for one
measurement type, the median normalized innovation ``NIS / dof`` (before gating, so rejected
measurements count) over the last ``nis_window`` seconds exceeds ``nis_bound`` (at least
``nis_min_count`` measurements in the window). A consistent filter has a median ``NIS / dof``
below 1 (about 0.45-0.8 for 1-3 dof); a median beyond 25 means the measurements sit 5 sigma
away most of the time, i.e. the filter has diverged or its noise model is badly wrong, and its
solution should not be trusted silently. :func:`run_filter` catches the error and returns what
was computed up to the last good epoch with ``complete=False``.
"""

from __future__ import annotations

import time as _time
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from filterpy.kalman import predict as kf_predict
from filterpy.kalman import update as kf_update
from scipy.stats import chi2

from .. import earth
from ..errors import ConfigError, FilterHealthError, InvalidValueError
from ..imu import ImuErrorModel, coning_sculling, grade, increments
from ..mechanization.strapdown import NavState, attitude_update_id
from . import kernels
from .measurements import Measurement, NominalState
from .models import BIAS_MODELS, StateLayout, process_model
from .smoother import STD_COLS, assemble_table, output_columns, smooth

__all__ = ["BIAS_COLS", "STD_COLS", "FilterConfig", "FilterResult", "run_filter"]

BIAS_COLS = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
             "accel_bias_x", "accel_bias_y", "accel_bias_z"]
DISCRETIZATIONS = {"second_order": kernels.DISC_SECOND_ORDER, "vanloan": kernels.DISC_VANLOAN}


@dataclass
class FilterConfig:
    """Configuration of :func:`run_filter` (SI units, radians).

    Attributes
    ----------
    imu_model : ImuErrorModel or str
        IMU error model or grade preset name (``"navigation"``, ``"tactical"``, ``"mems"``).
    bias_model : {"gauss_markov", "random_walk", "random_constant"}
        See :func:`insgnss.filter.models.process_model`.
    scale_factors : bool
        Estimate gyro and accelerometer scale factors (21 states).
    propagation_interval : float
        Covariance sub-interval [s] over which F is averaged for ``Phi, Qd``.
    epoch_interval : float
        Longest time between filter epochs without measurements [s].
    discretization : {"second_order", "vanloan"}
    gate_probability : float or None
        Default chi-square gating probability; ``None`` or 0 disables gating.
    gate_probabilities : dict
        Per measurement type (``Measurement.name``) overrides.
    levelling_correlation : bool
        The initial roll and pitch come from accelerometer levelling with the initial nominal
        accelerometer bias: the tilt error is then the horizontal bias error over g, fully
        correlated with it (``phi_n = (C db)_e / g``, ``phi_e = -(C db)_n / g``). ``P0`` gets
        that cross-covariance and the tilt variance it implies; ``initial_att_std`` then only
        carries the other (noise) part of the tilt error.
    gate_recovery : float or None
        When every measurement of one type has been rejected for longer than this [s] (an
        unbroken run of at least 3 rejections, with no gap longer than this between them), the
        filter's covariance is taken to be wrong, not the measurements: the navigation blocks
        (position, velocity, attitude) of ``P`` are inflated until the measurement sits on the
        gate and it is applied (logged with ``recovered=True``). ``None`` disables it (a filter
        that lost lock then never recovers).
    smoother : bool
        Run the RTS smoother.
    initial_pos_std, initial_vel_std : float or 3-vector
        [m], [m/s] (ENU).
    initial_att_std : float or 3-vector
        Misalignment std (east, north, up) [rad]; the up component is the heading std.
    initial_gyro_bias_std, initial_accel_bias_std, initial_gyro_scale_std, initial_accel_scale_std
        Override the IMU model's values.
    gyro_bias, accel_bias : 3-vector, optional
        Initial nominal bias estimates (e.g. from alignment).
    gravity_model, attitude_update, coning
        Mechanization options (see :func:`insgnss.mechanization.strapdown.mechanize`).
    snap_tolerance : float
        Measurement times closer than this to an IMU sample are moved onto it [s].
    check_health : bool
        Check finiteness and positive definiteness at every epoch.
    nis_window : float or None
        Runaway-NIS window [s] (module docstring); ``None`` disables the check.
    nis_bound : float
        Largest allowed median ``NIS / dof`` over the window.
    nis_min_count : int
        Measurements of one type needed in the window before the check applies.
    extra_noise : DataFrame or None
        Extra process noise at given times, e.g. for IMU gaps the mechanization bridged
        (:func:`insgnss.policies.gap_noise`): indexed by time [s] with columns ``pos_std``
        [m], ``vel_std`` [m/s], ``att_std`` [rad] (the same on every axis); each row's variances
        are added to ``Qd`` of the propagation segment that contains its time.
    """

    imu_model: ImuErrorModel | str = "tactical"
    bias_model: str = "random_walk"
    scale_factors: bool = False
    propagation_interval: float = 0.1
    epoch_interval: float = 1.0
    discretization: str = "second_order"
    gate_probability: float | None = 0.9999
    gate_probabilities: dict = field(default_factory=dict)
    gate_recovery: float | None = 5.0
    levelling_correlation: bool = False
    smoother: bool = True
    initial_pos_std: float | tuple = 1.0
    initial_vel_std: float | tuple = 0.1
    initial_att_std: float | tuple = (np.deg2rad(0.5), np.deg2rad(0.5), np.deg2rad(2.0))
    initial_gyro_bias_std: float | tuple | None = None
    initial_accel_bias_std: float | tuple | None = None
    initial_gyro_scale_std: float | tuple | None = None
    initial_accel_scale_std: float | tuple | None = None
    gyro_bias: tuple | None = None
    accel_bias: tuple | None = None
    gravity_model: str = "somigliana"
    attitude_update: str = "exact"
    coning: bool = False
    snap_tolerance: float = 1e-6
    check_health: bool = True
    nis_window: float | None = 30.0
    nis_bound: float = 25.0
    nis_min_count: int = 10
    extra_noise: pd.DataFrame | None = None

    def validate(self) -> None:
        if self.bias_model not in BIAS_MODELS:
            raise ConfigError(f"unknown bias_model {self.bias_model!r}", column="bias_model",
                              expected=list(BIAS_MODELS), found=self.bias_model)
        if self.discretization not in DISCRETIZATIONS:
            raise ConfigError("unknown discretization", column="discretization",
                              expected=list(DISCRETIZATIONS), found=self.discretization)
        for key in ("propagation_interval", "epoch_interval"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError("must be a positive number of seconds", column=key, found=v)
        if self.nis_window is not None and not (np.isfinite(self.nis_window)
                                                and self.nis_window > 0):
            raise ConfigError("NIS window must be a positive number of seconds or None",
                              column="nis_window", found=self.nis_window)
        if not (self.nis_bound > 0):
            raise ConfigError("NIS bound must be positive", column="nis_bound",
                              found=self.nis_bound)
        for p in [self.gate_probability, *self.gate_probabilities.values()]:
            if p is not None and not (0.0 <= p < 1.0):
                raise ConfigError("gating probability must be in [0, 1)", column="gate_probability",
                                  found=p)


@dataclass
class FilterResult:
    """Output of :func:`run_filter`.

    Attributes
    ----------
    forward : DataFrame
        IMU-rate forward (causal) solution: ``NAV_COLS``, ``STD_COLS`` and every parameter
        state (``gyro_bias_x .. accel_bias_z``, scale factors, extras) with a ``_std`` column.
    smoothed : DataFrame or None
        The same columns from the RTS smoother.
    innovations : DataFrame
        One row per measurement evaluated: ``time type dof nis threshold accepted recovered`` and
        ``innov_k``, ``innov_std_k`` for each component.
    rejected : DataFrame
        The rows of ``innovations`` that the gate rejected.
    complete : bool
        False if the filter stopped early (see ``error``).
    error : Exception or None
    timing : dict
        Seconds spent in ``mechanization``, ``covariance``, ``updates``, ``smoother``,
        ``output`` and ``total``.
    layout : StateLayout
    epoch_times : (E,) array
    P_filtered, P_predicted : (E, n, n) arrays
        ``P(e|e)`` and ``P(e|e-1)`` at the filter epochs.
    feedback : (E, n) array
        Error estimate removed from the nominal at each epoch.
    P_smoothed : (E, n, n) array or None
    final : NavState
        Nominal state at the last processed epoch.
    """

    forward: pd.DataFrame
    smoothed: pd.DataFrame | None
    innovations: pd.DataFrame
    rejected: pd.DataFrame
    complete: bool
    timing: dict
    layout: StateLayout
    epoch_times: np.ndarray
    P_filtered: np.ndarray
    P_predicted: np.ndarray
    feedback: np.ndarray
    P_smoothed: np.ndarray | None = None
    error: Exception | None = None
    final: NavState | None = None
    params: np.ndarray | None = field(default=None, repr=False)


class _Store:
    """Per-run arrays shared by the engine, the smoother and the output assembly."""

    def __init__(self, n_t, n_ep, n, n_cols):
        # the forward table itself: the kernel writes the nominal into columns 0-8, the
        # output assembly the stds and parameters (no second copy of the trajectory)
        self.nav = np.empty((n_t, n_cols))
        self.seg = np.zeros(n_t, np.int64)
        self.post = np.zeros(n_t, np.bool_)
        self.Pf = np.empty((n_ep, n, n))
        self.Pp = np.empty((n_ep, n, n))
        self.Phi = np.empty((n_ep, n, n))
        self.fb = np.zeros((n_ep, n))
        self.pnom = np.empty((n_ep, n - 9))


def _epoch_schedule(t, measurements, epoch_interval, tol):
    """Epoch times and, per epoch, the (measurement index, row) events in order."""
    t0, t1 = t[0], t[-1]
    times, mi, ri = [], [], []
    for k, m in enumerate(measurements):
        tm = np.asarray(m.times, float)
        rows = np.nonzero((tm >= t0 - tol) & (tm <= t1 + tol))[0]
        tm = np.clip(tm[rows], t0, t1)
        # snap to IMU samples
        j = np.clip(np.searchsorted(t, tm), 1, t.size - 1)
        near = np.where(np.abs(t[j] - tm) < np.abs(t[j - 1] - tm), j, j - 1)
        tm = np.where(np.abs(t[near] - tm) <= tol, t[near], tm)
        times.append(tm)
        mi.append(np.full(rows.size, k))
        ri.append(rows)
    n_grid = int(np.floor((t1 - t0) / epoch_interval + 1e-9))
    grid = t0 + epoch_interval * np.arange(n_grid + 1)
    grid = np.append(grid, t1)
    j = np.clip(np.searchsorted(t, grid), 1, t.size - 1)
    near = np.where(np.abs(t[j] - grid) < np.abs(t[j - 1] - grid), j, j - 1)
    grid = np.where(np.abs(t[near] - grid) <= tol, t[near], grid)
    ev_t = np.concatenate(times) if times else np.empty(0)
    ev_m = np.concatenate(mi).astype(np.int64) if mi else np.empty(0, np.int64)
    ev_r = np.concatenate(ri).astype(np.int64) if ri else np.empty(0, np.int64)
    ep = np.unique(np.concatenate([grid, ev_t]))
    # merge epochs closer than the tolerance
    keep = np.concatenate([[True], np.diff(ep) > tol])
    ep = ep[keep]
    ev_e = np.clip(np.searchsorted(ep, ev_t - tol), 0, ep.size - 1)
    order = np.lexsort((ev_r, ev_m, ev_e))
    ev_e, ev_m, ev_r = ev_e[order], ev_m[order], ev_r[order]
    ptr = np.searchsorted(ev_e, np.arange(ep.size + 1))
    return ep, ev_m, ev_r, ptr


def innovation_tables(log: list, recoveries: list) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Innovation log and rejected rows from the per-measurement records
    ``(time, type, dof, nis, threshold, accepted, innovation, S)`` (shared with the RISS
    filter, so both produce the same columns)."""
    ncomp = max((r[2] for r in log), default=0)
    cols = {"time": [r[0] for r in log], "type": [r[1] for r in log],
            "dof": [r[2] for r in log], "nis": [r[3] for r in log],
            "threshold": [r[4] for r in log], "accepted": [bool(r[5]) for r in log]}
    rec = set(recoveries)
    cols["recovered"] = [(r[0], r[1]) in rec for r in log]
    for k in range(ncomp):
        cols[f"innov_{k}"] = [r[6][k] if r[2] > k else np.nan for r in log]
    for k in range(ncomp):
        cols[f"innov_std_{k}"] = [np.sqrt(r[7][k, k]) if r[2] > k and r[7][k, k] >= 0 else np.nan
                                   for r in log]
    innovations = pd.DataFrame(cols)
    rejected = innovations[~innovations["accepted"]].reset_index(drop=True)
    return innovations, rejected


def levelling_covariance(P, C, att: slice, accel_bias: slice, g: float) -> np.ndarray:
    """``P`` with the tilt / horizontal accelerometer-bias correlation of a levelled start.

    Levelling sets ``C`` so that ``C^T (0, 0, g) = f_mean``; with an accelerometer bias error
    ``db`` (nominal minus true) the misalignment is ``phi x g^l = C db``, i.e. ``phi = J db`` with
    ``J = [[0, -1, 0], [1, 0, 0], [0, 0, 0]] C / g``. Adds ``J P_b J^T`` to the attitude block
    and ``J P_b`` as the cross-covariance (errors "nominal minus true", ``C = (I + [phi x])
    C_true``).
    """
    P = P.copy()
    J = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]) @ C / g
    Pb = P[accel_bias, accel_bias]
    cross = J @ Pb
    P[att, att] += cross @ J.T
    P[att, accel_bias] = cross
    P[accel_bias, att] = cross.T
    return P


def _inflate_for(P, H, R, z, thr):
    """P with its navigation blocks (states 0-8) scaled so that ``z`` has NIS ~ thr / 2."""
    P = P.copy()
    nav = slice(0, 9)
    Hn = H[:, nav]
    for _ in range(60):
        S = H @ P @ H.T + R
        if kernels.nis(S, z) <= 0.5 * thr or not np.any(Hn):
            break
        P[nav, :] *= 2.0 ** 0.5
        P[:, nav] *= 2.0 ** 0.5
    return P


def _check(x, P, time, what, full=True):
    """Raise FilterHealthError if x or P is non-finite or (``full``) P is not positive definite."""
    if not np.isfinite(x.sum() + P.sum()):
        raise FilterHealthError(f"filter state became non-finite at t = {time:.6f} s ({what})",
                                found="NaN/inf in x or P")
    if not full:
        return
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        raise FilterHealthError(
            f"covariance is not positive definite at t = {time:.6f} s ({what})",
            found="Cholesky factorisation failed") from None


def _runaway_nis(hist: dict, name: str, time: float, nnis: float, config: FilterConfig) -> None:
    """Record one normalized NIS and raise FilterHealthError when its window median runs away."""
    rec = hist.get(name)
    if rec is None:
        rec = hist[name] = [deque(), -np.inf]
    q = rec[0]
    q.append((time, nnis if np.isfinite(nnis) else np.inf))
    while q and q[0][0] < time - config.nis_window:
        q.popleft()
    # the median is taken at most once per second per type (a 10 Hz NHC keeps ~300 values)
    if len(q) < config.nis_min_count or time - rec[1] < 1.0:
        return
    rec[1] = time
    vals = sorted(v for _, v in q)  # exact median; sorted() beats np.median on ~30 values
    k = len(vals) // 2
    med = vals[k] if len(vals) % 2 else 0.5 * (vals[k - 1] + vals[k])
    if med > config.nis_bound:
        raise FilterHealthError(
            f"runaway NIS at t = {time:.6f} s: the median NIS/dof of the {name!r} measurements over "
            f"the last {config.nis_window:g} s is {med:.4g} (filter diverged or measurement noise "
            "far too small)", column=name, expected=f"a median NIS/dof <= {config.nis_bound:g}",
            found=f"{med:.4g} over {len(q)} measurements")


def run_filter(
    imu: pd.DataFrame,
    initial: NavState,
    measurements: list[Measurement],
    config: FilterConfig | None = None,
    progress: bool = False,
) -> FilterResult:
    """Run the closed-loop error-state filter (and the RTS smoother) over an IMU table.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments, :mod:`insgnss.imu`) indexed by time [s]; its first
        row is the epoch of ``initial``.
    initial : NavState
        Initial nominal state (e.g. from alignment) at the first IMU time.
    measurements : list of Measurement
        Aiding measurement models (:mod:`insgnss.filter.measurements`).
    config : FilterConfig
    progress : bool
        Show a progress bar (tqdm) over the filter epochs.

    Returns
    -------
    FilterResult
    """
    t_start_total = _time.perf_counter()
    config = FilterConfig() if config is None else config
    config.validate()
    measurements = list(measurements)
    imu_model = grade(config.imu_model) if isinstance(config.imu_model, str) else config.imu_model

    t, dth, dv = increments(imu)
    if t.size < 2:
        raise InvalidValueError("IMU table needs at least two samples", found=t.size)
    if not np.all(np.diff(t) > 0):
        raise InvalidValueError("IMU times must be strictly increasing")
    if config.coning:
        dth, dv = coning_sculling(dth, dv)
    dth = np.ascontiguousarray(dth, dtype=float)
    dv = np.ascontiguousarray(dv, dtype=float)

    extras = []
    for m in measurements:
        extras.extend(m.extra_states())
    layout = StateLayout(config.scale_factors, extras)
    pm = process_model(
        layout, imu_model, config.bias_model, config.initial_pos_std, config.initial_vel_std,
        config.initial_att_std, config.initial_gyro_bias_std, config.initial_accel_bias_std,
        config.initial_gyro_scale_std, config.initial_accel_scale_std, config.gyro_bias,
        config.accel_bias)
    n = layout.n
    i_sg, i_sa = layout.index("gyro_scale"), layout.index("accel_scale")

    tol = min(config.snap_tolerance, 1e-3 * float(np.median(np.diff(t))))
    ep_t, ev_m, ev_r, ptr = _epoch_schedule(t, measurements, config.epoch_interval, tol)
    n_ep = ep_t.size
    st = _Store(t.size, n_ep, n, len(output_columns(layout)))
    max_gap = float(np.max(np.diff(ep_t))) if n_ep > 1 else 0.0
    max_sub = min(int(np.ceil(max_gap / config.propagation_interval)),
                  int(np.ceil(max_gap / np.min(np.diff(t))))) + 3
    Fint = np.zeros((max_sub, n, n))
    Qint = np.zeros((max_sub, 2, 3, 3))
    sub_dt = np.zeros(max_sub)
    Phi = np.eye(n)
    Qd = np.zeros((n, n))
    rates = np.zeros((4, 3))
    method = DISCRETIZATIONS[config.discretization]
    gmodel = earth.gravity_model_id(config.gravity_model)
    aupd = attitude_update_id(config.attitude_update)

    pos = np.array([initial.lat, initial.lon, initial.height], float)
    vel = np.array(initial.vel, float).copy()
    C = np.ascontiguousarray(initial.C, dtype=float).copy()
    pnom = pm.initial_values.copy()
    x = np.zeros(n)
    P = np.diag(pm.p0**2)
    if config.levelling_correlation:
        P = levelling_covariance(P, C, layout["att"], layout["accel_bias"],
                                 earth.normal_gravity(initial.lat, initial.height,
                                                      config.gravity_model))
    par_decay = pm.decay[9:].copy()
    has_decay = bool(np.any(par_decay > 0))
    I_n = np.eye(n)
    if config.extra_noise is not None and len(config.extra_noise):
        xn_t = np.asarray(config.extra_noise.index, float)
        xn_var = config.extra_noise[["pos_std", "vel_std", "att_std"]].to_numpy(float) ** 2
    else:
        xn_t, xn_var = np.empty(0), np.empty((0, 3))
    xn_i = int(np.searchsorted(xn_t, ep_t[0], side="right"))

    nav = NominalState()
    nav.layout = layout
    nav.gyro_psd = pm.gyro_psd
    gate_cache: dict = {}
    log = []  # (time, type, dof, nis, threshold, accepted, y, s)
    streak: dict = {}  # measurement type -> [first, last rejection time, count] of its streak
    nis_hist: dict = {}  # measurement type -> deque of (time, NIS / dof) for the runaway check
    nis_check = config.check_health and config.nis_window is not None
    recoveries: list = []

    timing = {"mechanization": 0.0, "covariance": 0.0, "updates": 0.0}
    j, frac = 1, 0.0
    kernels.store_nav(st.nav, 0, pos, vel, C)
    st.seg[0], st.post[0] = 0, True
    completed = -1
    error = None
    iterator = range(n_ep)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, total=n_ep, unit="epoch", desc="filter")
    perf = _time.perf_counter
    try:
        for e in iterator:
            te = ep_t[e]
            if e > 0:
                c0 = perf()
                j, frac, n_sub = kernels.propagate_nominal(
                    t, dth, dv, j, frac, te, pos, vel, C, pnom, i_sg, i_sa, gmodel, aupd,
                    config.propagation_interval, Fint, Qint, sub_dt, pm.gyro_psd, pm.accel_psd,
                    st.nav, st.seg, e, rates)
                seg_dur = te - ep_t[e - 1]
                if has_decay:
                    # the nominal of a Gauss-Markov parameter follows its mean, b' = -b / tau
                    pnom *= np.exp(-par_decay * seg_dur)
                c1 = perf()
                kernels.discretize(Fint, Qint, sub_dt, n_sub, pm.decay, pm.qdiag, method, Phi, Qd)
                if xn_i < xn_t.size and xn_t[xn_i] <= te:
                    Qd = Qd.copy()
                    while xn_i < xn_t.size and xn_t[xn_i] <= te:
                        for blk in range(3):  # position, velocity, attitude
                            i3 = np.arange(3 * blk, 3 * blk + 3)
                            Qd[i3, i3] += xn_var[xn_i, blk]
                        xn_i += 1
                x, P = kf_predict(x, P, Phi, Qd)
                if config.check_health:
                    if not np.isfinite(pos.sum() + vel.sum() + C.sum()):
                        raise FilterHealthError(
                            f"nominal state became non-finite at t = {te:.6f} s (mechanization; "
                            "non-finite IMU data?)", found="NaN/inf in position/velocity/attitude")
                    # full check (Cholesky) here only if no update follows at this epoch
                    _check(x, P, te, "prediction", full=ptr[e + 1] == ptr[e])
                c2 = perf()
                timing["mechanization"] += c1 - c0
                timing["covariance"] += c2 - c1
                st.Phi[e] = Phi
            else:
                st.Phi[e] = I_n
                seg_dur = 0.0
            st.Pp[e] = P
            c0 = perf()
            k0, k1 = ptr[e], ptr[e + 1]
            if k1 > k0:
                nav.time = te
                nav.lat, nav.lon, nav.height = pos[0], pos[1], pos[2]
                nav.vel, nav.C = vel, C
                nav.omega_ib, nav.omega_ib_mean = rates[0], rates[1]
                nav.f_ib, nav.f_ib_mean = rates[2], rates[3]
                nav.segment_duration = seg_dur
                nav.params = pnom
                nav.M, nav.N = earth.radii(pos[0])
                zs, Hs, Rs = [], [], []
                for k in range(k0, k1):
                    m = measurements[ev_m[k]]
                    res = m.evaluate(int(ev_r[k]), nav)
                    if res is None:
                        continue
                    z, H, R = res
                    if not (isinstance(z, np.ndarray) and z.ndim == 1):
                        z = np.atleast_1d(np.asarray(z, dtype=float))
                    if not (isinstance(R, np.ndarray) and R.ndim == 2):
                        R = np.atleast_2d(np.asarray(R, dtype=float))
                    dof = z.size
                    # x is zero here (reset after the previous epoch), so y = z; every
                    # measurement of the epoch is gated against the predicted P
                    S = H @ P @ H.T + R
                    nis = kernels.nis(S, z)
                    if nis_check:
                        _runaway_nis(nis_hist, m.name, te, nis / dof, config)
                    p_gate = m.gate_probability
                    if p_gate is None:
                        p_gate = config.gate_probabilities.get(m.name, config.gate_probability)
                    if p_gate:
                        key = (p_gate, dof)
                        thr = gate_cache.get(key)
                        if thr is None:
                            thr = gate_cache[key] = float(chi2.ppf(p_gate, dof))
                    else:
                        thr = np.inf
                    ok = nis <= thr  # False for NaN
                    recovered = False
                    if ok:
                        streak.pop(m.name, None)
                    elif np.isfinite(nis):
                        # a streak is an unbroken run of rejections of one type: a gap longer
                        # than the recovery time without any (e.g. between two stops for ZUPT)
                        # starts a new one, so sparse measurements are not force-applied
                        rec = streak.get(m.name)
                        if rec is None or (config.gate_recovery is not None
                                           and te - rec[1] > config.gate_recovery):
                            rec = streak[m.name] = [te, te, 0]
                        rec[1] = te
                        rec[2] += 1
                        t_first = rec[0]
                        if config.gate_recovery is not None and rec[2] >= 3 and \
                                te - t_first > config.gate_recovery:
                            P = _inflate_for(P, H, R, z, thr)
                            S = H @ P @ H.T + R
                            nis = kernels.nis(S, z)
                            ok = recovered = True
                            streak.pop(m.name, None)
                    log.append((te, m.name, dof, nis, thr, ok, z, S))
                    if recovered:
                        recoveries.append((te, m.name))
                    if ok:
                        zs.append(z)
                        Hs.append(H)
                        Rs.append(R)
                if zs:
                    # one filterpy (Joseph-form) update with the accepted measurements stacked;
                    # their noises are independent, so this equals sequential updates
                    if len(zs) == 1:
                        z, H, R = zs[0], Hs[0], Rs[0]
                    else:
                        z, H = np.concatenate(zs), np.vstack(Hs)
                        R = np.zeros((z.size, z.size))
                        i0 = 0
                        for Rk in Rs:
                            i1 = i0 + Rk.shape[0]
                            R[i0:i1, i0:i1] = Rk
                            i0 = i1
                    if recoveries and recoveries[-1][0] == te:
                        st.Pp[e] = P  # the gate recovery inflated P(e|e-1): the smoother needs it
                    x, P = kf_update(x, P, z, R, H)
                    P = 0.5 * (P + P.T)
                    if config.check_health:
                        _check(x, P, te, "update")
                    st.fb[e] = x
                    kernels.apply_feedback(pos, vel, C, pnom, x)
                    x = np.zeros(n)
            timing["updates"] += perf() - c0
            st.Pf[e] = P
            st.pnom[e] = pnom
            # the IMU sample that sits on this epoch holds the post-feedback state
            if frac == 0.0 and t[j - 1] == te:
                kernels.store_nav(st.nav, j - 1, pos, vel, C)
                st.seg[j - 1], st.post[j - 1] = e, True
            completed = e
    except FilterHealthError as exc:
        error = exc

    n_ok = completed + 1
    # IMU-rate rows that belong to completed epochs
    n_rows = int(np.searchsorted(t, ep_t[completed], side="right")) if n_ok >= 1 else 0

    c0 = perf()
    forward = assemble_table(t, st, ep_t, n_rows, layout, None)
    timing["output"] = perf() - c0
    smoothed = None
    Ps = None
    timing["smoother"] = 0.0
    if config.smoother and n_ok >= 2:
        c0 = perf()
        xs_plus, xs_minus, Ps = smooth(st, n_ok)
        smoothed = assemble_table(t, st, ep_t, n_rows, layout, (xs_plus, xs_minus, Ps))
        timing["smoother"] = perf() - c0

    innovations, rejected = innovation_tables(log, recoveries)
    timing["total"] = perf() - t_start_total
    final = NavState(pos[0], pos[1], pos[2], vel.copy(), C.copy(), float(ep_t[max(completed, 0)]))
    return FilterResult(
        forward=forward, smoothed=smoothed, innovations=innovations, rejected=rejected,
        complete=error is None, timing=timing, layout=layout, epoch_times=ep_t[:n_ok].copy(),
        P_filtered=st.Pf[:n_ok], P_predicted=st.Pp[:n_ok], feedback=st.fb[:n_ok],
        P_smoothed=None if Ps is None else Ps[:n_ok], error=error, final=final,
        params=st.pnom[:n_ok])
