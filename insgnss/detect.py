"""Stillness (zero-velocity) detectors for ZUPT / ZARU.

Every detector computes a windowed test statistic ``T_k`` from the IMU samples in a window of
``W`` samples centred on sample ``k`` (truncated at the ends) and declares the sample still when
``T_k`` is below a threshold. Notation: ``a_j`` specific force [m/s^2], ``w_j`` angular rate
[rad/s] (both in any body frame), ``abar`` the window mean of ``a_j``, ``g`` the magnitude of
gravity.

``shoe``  SHOE / GLRT (Skog, Handel, Nilsson, Rantakokko, 2010, "Zero-velocity detection -- an
          algorithm evaluation", IEEE Trans. Biomed. Eng. 57(11), eq. 21), dimensionless::

              T = 1/W sum_j ( |a_j - g abar/|abar||^2 / sigma_a^2 + |w_j|^2 / sigma_w^2 )

``amv``   acceleration moving variance, reported as the standard deviation of the specific-force
          vector over the window [m/s^2]: ``T = sqrt(1/W sum_j |a_j - abar|^2)``.
``are``   angular-rate energy, reported as the RMS angular rate [rad/s]:
          ``T = sqrt(1/W sum_j |w_j|^2)``.
``mag``   acceleration magnitude, reported as the RMS deviation of ``|a_j|`` from ``g``
          [m/s^2]: ``T = sqrt(1/W sum_j (|a_j| - g)^2)``.
``adaptive``  (insgnss' own, the foot-mounted default) SHOE statistic with a gait-adaptive
          threshold. Per-trial tuned SHOE thresholds on the PyShoe data span three decades
          (walking ~3e6, running ~3e8 at pyshoe's sigmas): a running foot never comes to rest
          as completely as a walking one, and its stance valleys sit higher. The threshold
          follows the depth of the surrounding stance valleys::

              m_k  = min of T over [k - h, k + h], skipping standing periods
                     (runs with T < gamma_lo lasting at least ``quiet_duration``)
              M_k  = max of T over [k - h, k + h]      (swing peak level)
              gamma_k = gamma_lo                                   if M_k < gait_peak
                      = clip(factor * m_k, gamma_lo, M_k / peak_ratio)  otherwise

          ``gamma_lo`` (the ``threshold``) is the floor that also serves standing and motions
          without a gait (no swing peaks above ``gait_peak``: crawling, shuffling), where only
          true stillness may be used; the cap ``M_k / peak_ratio`` keeps the threshold well
          below the swing level. The window (2h + 1 samples, ``adapt_window`` seconds) spans a
          few strides. This follows the idea of gait-dependent thresholds (Wagstaff,
          Peretroukhin, Kelly 2017, "Improving foot-mounted inertial navigation through
          real-time motion classification") without a classifier.

With pyshoe's noise levels (``sigma_a = 0.00098 m/s^2``, ``sigma_w = 8.7266e-5 rad/s``) the
SHOE statistic is dominated by the rate term, ``T ~ |w|^2 / sigma_w^2``: ``T = 1e6`` is an RMS
rate of about 0.087 rad/s (5 deg/s), ``1e8`` about 0.87 rad/s.

Post-processing of the raw decisions (all in compiled per-sample loops):

- **hysteresis**: a still segment is entered when ``T < gamma`` and left only when
  ``T > hysteresis * gamma`` (``hysteresis >= 1``);
- **minimum motion**: motion segments shorter than ``min_motion`` [s] between two still
  segments are treated as still (fills one-sample drop-outs inside a stance);
- **minimum stance**: still segments shorter than ``min_stance`` [s] are discarded (no ZUPT on a
  fleeting dip of the statistic in mid-swing);
- **margin**: every still segment is then shortened by ``margin`` [s] at both ends. A centred
  window sees the start of a motion only once half of it covers the motion, so the raw decision
  overhangs the motion by up to half a window; a vehicle that pulls away smoothly would get
  ZUPTs while it already moves.

The result is a :class:`Stillness` holding the boolean series, the statistic and the
threshold used, all as pandas Series indexed by time.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np
import pandas as pd
from numba import njit

from .errors import ConfigError
from .imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS, is_increment_table

METHODS = ("shoe", "amv", "are", "mag", "adaptive")
G_STANDARD = 9.80665


# --- compiled statistics ---------------------------------------------------------------------
@njit(cache=True)
def _window_bounds(k, n, half_lo, half_hi):
    lo = k - half_lo
    hi = k + half_hi + 1
    if lo < 0:
        lo = 0
    if hi > n:
        hi = n
    return lo, hi


@njit(cache=True)
def shoe_statistic(acc, gyro, window, sigma_a, sigma_w, g):
    """SHOE/GLRT statistic per sample (centred window of ``window`` samples)."""
    n = acc.shape[0]
    out = np.empty(n)
    half_lo = (window - 1) // 2
    half_hi = window - 1 - half_lo
    ia = 1.0 / (sigma_a * sigma_a)
    iw = 1.0 / (sigma_w * sigma_w)
    for k in range(n):
        lo, hi = _window_bounds(k, n, half_lo, half_hi)
        mx = 0.0
        my = 0.0
        mz = 0.0
        for j in range(lo, hi):
            mx += acc[j, 0]
            my += acc[j, 1]
            mz += acc[j, 2]
        nm = np.sqrt(mx * mx + my * my + mz * mz)
        if nm > 0.0:
            ux, uy, uz = g * mx / nm, g * my / nm, g * mz / nm
        else:
            ux, uy, uz = 0.0, 0.0, g
        s = 0.0
        for j in range(lo, hi):
            dx = acc[j, 0] - ux
            dy = acc[j, 1] - uy
            dz = acc[j, 2] - uz
            s += ia * (dx * dx + dy * dy + dz * dz)
            s += iw * (gyro[j, 0] ** 2 + gyro[j, 1] ** 2 + gyro[j, 2] ** 2)
        out[k] = s / (hi - lo)
    return out


@njit(cache=True)
def amv_statistic(acc, window):
    """Standard deviation of the specific-force vector over the window [m/s^2]."""
    n = acc.shape[0]
    out = np.empty(n)
    half_lo = (window - 1) // 2
    half_hi = window - 1 - half_lo
    for k in range(n):
        lo, hi = _window_bounds(k, n, half_lo, half_hi)
        m = hi - lo
        mx = 0.0
        my = 0.0
        mz = 0.0
        for j in range(lo, hi):
            mx += acc[j, 0]
            my += acc[j, 1]
            mz += acc[j, 2]
        mx /= m
        my /= m
        mz /= m
        s = 0.0
        for j in range(lo, hi):
            s += (acc[j, 0] - mx) ** 2 + (acc[j, 1] - my) ** 2 + (acc[j, 2] - mz) ** 2
        out[k] = np.sqrt(s / m)
    return out


@njit(cache=True)
def are_statistic(gyro, window):
    """RMS angular rate over the window [rad/s]."""
    n = gyro.shape[0]
    out = np.empty(n)
    half_lo = (window - 1) // 2
    half_hi = window - 1 - half_lo
    for k in range(n):
        lo, hi = _window_bounds(k, n, half_lo, half_hi)
        s = 0.0
        for j in range(lo, hi):
            s += gyro[j, 0] ** 2 + gyro[j, 1] ** 2 + gyro[j, 2] ** 2
        out[k] = np.sqrt(s / (hi - lo))
    return out


@njit(cache=True)
def mag_statistic(acc, window, g):
    """RMS deviation of the specific-force magnitude from ``g`` over the window [m/s^2]."""
    n = acc.shape[0]
    out = np.empty(n)
    half_lo = (window - 1) // 2
    half_hi = window - 1 - half_lo
    for k in range(n):
        lo, hi = _window_bounds(k, n, half_lo, half_hi)
        s = 0.0
        for j in range(lo, hi):
            d = np.sqrt(acc[j, 0] ** 2 + acc[j, 1] ** 2 + acc[j, 2] ** 2) - g
            s += d * d
        out[k] = np.sqrt(s / (hi - lo))
    return out


@njit(cache=True)
def running_max(x, half):
    """Maximum of ``x`` over the centred window ``[k - half, k + half]`` (monotone deque, O(N))."""
    n = x.shape[0]
    out = np.empty(n)
    dq = np.empty(n, np.int64)
    head = 0
    tail = 0
    nxt = 0  # next index to push
    for k in range(n):
        hi = min(n - 1, k + half)
        while nxt <= hi:
            while tail > head and x[dq[tail - 1]] <= x[nxt]:
                tail -= 1
            dq[tail] = nxt
            tail += 1
            nxt += 1
        lo = k - half
        while dq[head] < lo:
            head += 1
        out[k] = x[dq[head]]
    return out


@njit(cache=True)
def running_min(x, half):
    """Minimum of ``x`` over the centred window ``[k - half, k + half]`` (O(N))."""
    return -running_max(-x, half)


@njit(cache=True)
def quiet_runs(stat, level, min_len):
    """True on runs of ``stat < level`` lasting at least ``min_len`` samples (standing)."""
    n = stat.shape[0]
    out = np.zeros(n, np.bool_)
    k = 0
    while k < n:
        if stat[k] < level:
            j = k
            while j < n and stat[j] < level:
                j += 1
            if j - k >= min_len:
                for i in range(k, j):
                    out[i] = True
            k = j
        else:
            k += 1
    return out


@njit(cache=True)
def gait_adaptive_threshold(stat, half, gamma_lo, factor, peak_ratio, gait_peak, quiet_len,
                            gamma_max):
    """Gait-adaptive SHOE threshold (see the module docstring, ``adaptive``)."""
    n = stat.shape[0]
    quiet = quiet_runs(stat, gamma_lo, quiet_len)
    s2 = np.empty(n)
    for k in range(n):
        s2[k] = np.inf if quiet[k] else stat[k]
    m = running_min(s2, half)
    mx = running_max(stat, half)
    out = np.empty(n)
    for k in range(n):
        if mx[k] < gait_peak:
            g = gamma_lo
        else:
            g = factor * m[k] if np.isfinite(m[k]) else gamma_lo
            cap = mx[k] / peak_ratio
            if g > cap:
                g = cap
            if g < gamma_lo:
                g = gamma_lo
        if g > gamma_max:
            g = gamma_max
        out[k] = g
    return out


# --- compiled decision logic -----------------------------------------------------------------
@njit(cache=True)
def hysteresis_decision(stat, threshold, ratio):
    """Still when ``stat < threshold``; once still, stay still until ``stat > ratio*threshold``."""
    n = stat.shape[0]
    out = np.zeros(n, np.bool_)
    still = False
    for k in range(n):
        if still:
            still = stat[k] <= ratio * threshold[k]
        else:
            still = stat[k] < threshold[k]
        out[k] = still
    return out


@njit(cache=True)
def fill_short_runs(flags, value, min_len):
    """Flip runs of ``flags == value`` shorter than ``min_len`` samples that are bounded on both
    sides by the opposite value (interior runs only) and return a new array."""
    n = flags.shape[0]
    out = flags.copy()
    k = 0
    while k < n:
        if flags[k] == value:
            j = k
            while j < n and flags[j] == value:
                j += 1
            if k > 0 and j < n and (j - k) < min_len:
                for i in range(k, j):
                    out[i] = not value
            k = j
        else:
            k += 1
    return out


@njit(cache=True)
def shrink_runs(flags, n):
    """Shorten every still run by ``n`` samples at both ends (runs of ``2n`` or fewer vanish);
    runs touching the start or the end of the record are not shortened there."""
    m = flags.shape[0]
    out = flags.copy()
    k = 0
    while k < m:
        if flags[k]:
            j = k
            while j < m and flags[j]:
                j += 1
            a = k + n if k > 0 else k
            b = j - n if j < m else j
            for i in range(k, j):
                out[i] = a <= i < b
            k = j
        else:
            k += 1
    return out


@njit(cache=True)
def drop_short_runs(flags, min_len):
    """Clear still runs (``True``) shorter than ``min_len`` samples, including runs at the ends."""
    n = flags.shape[0]
    out = flags.copy()
    k = 0
    while k < n:
        if flags[k]:
            j = k
            while j < n and flags[j]:
                j += 1
            if (j - k) < min_len:
                for i in range(k, j):
                    out[i] = False
            k = j
        else:
            k += 1
    return out


# --- configuration and front end -------------------------------------------------------------
@dataclass
class DetectorConfig:
    """Stillness detector settings (SI units; see the module docstring for each method).

    Attributes
    ----------
    method : {"shoe", "amv", "are", "mag", "adaptive"}
    window : float
        Window length [s] (rounded to an odd-or-even sample count, at least 1).
    threshold : float
        ``shoe``/``adaptive``: dimensionless GLRT threshold ``gamma`` (the floor ``gamma_lo`` for
        adaptive);
        ``amv``: accel standard deviation [m/s^2]; ``are``: RMS angular rate [rad/s];
        ``mag``: RMS magnitude deviation [m/s^2].
    sigma_a, sigma_w : float
        SHOE noise levels [m/s^2], [rad/s].
    gravity : float or None
        Gravity magnitude [m/s^2]; None estimates it as the median specific-force magnitude over
        the 20 % of windows with the lowest angular-rate energy.
    hysteresis : float
        Exit threshold / entry threshold (>= 1).
    min_stance, min_motion : float
        Minimum still-segment duration and the longest motion gap filled as still [s].
    margin : float
        Still segments are shortened by this at both ends [s] (after the other steps).
    adapt_window : float
        ``adaptive``: length ``2h`` of the window of the valley and peak levels [s].
    adapt_factor, adapt_peak_ratio, adapt_gait_peak : float
        ``adaptive``: ``factor``, ``peak_ratio`` and ``gait_peak`` of the module docstring.
    quiet_duration : float
        ``adaptive``: runs below ``threshold`` at least this long [s] are standing and are
        left out of the valley level.
    threshold_max : float
        Upper bound of the (adaptive) threshold.
    """

    method: str = "shoe"
    window: float = 0.05
    threshold: float = 1.0e4
    sigma_a: float = 0.01
    sigma_w: float = 0.1 * np.pi / 180.0
    gravity: float | None = None
    hysteresis: float = 1.0
    min_stance: float = 0.0
    min_motion: float = 0.0
    margin: float = 0.0
    adapt_window: float = 3.0
    adapt_factor: float = 10.0
    adapt_peak_ratio: float = 100.0
    adapt_gait_peak: float = 1.0e9
    quiet_duration: float = 0.5
    threshold_max: float = np.inf

    def __post_init__(self):
        if self.method not in METHODS:
            raise ConfigError(f"unknown stillness detector {self.method!r}", column="method",
                              expected=list(METHODS), found=self.method)
        for name in ("window", "threshold", "sigma_a", "sigma_w"):
            if not float(getattr(self, name)) > 0.0:
                raise ConfigError(f"detector {name} must be positive", column=name,
                                  found=getattr(self, name))
        if self.hysteresis < 1.0:
            raise ConfigError("hysteresis must be >= 1", column="hysteresis", found=self.hysteresis)
        if self.min_stance < 0 or self.min_motion < 0:
            raise ConfigError("minimum durations must be >= 0", column="min_stance")
        if self.margin < 0:
            raise ConfigError("margin must be >= 0", column="margin", found=self.margin)

    @classmethod
    def from_dict(cls, d: dict) -> DetectorConfig:
        """Build from a mapping (e.g. a TOML table); unknown keys raise :class:`ConfigError`."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ConfigError("unknown detector settings", column=unknown[0],
                              expected=sorted(names), found=unknown)
        return cls(**d)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class Stillness:
    """Detector output: ``still`` (bool), ``statistic`` and ``threshold`` Series indexed by time."""

    still: pd.Series
    statistic: pd.Series
    threshold: pd.Series
    method: str

    @property
    def fraction(self) -> float:
        """Fraction of samples declared still."""
        return float(np.mean(self.still.to_numpy()))

    def intervals(self) -> list[tuple[float, float]]:
        """Still intervals as ``(t_start, t_end)`` pairs (times of the first and last sample)."""
        s = self.still.to_numpy()
        t = np.asarray(self.still.index, float)
        d = np.diff(np.concatenate([[0], s.astype(np.int8), [0]]))
        starts = np.flatnonzero(d == 1)
        ends = np.flatnonzero(d == -1) - 1
        return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True)]


def imu_rates(imu: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, gyro, accel)`` rate arrays of an IMU table (increments are divided by the interval;
    row 0 of an increment table takes the rate of row 1).

    Rate tables are returned as sampled. Every noise-sensitive consumer (the detectors'
    statistics and their noise levels, static-window noise estimates) uses these arrays, never the
    trapezoidal increments of :func:`insgnss.imu.increments`, whose averaging of neighbouring
    samples halves the variance of white noise (issue 20).
    """
    t = np.asarray(imu.index, dtype=float)
    if is_increment_table(imu):
        dt = np.diff(t)
        w = np.empty((t.size, 3))
        a = np.empty((t.size, 3))
        w[1:] = imu[DTHETA_COLS].to_numpy(float)[1:] / dt[:, None]
        a[1:] = imu[DV_COLS].to_numpy(float)[1:] / dt[:, None]
        w[0], a[0] = w[min(1, t.size - 1)], a[min(1, t.size - 1)]
        return t, w, a
    return t, imu[GYRO_COLS].to_numpy(float), imu[ACCEL_COLS].to_numpy(float)


def estimate_gravity(gyro: np.ndarray, acc: np.ndarray, window: int) -> float:
    """Median specific-force magnitude over the 20 % of windows with the least rotation."""
    rate = are_statistic(gyro, max(window, 1))
    k = max(1, int(0.2 * rate.size))
    idx = np.argpartition(rate, k - 1)[:k]
    return float(np.median(np.linalg.norm(acc[idx], axis=1)))


def sample_count(seconds: float, dt: float) -> int:
    """Number of samples spanning ``seconds`` at interval ``dt`` (at least 1)."""
    return max(1, int(round(seconds / dt)))


def statistic_arrays(t, gyro, acc, config: DetectorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Array form of :func:`detect_stillness` before post-processing: ``(stat, threshold)``."""
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = sample_count(config.window, dt)
    # C-contiguous and writeable (pandas may return read-only views, for which numba would
    # compile separate specialisations)
    acc = np.require(acc, float, ["C", "W"])
    gyro = np.require(gyro, float, ["C", "W"])
    m = config.method
    g = config.gravity
    if g is None and m in ("shoe", "adaptive", "mag"):
        g = estimate_gravity(gyro, acc, w)
    if m in ("shoe", "adaptive"):
        stat = shoe_statistic(acc, gyro, w, config.sigma_a, config.sigma_w, g)
    elif m == "amv":
        stat = amv_statistic(acc, w)
    elif m == "are":
        stat = are_statistic(gyro, w)
    else:
        stat = mag_statistic(acc, w, g)
    if m == "adaptive":
        thr = gait_adaptive_threshold(
            stat, sample_count(0.5 * config.adapt_window, dt), float(config.threshold),
            float(config.adapt_factor), float(config.adapt_peak_ratio),
            float(config.adapt_gait_peak), sample_count(config.quiet_duration, dt),
            float(config.threshold_max))
    else:
        thr = np.full(stat.size, min(float(config.threshold), float(config.threshold_max)))
    return stat, thr


def decide(t, stat, thr, config: DetectorConfig) -> np.ndarray:
    """Hysteresis, minimum-motion gap filling and minimum-stance pruning."""
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    still = hysteresis_decision(stat, thr, float(config.hysteresis))
    if config.min_motion > 0:
        still = fill_short_runs(still, False, sample_count(config.min_motion, dt) + 1)
    if config.min_stance > 0:
        still = drop_short_runs(still, sample_count(config.min_stance, dt))
    if config.margin > 0:
        still = shrink_runs(still, sample_count(config.margin, dt))
    return still


def detect_arrays(t, gyro, acc, config: DetectorConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Array front end: ``(still, stat, threshold)`` for time ``t``, rates ``gyro``, ``acc``."""
    t = np.asarray(t, float)
    stat, thr = statistic_arrays(t, gyro, acc, config)
    return decide(t, stat, thr, config), stat, thr


def detect_stillness(imu: pd.DataFrame, config: DetectorConfig | None = None, **kwargs) -> Stillness:
    """Run a stillness detector on an IMU table.

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments) indexed by time [s]; the axes need not be RFU (the
        statistics are rotation invariant).
    config : DetectorConfig, optional
        Settings; keyword arguments override fields of it (or of the default).

    Returns
    -------
    Stillness
    """
    cfg = config or DetectorConfig()
    if kwargs:
        cfg = DetectorConfig(**{**cfg.to_dict(), **kwargs})
    t, gyro, acc = imu_rates(imu)
    still, stat, thr = detect_arrays(t, gyro, acc, cfg)
    idx = pd.Index(t, name="time")
    return Stillness(pd.Series(still, idx, name="still"), pd.Series(stat, idx, name="statistic"),
                     pd.Series(thr, idx, name="threshold"), cfg.method)
