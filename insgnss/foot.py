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

from dataclasses import asdict, dataclass, field, fields

import numpy as np
import pandas as pd

from . import earth
from .align import level
from .attitude import euler_to_dcm
from .detect import DetectorConfig, Stillness, detect_arrays, imu_rates
from .errors import AlignmentError, ConfigError, FilterHealthError
from .filter.engine import BIAS_COLS, FilterConfig, run_engine
from .filter.measurements import Zaru, Zupt
from .filter.strapdown_model import STD_COLS, StrapdownModel
from .imu import ImuErrorModel, increments
from .mechanization.strapdown import NAV_COLS, NavState
from .stats import chi2_cdf

__all__ = ["FootConfig", "FootResult", "foot_detector", "foot_filter_arrays",
           "foot_filter_config", "initial_state", "level", "level_window_mask", "run_foot_ins"]


# --- configuration ---------------------------------------------------------------------------
#: pyshoe's SHOE noise levels (Wagstaff et al. 2019): sigma_a [m/s^2], sigma_w [rad/s]
PYSHOE_SIGMA_A = 0.00098
PYSHOE_SIGMA_W = 8.7266e-5


def foot_detector() -> DetectorConfig:
    """The foot preset's stance detector: gait-adaptive SHOE (see :mod:`insgnss.detect`)."""
    return DetectorConfig(method="adaptive", window=0.04, threshold=1.0e6,
                          sigma_a=PYSHOE_SIGMA_A, sigma_w=PYSHOE_SIGMA_W, adapt_window=3.0,
                          adapt_factor=10.0, adapt_peak_ratio=30.0, adapt_gait_peak=5.0e8,
                          quiet_duration=0.5)


@dataclass
class FootConfig:
    """Foot-mounted INS settings (SI units).

    Attributes
    ----------
    detector : DetectorConfig
        Stance detector (see :mod:`insgnss.detect`).
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
        Velocity / angle random walk of the process model [m/s/sqrt(s)], [rad/sqrt(s)]
        (larger than the datasheet values: they also cover the unmodelled dynamics of a foot).
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
    """

    detector: DetectorConfig = field(default_factory=foot_detector)
    zaru: bool = True
    zaru_max_rate: float = 0.05
    sigma_zupt: float = 0.01
    sigma_zaru: float = 0.01
    update_every: int = 1
    zupt_noise_exponent: float = 0.25
    zupt_noise_ref: float = 1.0e5
    gate_zupt: float = np.inf
    gate_zaru: float = np.inf
    accel_psd: float = 0.01
    gyro_psd: float = 3e-3
    accel_dyn_noise: float = 0.01
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

    def __post_init__(self):
        if isinstance(self.detector, dict):
            self.detector = DetectorConfig.from_dict(self.detector)
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
    nodes, timing).
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
    out = [Zupt(t[upd], std=sigma[upd], high_rate=True)]
    if cfg.zaru:
        z = upd.copy()
        if cfg.zaru_max_rate < np.inf:
            z &= np.linalg.norm(gyro - bg0, axis=1) < cfg.zaru_max_rate
        out.append(Zaru(t[z], std=cfg.sigma_zaru, average=False, high_rate=True))
    return out


def foot_filter_arrays(t, dth, dv, gyro, still, stat, initial: NavState, bg0,
                       cfg: FootConfig) -> dict:
    """Array core of :func:`run_foot_ins`: increments ``dth, dv`` (N,3), rates ``gyro`` (N,3)
    for the ZARU sample selection, ``still`` flags, detector statistic ``stat`` (NaN: no soft
    ZUPT), initial state and gyro bias. Returns a dict: ``nav``, ``nav_smoothed`` (N,9
    :data:`NAV_COLS`), ``bias`` (N,6), ``std`` (N,9), ``innovations`` (N,6: ZUPT e n u, ZARU
    x y z; NaN where none), ``n_updates`` and ``result`` (the engine's
    :class:`~insgnss.filter.engine.FilterResult`)."""
    t = _arr(t)
    dt = float(np.median(np.diff(t)))
    fcfg = foot_filter_config(cfg, bg0, dt, float(t[-1] - t[0]))
    meas = foot_measurements(t, gyro, still, stat, bg0, cfg)
    model = StrapdownModel.from_increments(t, _arr(dth), _arr(dv), initial, [], fcfg)
    res = run_engine(model, meas, fcfg)
    if not res.complete:
        raise FilterHealthError(f"foot-mounted filter stopped: {res.error}",
                                found=str(res.error))
    fwd = res.forward.to_numpy()
    nav = fwd[:, :9]
    nav_s = res.smoothed.to_numpy()[:, :9] if res.smoothed is not None else nav
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


def run_foot_ins(
    imu: pd.DataFrame,
    config: FootConfig | None = None,
    *,
    initial: NavState | None = None,
    still: Stillness | pd.Series | np.ndarray | None = None,
    lat: float = 0.0,
    lon: float = 0.0,
    height: float = 0.0,
) -> FootResult:
    """Foot-mounted ZUPT(+ZARU) INS on an IMU table (body RFU, rates or increments).

    Parameters
    ----------
    imu : DataFrame
        IMU table indexed by time [s], body frame right-forward-up.
    config : FootConfig, optional
        Settings (default: the foot preset).
    initial : NavState, optional
        Initial state; by default levelled from the first still window with heading
        ``config.heading`` at (``lat``, ``lon``, ``height``) [rad, rad, m].
    still : Stillness, bool Series or array, optional
        Declared still samples (a :class:`Stillness` also brings its statistic for the soft
        ZUPT); by default ``config.detector`` decides.

    Returns
    -------
    FootResult
    """
    cfg = config or FootConfig()
    t, gyro, acc = imu_rates(imu)
    if still is None:
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
    bg0 = np.zeros(3)
    if initial is None:
        initial, bg0 = initial_state(t, gyro, acc, st_flags, cfg, lat, lon, height)
    _, dth, dv = increments(imu)
    out = foot_filter_arrays(t, dth, dv, gyro, st_flags, stat, initial, bg0, cfg)
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
    stillness = Stillness(pd.Series(st_flags, idx, name="still"),
                          pd.Series(stat, idx, name="statistic"),
                          pd.Series(thr, idx, name="threshold"),
                          cfg.detector.method if still is None else
                          getattr(still, "method", "declared"))
    innov = pd.DataFrame(nu, index=idx, columns=["zupt_e", "zupt_n", "zupt_u", "zaru_x", "zaru_y",
                                                 "zaru_z"])
    return FootResult(traj, fwd, pd.DataFrame(std, index=idx, columns=STD_COLS),
                      pd.DataFrame(bias, index=idx, columns=BIAS_COLS), stillness, innov,
                      int(nupd), initial, out["result"])
