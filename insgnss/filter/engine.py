"""The filter engine: one closed-loop error-state Kalman filter for every process model.

Structure
---------
The engine owns the event loop and everything that does not depend on the process or the
measurement: the epoch schedule (:mod:`.schedule`), covariance propagation (compiled
``predict``, :mod:`.kalman`), gating and gate recovery (:mod:`.gating`), health checks
(:mod:`.health`), the stacked Joseph-form update (compiled ``update``, :mod:`.kalman`;
filterpy's with ``FilterConfig.kalman = "filterpy"``), closed-loop feedback and reset, the
smoother's storage and backward pass (:mod:`.store`, :mod:`.smoother`) and the compiled
high-rate path (:mod:`.highrate`). It has two plug points:

- the *process model* (:class:`.process.ProcessModelBase`: nominal propagation, ``Phi``,
  ``Qd``, feedback, state layout, the nominal seen by the measurements, output tables):
  :class:`.strapdown_model.StrapdownModel` (:func:`run_filter`) and
  :class:`.riss_model.RissModel` (:func:`insgnss.filter.riss_model.run_riss_filter`);
- the *measurement models* (:mod:`.measurements`: ``(z, H, R)`` at an epoch).

Event loop (:func:`run_engine`)
-------------------------------
For every epoch ``e`` (:func:`.schedule.build_schedule`):

1. *propagate*: if the segment holds high-rate measurements, the compiled path runs it sample
   by sample (a node per IMU sample, updates at the samples that have high-rate events); then
   the process model advances the nominal to the epoch and gives ``Phi, Qd``, and
   :func:`.kalman.predict` propagates ``x, P``;
2. *update*: each measurement at the epoch gives ``(z, H, R)`` (mapped onto the process
   model's state); the innovation passes a chi-square gate against the predicted ``P`` or is
   rejected and logged (gate recovery may inflate ``P``); the accepted ones are applied
   together with :func:`.kalman.update` (Joseph form ``(I-KH) P (I-KH)^T + K R K^T``;
   independent noises, so stacking equals sequential updates);
3. *feedback*: the error estimate is fed back into the nominal and reset to zero;
4. *store*: the node (``P(e|e-1)``, ``P(e|e)``, ``Phi``, feedback, the update's ``H, K,
   S^-1 H, S^-1 z`` and the nominal parameters) goes to the smoother's store.

After the loop the smoother runs backwards over the nodes and the process model assembles the
IMU-rate forward and smoothed tables.

Health: non-finite ``x``/``P``/nominal, a ``P`` that is not positive definite and a runaway NIS
(:mod:`.health`) raise :class:`insgnss.errors.FilterHealthError` internally; the engine catches
it and returns what was computed up to the last good node with ``complete=False``.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import ConfigError, FilterHealthError
from ..imu import ImuErrorModel
from ..mechanization.strapdown import NavState
from . import gating, health, highrate
from .gating import GateTable
from .heading_reinit import HeadingMonitor, HeadingReinit, reset_covariance
from .health import RunawayNis, check_covariance
from .kalman import KALMAN_BACKENDS, as_f64, smoother_record
from .kalman import backend as kalman_backend
from .measurements import Measurement
from .models import BIAS_MODELS, ERROR_DYNAMICS, StateLayout
from .process import ProcessModelBase
from .schedule import EPOCH_GRIDS, build_schedule
from .smoother import smooth
from .store import InnovationLog, NodeStore, Table, innovation_tables
from .strapdown_model import DISCRETIZATIONS, STD_COLS, StrapdownModel, levelling_covariance

__all__ = ["BIAS_COLS", "STD_COLS", "FilterConfig", "FilterResult", "run_filter", "run_engine",
           "levelling_covariance"]

BIAS_COLS = ["gyro_bias_x", "gyro_bias_y", "gyro_bias_z",
             "accel_bias_x", "accel_bias_y", "accel_bias_z"]


#: columns of ``FilterConfig.extra_noise`` (stds; missing ones are 0)
EXTRA_NOISE_COLS = ("pos_std", "vel_std", "att_std", "up_std")


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
    epoch_grid : {"gaps", "always"}
        Where the grid of epochs every ``epoch_interval`` is laid: only inside the gaps between
        measurement epochs longer than the interval (``"gaps"``, :func:`.schedule.gap_grid`)
        or at every grid time (``"always"``: nodes, ``P(k|k)`` and ``P(k|N)``, at the grid
        times, e.g. for a Monte Carlo NEES on a time grid).
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
    initial_parameters : dict, optional
        Initial nominal values of parameter states by state label (``"gyro_bias_z"``,
        ``"nhc_misalignment_x"``, ...; index 9 onwards of the layout), applied after
        ``gyro_bias`` / ``accel_bias`` and the extra states' ``initial_value``; the initial
        sigmas are unchanged. Used to re-linearize a second pass about the smoothed estimate of
        a first one (``[filter] smoother_passes``); labels the layout does not hold are ignored.
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
        Epochs (distinct times) with measurements of one type needed in the window before the
        check applies (one epoch of per-satellite rows counts once).
    extra_noise : DataFrame or None
        Extra process noise at given times, e.g. for IMU gaps the mechanization bridged
        (:func:`insgnss.policies.gap_noise`): indexed by time [s] with columns ``pos_std``
        [m], ``vel_std`` [m/s], ``att_std`` [rad] (the same on every axis) and, optionally,
        ``up_std`` [m] (the vertical position only; the foot profile's per-stride height
        noise); missing columns are 0. Each row's variances are added to ``Qd`` of the
        propagation segment that contains its time (segments end at epochs: a row meant for
        one instant needs an epoch there).
    error_dynamics : {"full", "short_term"}
        The strapdown error model: the full LLF dynamics (:mod:`.models`) or the short-term
        pedestrian form without Earth-rate, transport-rate and gravity-gradient couplings
        (:func:`.models.accumulate_short_term_dynamics`; used by the foot-mounted profile).
    accel_dynamic_noise, gyro_dynamic_noise : float
        Dynamics-dependent process noise [fraction]: a white error of this fraction of each
        IMU interval's dynamic velocity increment ``|C dv - g dt|`` and angle increment
        ``|dtheta|`` (unmodelled scale-factor, g-sensitivity and vibration errors; used by the
        foot-mounted profile). 0: none.
    smoother_covariance : bool
        Run the smoother's covariance recursion (smoothed ``*_std`` columns and
        ``P_smoothed``); without it the smoothed table has NaN stds (cheaper at high rate).
    heading_reinit : HeadingReinit or None
        Re-initialise the heading of a land vehicle from the GNSS course when it disagrees
        with it while the GNSS innovations run away (:mod:`.heading_reinit`; LLF strapdown
        model only); ``None``: never.
    kalman : {"compiled", "filterpy"}
        Predict and update of the general epochs (GNSS and the other non high-rate
        measurements): the compiled :func:`.kalman.predict` / :func:`.kalman.update`, or
        filterpy's ``predict`` / ``update`` (the reference; same results to rounding, slower).
    store_allocate : callable or None
        ``allocate(shape, dtype)`` for the large arrays of the smoother's node store
        (:class:`.store.NodeStore`); None: in memory. A job passes
        :class:`insgnss.io.spill.SpillAllocator` (``[filter] store_memory_mb``).
    """

    imu_model: ImuErrorModel | str = "tactical"
    bias_model: str = "random_walk"
    scale_factors: bool = False
    propagation_interval: float = 0.1
    epoch_interval: float = 1.0
    epoch_grid: str = "gaps"
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
    initial_parameters: dict | None = None
    gravity_model: str = "somigliana"
    attitude_update: str = "exact"
    coning: bool = False
    snap_tolerance: float = 1e-6
    check_health: bool = True
    nis_window: float | None = 30.0
    nis_bound: float = 25.0
    nis_min_count: int = 10
    extra_noise: pd.DataFrame | None = None
    error_dynamics: str = "full"
    accel_dynamic_noise: float = 0.0
    gyro_dynamic_noise: float = 0.0
    smoother_covariance: bool = True
    heading_reinit: HeadingReinit | None = None
    kalman: str = "compiled"
    store_allocate: Callable | None = None

    def validate(self) -> None:
        if self.bias_model not in BIAS_MODELS:
            raise ConfigError(f"unknown bias_model {self.bias_model!r}", column="bias_model",
                              expected=list(BIAS_MODELS), found=self.bias_model)
        if self.discretization not in DISCRETIZATIONS:
            raise ConfigError("unknown discretization", column="discretization",
                              expected=list(DISCRETIZATIONS), found=self.discretization)
        if self.epoch_grid not in EPOCH_GRIDS:
            raise ConfigError("unknown epoch_grid", column="epoch_grid",
                              expected=list(EPOCH_GRIDS), found=self.epoch_grid)
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
        if self.kalman not in KALMAN_BACKENDS:
            raise ConfigError("unknown Kalman backend", column="kalman",
                              expected=list(KALMAN_BACKENDS), found=self.kalman)
        if self.error_dynamics not in ERROR_DYNAMICS:
            raise ConfigError("unknown error_dynamics", column="error_dynamics",
                              expected=list(ERROR_DYNAMICS), found=self.error_dynamics)
        for key in ("accel_dynamic_noise", "gyro_dynamic_noise"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError("must be a finite non-negative number", column=key, found=v)
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
        The same columns from the smoother (:mod:`.smoother`).
    forward_array, smoothed_array : (N, C) arrays
        Their values; the DataFrames (and the innovation tables) are built when first read,
        so array callers do not pay for them (``forward_table``, ``smoothed_table``: the
        :class:`.store.Table` or DataFrame the process model returned).
    innovations : DataFrame
        One row per measurement evaluated: ``time type label dof nis threshold accepted
        recovered`` and ``innov_k``, ``innov_std_k`` for each component (``label``: the row's
        ``Measurement.row_label``, e.g. the satellite of a pseudorange; empty otherwise).
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
        Times of the smoother nodes (:mod:`.store`): the filter epochs.
    P_filtered, P_predicted : (E, n, n) arrays
        ``P(e|e)`` and ``P(e|e-1)`` at the nodes.
    Phi : (E, n, n) array or None
        Error transition from node ``e-1`` (or the last high-rate sample before ``e``) to
        ``e``; kept only when the smoother runs (``config.smoother``), its only reader.
    feedback : (E, n) array
        Error estimate removed from the nominal at each node.
    P_smoothed : (E, n, n) array or None
    heading_reinits : list of dict
        The heading re-initialisations (:mod:`.heading_reinit`): ``time``, ``course_time``,
        ``old_heading_deg``, ``new_heading_deg``, ``heading_std_deg``, ``speed``, ``reason``.
    final : NavState
        Nominal state at the last processed epoch.
    params : (E, p) array
        Nominal parameter values at each node (process-model specific).
    updates : dict
        The applied updates: rows ``r0[e] .. r1[e]-1`` of ``H``, ``K`` (transposed), ``G =
        S^-1 H``, ``s = S^-1 z`` belong to node ``e`` (:class:`insgnss.filter.store.NodeStore`);
        the smoother's record, kept only when it runs (``config.smoother``; the compiled
        high-rate path keeps its rows always). ``H`` is compact, by its non-zeros: row ``r``
        has the columns ``H_col[H_ptr[r]:H_ptr[r+1]]`` and values ``H_val[...]``
        (:func:`insgnss.filter.store.dense_rows` gives dense rows); ``G`` is written only where
        it is kept (the Python path; the compiled path with ``smoother_covariance``).
    log : dict
        The innovation log as arrays (``time tid lid dof nis threshold accepted recovered innov
        innov_std``, ``names``: the measurement type of each ``tid``, and ``labels``: the row
        label of each ``lid``).
    high_rate : dict or None
        The samples of the compiled high-rate path (times, IMU rows, ``F dt`` and ``Qd`` at the
        process model's ``pattern``, feedback, update rows ``r0 .. r1-1``, and ``Pp[Pp_index]``
        where a gate recovery inflated ``P(i|i-1)``; ``seg0[e] .. seg1[e]-1`` lie before node
        ``e``), None without high-rate measurements.
    """

    forward_table: Table | pd.DataFrame = field(repr=False)
    smoothed_table: Table | pd.DataFrame | None = field(repr=False)
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
    Phi: np.ndarray | None = field(default=None, repr=False)
    updates: dict | None = field(default=None, repr=False)
    high_rate: dict | None = field(default=None, repr=False)
    log: dict | None = field(default=None, repr=False)
    heading_reinits: list = field(default_factory=list)

    # the tables are built on first access: array callers read forward_array / log
    @property
    def forward(self) -> pd.DataFrame:
        return _frame(self.forward_table)

    @forward.setter
    def forward(self, table) -> None:
        self.forward_table = table

    @property
    def smoothed(self) -> pd.DataFrame | None:
        return _frame(self.smoothed_table)

    @smoothed.setter
    def smoothed(self, table) -> None:
        self.smoothed_table = table

    @property
    def forward_array(self) -> np.ndarray:
        """The values of :attr:`forward` (no DataFrame built)."""
        return _values(self.forward_table)

    @property
    def smoothed_array(self) -> np.ndarray | None:
        """The values of :attr:`smoothed` (no DataFrame built)."""
        return _values(self.smoothed_table)

    @property
    def innovations(self) -> pd.DataFrame:
        return self._innovation_tables()[0]

    @property
    def rejected(self) -> pd.DataFrame:
        return self._innovation_tables()[1]

    def _innovation_tables(self):
        if "_innov" not in self.__dict__:
            self.__dict__["_innov"] = innovation_tables(None, self.log)
        return self.__dict__["_innov"]


def _frame(table):
    return table.frame() if isinstance(table, Table) else table


def _values(table):
    if table is None:
        return None
    return table.values if isinstance(table, Table) else table.to_numpy()


class _Run:
    """State of one engine run shared by the loop's steps."""

    def __init__(self, model: ProcessModelBase, measurements: list, config: FilterConfig):
        self.model = model
        self.config = config
        self.general = [m for m in measurements if not getattr(m, "high_rate", False)]
        self.fast = [m for m in measurements if getattr(m, "high_rate", False)]
        names = []
        for m in self.general + self.fast:
            if m.name not in names:
                names.append(m.name)
        self.tid = {name: i for i, name in enumerate(names)}
        self.gates = GateTable(config.gate_probability, config.gate_probabilities)
        # per general model, looked up once instead of at every measurement: (type id,
        # gating probability, recoverable, labelled rows)
        self.ginfo = [(self.tid[m.name], self.gates.probability(m),
                       bool(getattr(m, "recoverable", False)), hasattr(m, "row_label"))
                      for m in self.general]
        # gate recovery time per type; -1 (never) for types that may not be forced in
        # (Measurement.recoverable: constraints such as NHC, a vehicle's ZUPT, odometer)
        rec = -1.0 if config.gate_recovery is None else float(config.gate_recovery)
        absolute = np.zeros(max(len(names), 1), bool)
        for m in self.general + self.fast:
            absolute[self.tid[m.name]] |= bool(getattr(m, "recoverable", False))
        self.recovery = np.where(absolute, rec, -1.0)
        self.streak = np.zeros((max(len(names), 1), 3))
        self.streak_rows: dict = {}  # (type, row label) -> row of streak (labelled rows)
        self.last_accept = np.full(max(len(names), 1), -np.inf)  # per type
        self.log = InnovationLog(names)
        self.check = bool(config.check_health)
        # Kalman predict/update of the general epochs: compiled (kalman.py) or filterpy's
        self.kf_predict, self.kf_update = kalman_backend(config.kalman)
        # the compiled ones return P symmetrized; filterpy's P is symmetrized here
        self.symmetrize = config.kalman != "compiled"
        self.timing = {"updates": 0.0}
        t = model.t
        tol = min(config.snap_tolerance, 1e-3 * float(np.median(np.diff(t))))
        self.sched = build_schedule(t, [m.times for m in self.general], config.epoch_interval,
                                    tol, model.split, [m.times for m in self.fast],
                                    grid_in_gaps=config.epoch_grid == "gaps")
        # the constraints are watched only in runs without absolute measurements (health.py)
        self.runaway = RunawayNis(len(names), config.nis_window if self.check else None,
                                  config.nis_bound, config.nis_min_count,
                                  _window_capacity(self, config.nis_window),
                                  watched=absolute if absolute.any() else None)
        n = model.layout.n
        self.hr = highrate.HighRate(self.fast, model, self) if self.fast else None
        pat = self.hr.pattern if self.hr is not None else None
        self.store = NodeStore(self.sched.n_epochs, n, model.n_par, self.sched.dense_samples,
                               0 if pat is None else pat[1].size,
                               0 if pat is None else pat[3].size,
                               allocate=config.store_allocate,
                               transitions=config.smoother)
        if config.extra_noise is not None and len(config.extra_noise):
            xn = config.extra_noise.reindex(columns=list(EXTRA_NOISE_COLS)).fillna(0.0)
            self.xn_t = np.asarray(xn.index, float)
            self.xn_var = xn.to_numpy(float) ** 2
        else:
            self.xn_t, self.xn_var = np.empty(0), np.empty((0, len(EXTRA_NOISE_COLS)))
        self.xn_i = int(np.searchsorted(self.xn_t, self.sched.epochs[0], side="right"))
        self.I = np.eye(n)
        self.heading = None  # the heading re-initialisation monitor (.heading_reinit)
        self.abs_nis = np.nan  # largest NIS/dof of the absolute measurements at this epoch
        self.reinits: list = []
        if config.heading_reinit is not None:
            if not getattr(model, "heading_reset", False):
                raise ConfigError("the heading re-initialisation needs the LLF strapdown "
                                  "process model", column="heading_reinit",
                                  found=type(model).__name__)
            self.heading = HeadingMonitor(config.heading_reinit)


def _window_capacity(run: _Run, window) -> int:
    """Most measurements of one type inside any runaway-NIS window (buffer size)."""
    if window is None:
        return 2
    cap = 2
    per: dict = {}
    for m in run.general + run.fast:
        per.setdefault(run.tid[m.name], []).append(np.asarray(m.times, float))
    for arrs in per.values():
        tm = np.sort(np.concatenate(arrs))
        if tm.size:
            cap = max(cap, int(np.max(np.searchsorted(tm, tm + window, side="right")
                                      - np.arange(tm.size))) + 1)
    return cap


def _propagate(run: _Run, e: int, node: int, x, P):
    """Step 1: advance the nominal and the covariance from the previous node to epoch ``e``
    (through the compiled high-rate path first if the segment holds high-rate events)."""
    model, te = run.model, run.sched.epochs[e]
    if run.hr is not None and run.sched.dense[e]:
        P = run.hr.segment(te, P)
    Phi, Qd = model.propagate(te, node)
    if run.xn_i < run.xn_t.size and run.xn_t[run.xn_i] <= te:
        Qd = Qd.copy()
        while run.xn_i < run.xn_t.size and run.xn_t[run.xn_i] <= te:
            for blk, sl in enumerate(model.noise_blocks):  # position, velocity, attitude
                i3 = np.arange(sl.start, sl.stop)
                Qd[i3, i3] += run.xn_var[run.xn_i, blk]
            up = model.noise_blocks[0].start + 2  # ENU position: the up component
            Qd[up, up] += run.xn_var[run.xn_i, 3]
            run.xn_i += 1
    c0 = _time.perf_counter()
    x, P = run.kf_predict(x, P, Phi, Qd)
    if run.symmetrize:
        P = 0.5 * (P + P.T)
    if run.check:
        if not model.nominal_finite():
            raise health.nominal_error(te)
        # full check (Cholesky) here only if no update follows at this epoch
        ptr = run.sched.ptr
        check_covariance(x, P, te, "prediction", full=ptr[e + 1] == ptr[e])
    model.timing["covariance"] += _time.perf_counter() - c0
    return x, P, Phi


def _as_arrays(z, H, R):
    if not (isinstance(z, np.ndarray) and z.ndim == 1):
        z = np.atleast_1d(np.asarray(z, dtype=float))
    if not (isinstance(R, np.ndarray) and R.ndim == 2):
        R = np.atleast_2d(np.asarray(R, dtype=float))
    if not (isinstance(H, np.ndarray) and H.ndim == 2):
        H = np.atleast_2d(np.asarray(H, dtype=float))
    return z, H, R


def _streak_row(run: _Run, tid: int, label: str) -> int:
    """Row of the gate-streak array of measurement type ``tid`` and row label ``label`` (the
    type's own row without a label; a new row the first time a label appears)."""
    if not label:
        return tid
    key = (tid, label)
    row = run.streak_rows.get(key)
    if row is None:
        row = run.streak_rows[key] = run.streak.shape[0]
        run.streak = np.vstack([run.streak, np.zeros((1, 3))])
    return row


def _gate(run: _Run, m, info, time: float, z, H, R, P, label: str = ""):
    """Gate one measurement against the predicted ``P``: ``(accepted, P, S, nis)``; a gate
    recovery returns the inflated ``P``. A labelled row (one satellite of a pseudorange model)
    keeps its own rejection streak, and recovers only when no measurement of its type was
    accepted for longer than the recovery time (:mod:`.gating`, "Labelled rows"). ``info``:
    the model's entry of ``run.ginfo``."""
    tid, prob, recoverable = info[0], info[1], info[2]
    S, nis = gating.innovation_nis(as_f64(H), as_f64(P), as_f64(R), as_f64(z))
    nn = nis / z.size
    run.runaway.push(tid, m.name, time, nn)
    if recoverable and not nn <= run.abs_nis:
        run.abs_nis = nn  # for the heading monitor (NaN start: the first one)
    thr = run.gates.threshold(prob, z.size)
    row = _streak_row(run, tid, label)  # may grow run.streak: before passing the array
    rec = run.recovery[tid]  # -1 for a type that may not be forced in
    code = gating.gate_step(run.streak, row, time, nis, thr, rec)
    if code == gating.RECOVER and label and \
            not gating.type_lost(run.last_accept[tid], time, rec):
        code = gating.REJECT  # the other rows of the type are accepted: this row is bad
    if code == gating.RECOVER:
        run.runaway.restart()  # the NIS before the recovery no longer counts (health.py)
        P = P.copy()
        S = gating.inflate_for(P, H, R, z, thr, run.model.n_nav)
        nis = gating.nis(S, z)
    if code != gating.REJECT:
        run.last_accept[tid] = time
    run.log.add(time, tid, nis, thr, code != gating.REJECT, code == gating.RECOVER, z, S, label)
    return code != gating.REJECT, code == gating.RECOVER, P


def _update(run: _Run, e: int, x, P):
    """Step 2: evaluate, gate and apply the measurements of epoch ``e`` (one stacked
    compiled update). Returns ``(x, P, P_predicted_seen, applied)``."""
    sched, model = run.sched, run.model
    zs, Hs, Rs = [], [], []
    Pp = P
    general, ginfo = run.general, run.ginfo
    ev_m, ev_t, ev_r = sched.ev_m, sched.ev_t, sched.ev_r
    for k in range(sched.ptr[e], sched.ptr[e + 1]):
        im = ev_m[k]
        m, info = general[im], ginfo[im]
        time = ev_t[k]
        row = int(ev_r[k])
        res = m.evaluate(row, model.nominal(time))
        if res is None:
            continue
        res = model.observe(m, *_as_arrays(*res))
        if res is None:
            continue
        z, H, R = res
        label = m.row_label(row) if info[3] else ""
        ok, recovered, P = _gate(run, m, info, time, z, H, R, P, label)
        if recovered:
            Pp = P  # the gate recovery inflated P(e|e-1): the smoother needs it
        if ok:
            zs.append(z)
            Hs.append(H)
            Rs.append(R)
    if not zs:
        return x, P, Pp, False
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
    x, P = run.kf_update(x, P, z, R, H)
    if run.symmetrize:
        P = 0.5 * (P + P.T)
    if run.check:
        check_covariance(x, P, sched.epochs[e], "update")
    if run.config.smoother:
        # the smoother's record of the update: H, K = Pp H^T S^-1, S^-1 H, S^-1 z (a
        # forward-only run, e.g. of the self-tuning, skips it: a solve per epoch)
        K, G, s = smoother_record(Pp, H, R, z, sched.epochs[e])
        run.store.add_update(H, K, G, s)
    return x, P, Pp, True


def _heading_reinit(run: _Run, te: float, P):
    """Before the update of epoch ``te`` (the error state is zero): re-initialise the heading
    and the horizontal velocity from the GNSS course when the monitor asks for it
    (:mod:`.heading_reinit`); returns ``(P(e|e-1), reset?)``. The update then runs from the
    reset nominal and covariance (its ``P(e|e-1)``, like a gate recovery's)."""
    model = run.model
    if not run.heading.due(te):  # most epochs: not the nominal's attitude to compute
        return P, False
    ev = run.heading.check(te, model.nominal(te).C)
    if ev is None:
        return P, False
    c = run.config.heading_reinit.course
    lay = model.layout
    att, vel = lay["att"], lay["vel"]
    d = np.zeros(lay.n)
    d[att.start + 2] = ev.d  # C <- exp(-[phi x]) C with phi = (0, 0, d): heading + d
    nav = model.nominal(te)
    d[vel.start] = nav.vel[0] - c.vel_e[ev.k]
    d[vel.start + 1] = nav.vel[1] - c.vel_n[ev.k]
    model.feedback(d)
    P = reset_covariance(P, att.start + 2, (vel.start, vel.start + 1),
                         float(c.course_std[ev.k]) ** 2, float(c.vel_std[ev.k]) ** 2)
    run.runaway.restart()  # the NIS before the reset describes the abandoned state
    run.reinits.append(ev.record)
    return P, True


def run_engine(model: ProcessModelBase, measurements: list[Measurement], config: FilterConfig,
               progress: bool = False) -> FilterResult:
    """Run the engine (module docstring) with a prepared process model.

    Parameters
    ----------
    model : ProcessModelBase
        Process model at the initial state (e.g. :class:`.strapdown_model.StrapdownModel`).
    measurements : list of Measurement
        Measurement models; those with ``high_rate=True`` run on the compiled path.
    config : FilterConfig
        Gating, recovery, health, epoch and smoother settings (the process settings were used
        to build ``model``).
    progress : bool
        Show a progress bar (tqdm) over the epochs.
    """
    t_start = _time.perf_counter()
    run = _Run(model, list(measurements), config)
    sched, store = run.sched, run.store
    model.prepare(sched.epochs, sched.dense)
    n = model.layout.n
    x = np.zeros(n)
    P = model.initial_covariance()
    perf = _time.perf_counter
    node, completed, error = 0, -1, None
    iterator = range(sched.n_epochs)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, total=sched.n_epochs, unit="epoch", desc="filter")
    try:
        for e in iterator:
            te = sched.epochs[e]
            Phi = run.I
            if e > 0:
                x, P, Phi = _propagate(run, e, node, x, P)
            c0 = perf()
            fb = None
            store.open(node)
            run.abs_nis = np.nan
            if run.heading is not None:
                P, cut = _heading_reinit(run, te, P)
                if cut:  # a smoother boundary: nothing flows back across the reset
                    Phi = np.zeros_like(Phi)
            x, P, Pp, applied = _update(run, e, x, P) if sched.ptr[e + 1] > sched.ptr[e] \
                else (x, P, P, False)
            if run.heading is not None:
                run.heading.note(run.abs_nis)
            if applied:  # an update was applied: feed back and reset
                fb = x
                model.feedback(x)
                x = np.zeros(n)
            store.close(node, te, Phi, Pp, P, fb, model.params())
            model.close_epoch(node, te)
            model.release_rows()
            run.timing["updates"] += perf() - c0
            completed, node = e, node + 1
    except FilterHealthError as exc:
        error = exc
    return _finish(run, completed, error, t_start)


def _finish(run: _Run, completed: int, error, t_start: float) -> FilterResult:
    """Smoother and output tables over the completed nodes (and high-rate samples)."""
    model, store, config = run.model, run.store, run.config
    perf = _time.perf_counter
    n_ok = store.count
    t_last = store.t[n_ok - 1] if n_ok else model.t[0]
    n_hr = store.hr_count
    if n_ok and n_hr > store.seg1[n_ok - 1]:  # a run stopped inside a high-rate segment
        t_last = store.hr_t[n_hr - 1]
    n_rows = model.rows_done(t_last) if n_ok else 0
    timing = {"mechanization": model.timing["mechanization"],
              "covariance": model.timing["covariance"], "updates": run.timing["updates"]}
    if "high_rate" in run.timing:
        timing["high_rate"] = run.timing["high_rate"]
    c0 = perf()
    forward = model.output(store, n_ok, n_rows)
    timing["output"] = perf() - c0
    smoothed, Ps = None, None
    timing["smoother"] = 0.0
    if config.smoother and n_ok >= 2:
        c0 = perf()
        xs = smooth(store, n_ok, config.smoother_covariance,
                    run.hr.pattern if run.hr is not None else None)
        Ps = xs[2]
        smoothed = model.output(store, n_ok, n_rows, xs)
        timing["smoother"] = perf() - c0
    log = run.log.columns()
    log["names"] = list(run.log.names)
    log["labels"] = list(run.log.labels)
    timing["total"] = perf() - t_start
    nz = int(store.H_ptr[store.n_rows])
    updates = {"r0": store.r0[:n_ok], "r1": store.r1[:n_ok],
               "H_ptr": store.H_ptr[:store.n_rows + 1], "H_col": store.H_col[:nz],
               "H_val": store.H_val[:nz], "K": store.K[:store.n_rows],
               "G": store.G[:store.n_rows], "s": store.s[:store.n_rows]}
    high_rate = None
    if n_hr:
        high_rate = {"t": store.hr_t[:n_hr], "row": store.hr_row[:n_hr],
                     "seg0": store.seg0[:n_ok], "seg1": store.seg1[:n_ok],
                     "F": store.hr_F[:n_hr], "Q": store.hr_Q[:n_hr],
                     "feedback": store.hr_fb[:n_hr], "r0": store.hr_r0[:n_hr],
                     "r1": store.hr_r1[:n_hr], "pattern": run.hr.pattern,
                     "Pp_index": store.hr_ppi[:n_hr], "Pp": store.hr_Pp}
    return FilterResult(
        forward_table=forward, smoothed_table=smoothed, complete=error is None,
        timing=timing, layout=model.layout,
        epoch_times=store.t[:n_ok].copy(), P_filtered=store.Pf[:n_ok],
        P_predicted=store.Pp[:n_ok], feedback=store.fb[:n_ok], P_smoothed=Ps, error=error,
        final=model.final_state(float(t_last)), params=store.par[:n_ok],
        Phi=None if store.Phi is None else store.Phi[:n_ok],
        updates=updates, high_rate=high_rate, log=log, heading_reinits=list(run.reinits))


def run_filter(
    imu: pd.DataFrame,
    initial: NavState,
    measurements: list[Measurement],
    config: FilterConfig | None = None,
    progress: bool = False,
) -> FilterResult:
    """Run the closed-loop error-state filter (and the smoother) over an IMU table with the
    LLF strapdown process model.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments, :mod:`insgnss.imu`) indexed by time [s]; its first
        row is the epoch of ``initial``.
    initial : NavState
        Initial nominal state (e.g. from alignment) at the first IMU time.
    measurements : list of Measurement
        Aiding measurement models (:mod:`insgnss.filter.measurements`); those built with
        ``high_rate=True`` (ZUPT, ZARU, body velocity) run on the compiled high-rate path.
    config : FilterConfig
    progress : bool
        Show a progress bar (tqdm) over the filter epochs.

    Returns
    -------
    FilterResult
    """
    config = FilterConfig() if config is None else config
    config.validate()
    measurements = list(measurements)
    extras = []
    for m in measurements:
        extras.extend(m.extra_states())
    model = StrapdownModel(imu, initial, extras, config)
    return run_engine(model, measurements, config, progress)
