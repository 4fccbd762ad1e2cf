"""Foot-mounted pedestrian INS: stance detection, ZUPT + ZARU at every still IMU sample, smoother.

The foot-mounted INS is the filter engine (:mod:`insgnss.filter.engine`) with the LLF strapdown
process model (:class:`insgnss.filter.strapdown_model.StrapdownModel`) and high-rate ZUPT and
ZARU measurements (:class:`~insgnss.filter.measurements.Zupt`,
:class:`~insgnss.filter.measurements.Zaru` with ``high_rate=True``), applied on the engine's
compiled path (:mod:`insgnss.filter.highrate`) at every still sample the stance detector
(:mod:`insgnss.detect`) declares. This module holds the foot profile: the detector, the noise
defaults and the initial alignment.

Model
-----
The nominal trajectory is the strapdown mechanization of the bias-compensated increments. The
15-state error (``nominal - true``)::

    x = [dp (ENU, m), dv (ENU, m/s), phi (l-frame misalignment, rad), dbg (rad/s), dba (m/s^2)]

follows the short-term (pedestrian) strapdown error dynamics of :mod:`insgnss.filter.models`
(Groves 2013 eq. 14.63 without the Earth-rate, transport-rate and gravity-gradient couplings:
over a walk of minutes they are below 1e-4 of the retained terms), propagated per IMU
interval (``Phi = I + F dt``) with random-walk biases and, on a foot, a dynamics-dependent white
noise: the velocity and attitude variances of an interval grow by ``(accel_dyn_noise |C dv -
g dt|)^2`` and ``(gyro_dyn_noise |dtheta|)^2``, a white error of a fraction of each increment
(unmodelled scale-factor, g-sensitivity and vibration errors, which dominate on a foot).

Measurements (:mod:`insgnss.filter.measurements`)::

    ZUPT  z = v_nom                           H = [0  I  0  0  0]          R = sigma_zupt,k^2 I
    ZARU  z = w_ib,nom - C^T w_ie^l           H = [0  0  -C^T[w_ie x]  -I  0]   R = sigma_zaru^2 I

on the still samples (every ``update_every``-th of a still run; ZARU only where the rate is
below ``zaru_max_rate``); ``sigma_zupt,k`` grows with the detector statistic (soft ZUPT).
Closed loop: after each update the estimate is fed back into the nominal and reset to zero.

Stance threshold: chosen per recording (``threshold_selection = "innovation"``, the default)
among fixed and valley-relative SHOE thresholds by the RMS ZUPT innovation at stance entry of a
forward pass with each (:func:`insgnss.detect.select_threshold`, docs/zupt.md section 1).

Height aiding (optional, docs/zupt.md section 7): a level floor between consecutive stances
(:class:`~insgnss.filter.height_aiding.LevelFloor`, ``level_floor``) and barometric height when
the IMU table carries a ``pressure`` or ``baro_height`` column
(:class:`~insgnss.filter.height_aiding.BaroHeight`). ZUPT keeps the modelled height variance at
mm level while the real foot INS climbs 0.4-1.3 % of the distance walked, so at each stance
release the vertical position variance grows by ``(stride_height_noise L)^2``, ``L`` the
horizontal length of the stride that ended there: without it an aiding measurement barely moves
the height (level floor) or is absorbed by its own offset state (barometer).

Smoother: the engine's modified Bryson-Frazier backward pass (:mod:`insgnss.filter.smoother`)
over the nodes of the compiled path (one per IMU sample) gives the smoothed trajectory at every
sample.

Initial conditions: roll and pitch from accelerometer levelling over the first still window
(``f^b = C^T [0, 0, g]``, so ``roll = atan2(-f_x, f_z)``, ``pitch = atan2(f_y, hypot(f_x,
f_z))``), gyro bias from the mean rate over that window, and heading given by the caller or 0:
with only ZUPT and ZARU the heading is unobservable (no measurement depends on it), so the
filter keeps the initial heading up to gyro drift, and a foot-mounted trajectory is determined
up to a rotation about the vertical through its start.

References: Foxlin 2005 (IEEE CG&A 25(6), "Pedestrian tracking with shoe-mounted inertial
sensors"); Skog et al. 2010 (IEEE TBME 57(11)); Nilsson et al. 2012 ("Foot-mounted INS for
everybody - an open-source embedded implementation", OpenShoe); Wagstaff et al. 2019 (PyShoe).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np
import pandas as pd

from . import earth
from .align import level
from .attitude import euler_to_dcm
from .detect import (
    SELECTION_FIXED,
    SELECTION_RELATIVE,
    SHOE_METHODS,
    DetectorConfig,
    Stillness,
    ThresholdSelection,
    detect_arrays,
    imu_rates,
    select_threshold,
    statistic_arrays,
)
from .errors import AlignmentError, ConfigError, FilterHealthError
from .filter.engine import BIAS_COLS, FilterConfig, run_engine
from .filter.height_aiding import BARO_COLUMNS, BaroHeight, LevelFloor
from .filter.measurements import Measurement, Zaru, Zupt
from .filter.strapdown_model import STD_COLS, StrapdownModel
from .imu import ImuErrorModel, increments
from .mechanization.strapdown import NAV_COLS, NavState
from .stats import chi2_cdf
from .strides import stance_positions, still_runs

__all__ = ["FootConfig", "FootResult", "foot_detector", "foot_filter_arrays",
           "foot_filter_config", "initial_state", "level", "level_window_mask", "run_foot_ins"]


# --- configuration ---------------------------------------------------------------------------
#: pyshoe's SHOE noise levels (Wagstaff et al. 2019): sigma_a [m/s^2], sigma_w [rad/s]
PYSHOE_SIGMA_A = 0.00098
PYSHOE_SIGMA_W = 8.7266e-5


def foot_detector() -> DetectorConfig:
    """The foot profile's stance detector: SHOE with pyshoe's sigmas over 0.04 s, a threshold
    relative to the stance-valley level (``valley``: 5 % quantile over two gait periods,
    standing below 1e6 = about 5 deg/s for 0.5 s left out; :mod:`insgnss.detect`). With
    ``FootConfig.threshold_selection = "innovation"`` (the default) the threshold is chosen per
    recording; ``adapt_factor`` is the valley factor used without the selection."""
    return DetectorConfig(method="valley", window=0.04, threshold=1.0e6,
                          sigma_a=PYSHOE_SIGMA_A, sigma_w=PYSHOE_SIGMA_W, adapt_window=3.0,
                          adapt_factor=10.0, quiet_duration=0.5, valley_quantile=0.05,
                          valley_strides=2.0)


#: ``FootConfig.threshold_selection`` values
THRESHOLD_SELECTIONS = ("innovation", "none")


@dataclass
class FootConfig:
    """Foot-mounted INS settings (SI units).

    Attributes
    ----------
    detector : DetectorConfig
        Stance detector (see :mod:`insgnss.detect`).
    threshold_selection : {"innovation", "none"}
        ``innovation``: the SHOE threshold of the recording is chosen among the candidates
        ``selection_fixed`` and ``selection_relative`` by the RMS ZUPT innovation at stance
        entry of a forward pass with each (:func:`insgnss.detect.select_threshold`; needs a
        SHOE-based detector method); ``none``: the detector decides alone.
    selection_fixed, selection_relative : (float, float, float)
        log10 grids (start, stop, step) of the fixed thresholds and of the valley factors.
    zaru : bool
        Apply ZARU together with ZUPT on still samples.
    zaru_max_rate : float
        ZARU only on still samples whose angular rate is below this [rad/s] (the quiet core of
        a stance; the foot rolls at its edges).
    sigma_zupt, sigma_zaru : float
        Measurement standard deviations [m/s], [rad/s].
    zupt_noise_exponent, zupt_noise_ref : float
        Soft ZUPT: the ZUPT standard deviation of sample k is
        ``sigma_zupt * max(1, T_k / zupt_noise_ref) ** zupt_noise_exponent`` with ``T_k`` the
        detector statistic, so samples at the edge of a stance (where the foot still rolls)
        weigh less than its quiet core (0: constant ``sigma_zupt``).
    update_every : int
        Apply the updates on every n-th still sample (1 = every sample).
    gate_zupt, gate_zaru : float
        Chi-square gates on the normalised innovation squared (3 degrees of freedom); an update
        above it is skipped (``inf``: no gating). 16.27 is the 99.9 % point. The engine gates by
        probability: these become ``chi2.cdf(gate, 3)``; its gate recovery applies.
    accel_psd, gyro_psd : float
        Velocity / angle random walk of the process model [m/s/sqrt(s)], [rad/sqrt(s)]. The
        velocity one is the sensor's white noise (VN-100: 0.14 mg/sqrt(Hz)); the foot's
        unmodelled accelerometer errors are in ``accel_dyn_noise``. The angle one is an
        effective value about 50 times the datasheet ARW: it carries the rotation-dependent
        gyro errors of the swing (docs/zupt.md section 2).
    accel_dyn_noise, gyro_dyn_noise : float
        Dynamics-dependent process noise [fraction]: a white error of this fraction of each IMU
        interval's dynamic velocity increment ``|C dv - g dt|`` and angle increment
        ``|dtheta|`` (unmodelled scale-factor, g-sensitivity and vibration errors, which dominate
        on a foot; ``FilterConfig.accel_dynamic_noise``).
    gyro_bias_rw, accel_bias_rw : float
        Bias random walks [rad/s/sqrt(s)], [m/s^2/sqrt(s)].
    init_att_std, init_heading_std, init_vel_std, init_pos_std : float
        Initial standard deviations [rad], [rad], [m/s], [m].
    init_gyro_bias_std, init_accel_bias_std : float
        Initial bias standard deviations [rad/s], [m/s^2].
    level_window : float
        Length [s] of the start window used for levelling (the first still run is used if
        the detector finds one starting within it, else the first ``level_window`` seconds).
    heading : float
        Initial heading [rad] (unobservable; 0 unless known).
    smooth : bool
        Run the backward (smoother) pass and report the smoothed trajectory.
    gravity_model : str
        Normal-gravity model of the nominal mechanization.
    level_floor : bool
        Consecutive stances at the same height (:class:`~.filter.height_aiding.LevelFloor`)
        for walks known to stay on one floor (off by default: a stair step, a change above
        ``level_floor_max_step`` and steeper than ``level_floor_max_slope``, is skipped).
    level_floor_std, level_floor_max_step, level_floor_max_slope : float
        Floor flatness plus stance repeatability [m]; the height change between two stances
        below which the constraint always applies [m]; the change per metre of horizontal
        stance-to-stance distance below which it also applies (stairs rise 0.36-0.8 per
        metre, the foot INS's own error on a running stride reaches 0.15).
    baro : bool
        Use a ``pressure`` [Pa] or ``baro_height`` [m] column of the IMU table when present
        (:class:`~.filter.height_aiding.BaroHeight`).
    baro_std, baro_interval, baro_offset_psd : float
        Barometer height noise [m], one reading per this many seconds, random-walk PSD of its
        offset [m^2/s].
    stride_height_noise : float
        At each stance release the vertical position variance grows by
        ``(stride_height_noise * L)^2``, ``L`` the horizontal length of the stride that ended
        there [fraction]: the real foot INS climbs 0.4-1.3 % of the distance walked, which the
        ZUPT-only covariance does not show (docs/zupt.md section 7). Applied when a height
        aiding is used.
    """

    detector: DetectorConfig = field(default_factory=foot_detector)
    threshold_selection: str = "innovation"
    selection_fixed: tuple = SELECTION_FIXED
    selection_relative: tuple = SELECTION_RELATIVE
    zaru: bool = True
    zaru_max_rate: float = 0.05
    sigma_zupt: float = 0.01
    sigma_zaru: float = 0.01
    update_every: int = 1
    zupt_noise_exponent: float = 0.25
    zupt_noise_ref: float = 1.0e5
    gate_zupt: float = np.inf
    gate_zaru: float = np.inf
    accel_psd: float = 1.4e-3
    gyro_psd: float = 3e-3
    accel_dyn_noise: float = 0.02
    gyro_dyn_noise: float = 0.0
    gyro_bias_rw: float = 1e-5
    accel_bias_rw: float = 1e-4
    init_att_std: float = np.radians(1.0)
    init_heading_std: float = np.radians(0.1)
    init_vel_std: float = 0.01
    init_pos_std: float = 1e-3
    init_gyro_bias_std: float = np.radians(0.1)
    init_accel_bias_std: float = 0.05
    level_window: float = 0.5
    heading: float = 0.0
    smooth: bool = True
    gravity_model: str = "somigliana"
    level_floor: bool = False
    level_floor_std: float = 0.002
    level_floor_max_step: float = 0.05
    level_floor_max_slope: float = 0.2
    baro: bool = True
    baro_std: float = 0.2
    baro_interval: float = 0.5
    baro_offset_psd: float = 1.0e-5
    stride_height_noise: float = 0.01

    def __post_init__(self):
        if isinstance(self.detector, dict):
            self.detector = DetectorConfig.from_dict(self.detector)
        if self.threshold_selection not in THRESHOLD_SELECTIONS:
            raise ConfigError("unknown stance-threshold selection", column="threshold_selection",
                              expected=list(THRESHOLD_SELECTIONS), found=self.threshold_selection)
        if self.threshold_selection != "none" and self.detector.method not in SHOE_METHODS:
            raise ConfigError("the stance-threshold selection chooses SHOE thresholds: use a "
                              "SHOE-based detector, or threshold_selection = \"none\" to use "
                              f"the {self.detector.method} detector with its own threshold",
                              column="detector.method", expected=list(SHOE_METHODS),
                              found=self.detector.method)
        for name in ("selection_fixed", "selection_relative"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 3 or not all(np.isfinite(v)) or v[2] <= 0 or v[1] < v[0]:
                raise ConfigError("a candidate grid is [log10 start, stop, step] with stop >= "
                                  "start and step > 0", column=name, found=getattr(self, name))
            setattr(self, name, v)
        for name in ("zaru", "smooth", "level_floor", "baro"):  # TOML "yes" is not true
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ConfigError("must be true or false", column=name, expected="boolean",
                                  found=repr(getattr(self, name)))
        for name, low in (("level_floor_std", 0.0), ("level_floor_max_step", 0.0),
                          ("level_floor_max_slope", None),
                          ("baro_std", 0.0), ("baro_interval", None),
                          ("baro_offset_psd", None), ("stride_height_noise", None)):
            v = getattr(self, name)
            ok = isinstance(v, (int, float, np.number)) and not isinstance(v, bool) \
                and np.isfinite(v) and (v > 0 if low is not None else v >= 0)
            if not ok:
                raise ConfigError("must be a finite number " + ("> 0" if low is not None
                                                                  else ">= 0"),
                                  column=name, found=repr(v))
        if self.level_floor_std >= self.level_floor_max_step:
            # a floor sigma as large as the step that switches the constraint off is no floor
            raise ConfigError("level_floor_std must be below level_floor_max_step",
                              column="level_floor_std", expected=f"< {self.level_floor_max_step}",
                              found=self.level_floor_std)
        if self.stride_height_noise >= 1.0:
            raise ConfigError("stride_height_noise is a fraction of the stride length",
                              column="stride_height_noise", expected="0 <= x < 1",
                              found=self.stride_height_noise)
        if int(self.update_every) < 1:
            raise ConfigError("update_every must be >= 1", column="update_every",
                              found=self.update_every)
        self.update_every = int(self.update_every)

    @classmethod
    def from_dict(cls, d: dict) -> FootConfig:
        """Build from a mapping (e.g. the ``[foot]`` table of a job file)."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ConfigError("unknown foot-mounted settings", column=unknown[0],
                              expected=sorted(names), found=unknown)
        return cls(**d)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["detector"] = self.detector.to_dict()
        return d


@dataclass
class FootResult:
    """Output of :func:`run_foot_ins`.

    ``trajectory`` is the reported solution (smoothed when ``config.smooth``), ``forward`` the
    filtered one; both have ``NAV_COLS`` plus ``east north up`` [m] relative to the start.
    ``std`` holds the forward standard deviations, ``biases`` the bias estimates, ``stillness``
    the detector output and ``innovations`` the ZUPT (``zupt_*``) and ZARU (``zaru_*``)
    innovations (NaN where no update); ``filter`` is the engine's result (innovation log,
    nodes, timing); ``selection`` the stance-threshold choice (None when the detector decided
    alone or the stances were given); ``height_aiding`` what the height aiding did
    (``{"level_floor": {"applied", "skipped"}, "baro": {"column", "readings"},
    "stride_height_noise": releases}``, empty without aiding).
    """

    trajectory: pd.DataFrame
    forward: pd.DataFrame
    std: pd.DataFrame
    biases: pd.DataFrame
    stillness: Stillness
    innovations: pd.DataFrame
    n_updates: int
    initial: NavState
    filter: object = None
    selection: ThresholdSelection | None = None
    height_aiding: dict = field(default_factory=dict)


# --- front end -------------------------------------------------------------------------------
def level_window_mask(t: np.ndarray, still: np.ndarray, seconds: float) -> np.ndarray:
    """Samples used for levelling: the first still run if it starts within ``seconds`` of the
    start (capped at 4 * ``seconds``), else the first ``seconds``."""
    t0 = t[0]
    idx = np.flatnonzero(still)
    if idx.size and t[idx[0]] - t0 <= seconds:
        a = idx[0]
        ends = np.flatnonzero(~still[a:])
        b = a + (ends[0] if ends.size else still.size - a)
        m = np.zeros(t.size, bool)
        m[a:b] = True
        m &= t - t[a] <= 4.0 * seconds
        if m.sum() >= 3:
            return m
    return t - t0 <= seconds


def initial_state(t, gyro, acc, still, config: FootConfig, lat=0.0, lon=0.0, height=0.0):
    """Levelled initial :class:`NavState` and gyro bias from the start window."""
    m = level_window_mask(t, still, config.level_window)
    if m.sum() < 2:
        raise AlignmentError("fewer than 2 samples in the levelling window",
                             expected=f">= 2 samples within {config.level_window} s")
    fm = acc[m].mean(axis=0)
    roll, pitch = level(fm)
    C = euler_to_dcm(roll, pitch, config.heading)
    bg0 = np.zeros(3)
    if still[m].all():  # mean rate minus the Earth rate seen by the levelled body
        bg0 = gyro[m].mean(axis=0) - C.T @ earth.earth_rate_l(lat)
    return NavState(lat, lon, height, np.zeros(3), C, float(t[0])), bg0


def _enu(nav: np.ndarray, lat0: float, lon0: float, h0: float) -> np.ndarray:
    e, n, u = earth.geodetic_to_enu(nav[:, 0], nav[:, 1], nav[:, 2], lat0, lon0, h0)
    return np.column_stack([e, n, u])


def _arr(x, dtype=float) -> np.ndarray:
    """C-contiguous, writeable array (pandas may hand out read-only views; numba would compile
    a separate read-only specialisation of the kernels for them)."""
    return np.require(x, dtype=dtype, requirements=["C", "W"])


def _gate_probability(gate: float) -> float | None:
    """The engine's gating probability of a 3-dof NIS threshold (None: no gate)."""
    if not np.isfinite(gate):
        return None
    return float(chi2_cdf(gate, 3))


def foot_filter_config(cfg: FootConfig, bg0, dt: float, duration: float) -> FilterConfig:
    """The engine configuration of the foot profile: the short-term (pedestrian) error
    dynamics, random-walk biases with the foot's PSDs and initial stds, dynamics-dependent
    noise, the propagation at the IMU interval ``dt``
    and one epoch segment over the walk (``duration`` [s]: every sample is a node of the
    high-rate path), no runaway-NIS monitor, smoother without covariances."""
    imu_model = ImuErrorModel(gyro_arw=cfg.gyro_psd, accel_vrw=cfg.accel_psd,
                              gyro_rrw=cfg.gyro_bias_rw, accel_rrw=cfg.accel_bias_rw)
    return FilterConfig(
        imu_model=imu_model, bias_model="random_walk", propagation_interval=dt,
        epoch_interval=max(duration, dt), gate_probability=None,
        gate_probabilities={"zupt": _gate_probability(cfg.gate_zupt),
                            "zaru": _gate_probability(cfg.gate_zaru)},
        initial_pos_std=cfg.init_pos_std, initial_vel_std=cfg.init_vel_std,
        initial_att_std=(cfg.init_att_std, cfg.init_att_std, cfg.init_heading_std),
        initial_gyro_bias_std=cfg.init_gyro_bias_std,
        initial_accel_bias_std=cfg.init_accel_bias_std, gyro_bias=tuple(np.asarray(bg0, float)),
        gravity_model=cfg.gravity_model, smoother=cfg.smooth, smoother_covariance=False,
        nis_window=None, error_dynamics="short_term", accel_dynamic_noise=cfg.accel_dyn_noise,
        gyro_dynamic_noise=cfg.gyro_dyn_noise)


def foot_measurements(t, gyro, still, stat, bg0, cfg: FootConfig) -> list:
    """High-rate ZUPT (soft: sigma from the detector statistic ``stat``) and ZARU models on the
    still samples (every ``update_every``-th of a still run, never the first sample)."""
    still = np.asarray(still, bool).copy()
    still[0] = False  # the initial state
    # position of each sample in its still run
    start = np.flatnonzero(still & ~np.concatenate([[False], still[:-1]]))
    run_id = np.cumsum(still & ~np.concatenate([[False], still[:-1]])) - 1
    pos_in_run = np.arange(t.size) - start[np.maximum(run_id, 0)] if start.size else \
        np.zeros(t.size, np.int64)
    upd = still & (pos_in_run % cfg.update_every == 0)
    sigma = np.full(t.size, cfg.sigma_zupt)
    stat = np.asarray(stat, float)
    if cfg.zupt_noise_exponent > 0 and np.all(np.isfinite(stat)):
        sigma *= np.maximum(1.0, stat / cfg.zupt_noise_ref) ** cfg.zupt_noise_exponent
    # a detected stance is rest (the foot's only re-anchor): the gate recovery may force it in
    out = [Zupt(t[upd], std=sigma[upd], high_rate=True, recoverable=True)]
    if cfg.zaru:
        z = upd.copy()
        if cfg.zaru_max_rate < np.inf:
            z &= np.linalg.norm(gyro - bg0, axis=1) < cfg.zaru_max_rate
        out.append(Zaru(t[z], std=cfg.sigma_zaru, average=False, high_rate=True,
                        recoverable=True))
    return out


class _Epochs(Measurement):
    """Filter epochs without a measurement (where extra process noise is added)."""

    name = "epochs"

    def evaluate(self, i, nav):
        return None


def height_aiding(t, still, cfg: FootConfig, baro: pd.DataFrame | None = None,
                  east_north: np.ndarray | None = None) -> tuple[list, pd.DataFrame | None]:
    """The height-aiding measurements of a foot run and the per-stride height noise.

    Parameters
    ----------
    t, still : array
        Sample times [s] and stance flags.
    cfg : FootConfig
        ``level_floor*``, ``baro*`` and ``stride_height_noise`` settings.
    baro : DataFrame, optional
        Barometer readings (a :data:`~.filter.height_aiding.BARO_COLUMNS` column) indexed by
        time; used when ``cfg.baro``.
    east_north : (N, 2) array, optional
        Horizontal positions [m] of a forward pass: the length ``L`` of the stride starting at
        each stance release is the distance between the mean positions of the two still runs
        (:func:`insgnss.strides.stance_positions`); without it no per-stride noise is added.

    Returns
    -------
    measurements, extra_noise
        Measurement models and the ``FilterConfig.extra_noise`` table (``up_std = k L`` at
        the last still sample of each run but the final one), or ``([], None)`` when no
        height aiding applies.
    """
    meas: list = []
    runs = still_runs(still)
    if cfg.level_floor and len(runs) > 1:
        meas.append(LevelFloor([(t[a], t[b - 1]) for a, b in runs], std=cfg.level_floor_std,
                               max_step=cfg.level_floor_max_step,
                               max_slope=cfg.level_floor_max_slope))
    if cfg.baro and baro is not None and len(baro):
        meas.append(BaroHeight(baro, std=cfg.baro_std, interval=cfg.baro_interval,
                               offset_psd=cfg.baro_offset_psd))
    if not meas:
        return [], None
    noise = None
    if east_north is not None and cfg.stride_height_noise > 0 and len(runs) > 1:
        p = stance_positions(east_north, still, min_samples=1)
        length = np.linalg.norm(np.diff(p, axis=0), axis=1)
        release = t[runs[:-1, 1] - 1]
        noise = pd.DataFrame({"up_std": cfg.stride_height_noise * length},
                             index=pd.Index(release, name="time"))
        meas.append(_Epochs(release))
    return meas, noise


def foot_filter_arrays(t, dth, dv, gyro, still, stat, initial: NavState, bg0,
                       cfg: FootConfig, extra: tuple[list, pd.DataFrame | None] = ([], None)
                       ) -> dict:
    """Array core of :func:`run_foot_ins`: increments ``dth, dv`` (N,3), rates ``gyro`` (N,3)
    for the ZARU sample selection, ``still`` flags, detector statistic ``stat`` (NaN: no soft
    ZUPT), initial state and gyro bias. Returns a dict: ``nav``, ``nav_smoothed`` (N,9
    :data:`NAV_COLS`), ``bias`` (N,6), ``std`` (N,9), ``innovations`` (N,6: ZUPT e n u, ZARU
    x y z; NaN where none), ``n_updates`` and ``result`` (the engine's
    :class:`~insgnss.filter.engine.FilterResult`)."""
    t = _arr(t)
    dt = float(np.median(np.diff(t)))
    fcfg = foot_filter_config(cfg, bg0, dt, float(t[-1] - t[0]))
    fcfg.extra_noise = extra[1]
    meas = foot_measurements(t, gyro, still, stat, bg0, cfg) + list(extra[0])
    extras = [x for m in meas for x in m.extra_states()]  # the barometer's offset state
    model = StrapdownModel.from_increments(t, _arr(dth), _arr(dv), initial, extras, fcfg)
    res = run_engine(model, meas, fcfg)
    if not res.complete:
        raise FilterHealthError(f"foot-mounted filter stopped: {res.error}",
                                found=str(res.error))
    fwd = res.forward_array
    nav = fwd[:, :9]
    nav_s = res.smoothed_array[:, :9] if res.smoothed_table is not None else nav
    log = res.log
    nu = np.full((t.size, 6), np.nan)
    ok = log["accepted"]
    if ok.size:
        rows = np.searchsorted(t, log["time"])
        for k, name in ((0, "zupt"), (3, "zaru")):
            sel = ok & (log["tid"] == log["names"].index(name)) if name in log["names"] else \
                np.zeros(ok.size, bool)
            nu[rows[sel], k:k + 3] = log["innov"][sel, :3]
    return {"nav": nav, "nav_smoothed": nav_s, "bias": fwd[:, 18:24], "std": fwd[:, 9:18],
            "innovations": nu,
            "n_updates": int(ok.sum()), "result": res}


def _baro_table(imu: pd.DataFrame, baro: pd.DataFrame | None) -> pd.DataFrame | None:
    """The barometer readings of a run: ``baro`` if given, else the first
    :data:`~.filter.height_aiding.BARO_COLUMNS` column of the IMU table (None without)."""
    if baro is not None:
        return baro
    cols = [c for c in BARO_COLUMNS if c in imu.columns]
    if not cols:
        return None
    b = imu[[cols[0]]]
    b = b[np.isfinite(b[cols[0]].to_numpy(float))]
    return b if len(b) else None


def run_foot_ins(
    imu: pd.DataFrame,
    config: FootConfig | None = None,
    *,
    initial: NavState | None = None,
    still: Stillness | pd.Series | np.ndarray | None = None,
    lat: float = 0.0,
    lon: float = 0.0,
    height: float = 0.0,
    baro: pd.DataFrame | None = None,
) -> FootResult:
    """Foot-mounted ZUPT(+ZARU) INS on an IMU table (body RFU, rates or increments).

    Parameters
    ----------
    imu : DataFrame
        IMU table indexed by time [s], body frame right-forward-up; an optional ``pressure``
        [Pa] or ``baro_height`` [m] column is barometer height (``config.baro``).
    config : FootConfig, optional
        Settings (default: the foot profile).
    initial : NavState, optional
        Initial state; by default levelled from the first still window with heading
        ``config.heading`` at (``lat``, ``lon``, ``height``) [rad, rad, m].
    still : Stillness, bool Series or array, optional
        Declared still samples (a :class:`Stillness` also brings its statistic for the soft
        ZUPT); by default ``config.detector`` decides, with the threshold chosen per recording
        when ``config.threshold_selection = "innovation"``.
    baro : DataFrame, optional
        Barometer readings indexed by time with a ``pressure`` or ``baro_height`` column, in
        place of the IMU table's.

    Returns
    -------
    FootResult
    """
    cfg = config or FootConfig()
    t, gyro, acc = imu_rates(imu)
    _, dth, dv = increments(imu)
    given = initial

    def start(flags):
        if given is not None:
            return given, np.zeros(3)
        return initial_state(t, gyro, acc, flags, cfg, lat, lon, height)

    fwd_cfg = replace(cfg, smooth=False)

    def forward(flags, stat_):
        ini, b0 = start(flags)
        return foot_filter_arrays(t, dth, dv, gyro, flags, stat_, ini, b0, fwd_cfg), ini

    selection = None
    if still is None and cfg.threshold_selection == "innovation":
        stat, _ = statistic_arrays(t, gyro, acc, cfg.detector)
        selection = select_threshold(
            t, stat, cfg.detector, lambda f: forward(f, stat)[0]["innovations"][:, :3],
            cfg.selection_fixed, cfg.selection_relative)
        st_flags, thr = selection.still, selection.threshold
    elif still is None:
        st_flags, stat, thr = detect_arrays(t, gyro, acc, cfg.detector)
    elif isinstance(still, Stillness):
        st_flags = still.still.to_numpy(bool)
        stat = still.statistic.to_numpy(float)
        thr = still.threshold.to_numpy(float)
        if st_flags.size != t.size:
            raise ConfigError("stillness length differs from the IMU table", column="still",
                              expected=t.size, found=st_flags.size)
    else:
        st_flags = np.asarray(still, bool)
        if st_flags.size != t.size:
            raise ConfigError("still mask length differs from the IMU table", column="still",
                              expected=t.size, found=st_flags.size)
        stat = np.full(t.size, np.nan)
        thr = np.full(t.size, np.nan)
    initial, bg0 = start(st_flags)
    baro = _baro_table(imu, baro)
    extra = height_aiding(t, st_flags, cfg, baro)
    if extra[0] and cfg.stride_height_noise > 0:  # stride lengths from a forward pass
        f, ini = forward(st_flags, stat)
        en = _enu(f["nav"], ini.lat, ini.lon, ini.height)[:, :2]
        extra = height_aiding(t, st_flags, cfg, baro, en)
    out = foot_filter_arrays(t, dth, dv, gyro, st_flags, stat, initial, bg0, cfg, extra)
    nav, nav_s, bias, std, nu, nupd = (out[k] for k in ("nav", "nav_smoothed", "bias", "std",
                                                        "innovations", "n_updates"))
    idx = pd.Index(t, name="time")

    def table(arr):
        df = pd.DataFrame(arr, index=idx, columns=NAV_COLS)
        enu = _enu(arr, initial.lat, initial.lon, initial.height)
        df["east"], df["north"], df["up"] = enu[:, 0], enu[:, 1], enu[:, 2]
        return df

    fwd = table(nav)
    traj = table(nav_s) if cfg.smooth else fwd
    method = ("select" if selection is not None else cfg.detector.method) if still is None \
        else getattr(still, "method", "declared")
    stillness = Stillness(pd.Series(st_flags, idx, name="still"),
                          pd.Series(stat, idx, name="statistic"),
                          pd.Series(thr, idx, name="threshold"), method)
    innov = pd.DataFrame(nu, index=idx, columns=["zupt_e", "zupt_n", "zupt_u", "zaru_x", "zaru_y",
                                                 "zaru_z"])
    return FootResult(traj, fwd, pd.DataFrame(std, index=idx, columns=STD_COLS),
                      pd.DataFrame(bias, index=idx, columns=BIAS_COLS), stillness, innov,
                      int(nupd), initial, out["result"], selection, _aiding_report(*extra))


def _aiding_report(meas: list, noise: pd.DataFrame | None) -> dict:
    """What the height aiding of a run did (:attr:`FootResult.height_aiding`)."""
    rep: dict = {}
    for m in meas:
        if isinstance(m, LevelFloor):
            rep["level_floor"] = {"applied": m.applied, "skipped": m.skipped}
        elif isinstance(m, BaroHeight):
            rep["baro"] = {"column": m.source_column, "readings": int(m.times.size)}
    if noise is not None:
        rep["stride_height_noise"] = {"releases": int(len(noise)),
                                      "up_std_median_m": float(np.median(noise["up_std"]))}
    return rep
