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
``valley``  SHOE statistic with a threshold relative to the local stance-valley level, the
          window set by the gait's own period::

              v_k = q-quantile of T over [k - h, k + h], standing runs left out
              gamma_k = factor * v_k          (gamma_lo where the window holds only standing)
              2h = valley_strides * P,   P = gait period (autocorrelation of log T)

          The quantile (5 %) of a window spanning two gait cycles is the depth of the stance
          valleys around sample k: unlike the window minimum it is not set by one deep sample
          (a short pause), and the window scales with the cadence (a running stride is half a
          walking one). Used alone with a fixed ``adapt_factor``, or as one family of candidate
          thresholds of the per-recording selection below.

Per-recording threshold selection (:func:`threshold_candidates`, :func:`select_threshold`)
------------------------------------------------------------------------------------------
The best SHOE threshold of a recording is not a constant of the sensor: a walking foot comes
to rest at ``|w|`` of a few deg/s, a running one never drops below 30-60 deg/s, yet the foot's
velocity at the best threshold is about the same, 1-4 cm/s (Vicon, 28 PyShoe trials). The
threshold is therefore chosen from the recording itself, without truth, among a set of
candidates (fixed thresholds ``10^g`` and valley-relative ones ``10^c v_k``), by the
consistency of the ZUPT-aided INS they produce: for each candidate a forward ZUPT filter is
run and the criterion is the RMS velocity innovation at the first ZUPT of each stance
(:func:`stance_entry_rms`),

    J = sqrt( 1/S sum_s |nu_s|^2 ),   nu_s = v_INS at the first still sample of stance s,

the velocity the INS has accumulated over the preceding swing. A threshold that is too high
starts stances while the foot still moves (``nu_s`` contains its true velocity) and turns
mid-swing dips into stances (``nu_s`` of m/s); one that is too low misses stances (``nu_s``
after two swings of drift). The smallest ``J`` wins; fewer than ``min_stances`` stances give
``J = inf``. The filter is the caller's (:func:`insgnss.foot.run_foot_ins` passes its own
forward pass), so this module stays free of navigation code.

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

Static windows found in the data (:func:`find_static_windows`)
--------------------------------------------------------------
Initialization and noise measurement need the periods when the platform does not move, found
from the data instead of assumed. Two levels, both from the ``amv`` statistic of the specific
force and of the angular rate (standard deviation of the vector over a ``window``):

- **stationary**: below the platform's stillness limits (``max_accel_std``, ``max_rate_std``:
  a parked car vibrates with its engine, a hand trembles), and outside excluded intervals
  (bridged IMU gaps, GNSS showing motion);
- **truly still**: stationary and within ``floor_factor`` times the recording's *noise
  floor*, the 2 % quantile of the statistic over the whole recording (the quietest the sensor
  ever is: its own noise, or the vibration of a parked vehicle). A hand-held device standing
  "still" shows 0.2-0.6 m/s^2 of hand motion against a 0.01 m/s^2 sensor floor: stationary, not
  still; its sensor noise cannot be measured there.

Runs shorter than ``min_duration`` are dropped and every run is shortened by ``margin`` at
both ends (the centred window overhangs the motion by half its length).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np
import pandas as pd

from .aot import entry
from .errors import ConfigError
from .imu import ACCEL_COLS, DTHETA_COLS, DV_COLS, GYRO_COLS, is_increment_table
from .jit import njit
from .validate import time_slice

METHODS = ("shoe", "amv", "are", "mag", "adaptive", "valley")
#: methods built on the SHOE statistic
SHOE_METHODS = ("shoe", "adaptive", "valley")
G_STANDARD = 9.80665


def next_fast_len(target: int) -> int:
    """Smallest length ``>= target`` whose prime factors are 2, 3, 5, 7 and 11 (fast for
    numpy's pocketfft; ``scipy.fft.next_fast_len``, without importing scipy)."""
    n = max(int(target), 1)
    while True:
        m = n
        for f in (2, 3, 5, 7, 11):
            while m % f == 0:
                m //= f
        if m == 1:
            return n
        n += 1


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


@entry
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


#: output samples per block of :func:`amv_statistic` (the window sums are recomputed from the
#: samples at the start of each block)
AMV_BLOCK = 256


@entry
@njit(cache=True)
def amv_statistic(acc, window):
    """Standard deviation of the specific-force vector over the window [m/s^2].

    Sliding sums, O(N) instead of O(N * window): per block of :data:`AMV_BLOCK` output
    samples the sums of ``x - c`` and ``(x - c)^2`` over the window are computed afresh
    about a shift ``c``, the mean of the block's first window (no cancellation of the gravity
    offset in ``E[x^2] - E[x]^2``: about the shift both terms are of the size of the
    variation, whatever one sample holds), then
    updated by the samples entering and leaving the window; the rounding of the updates
    stays within one block. Equal to the two-pass value within 1e-12 relative.
    """
    n = acc.shape[0]
    out = np.empty(n)
    half_lo = (window - 1) // 2
    half_hi = window - 1 - half_lo
    s1 = np.zeros(3)
    s2 = np.zeros(3)
    c = np.zeros(3)
    cur_lo = 0
    cur_hi = 0
    for k in range(n):
        lo, hi = _window_bounds(k, n, half_lo, half_hi)
        if k % AMV_BLOCK == 0:  # fresh sums about the block's shift
            for i in range(3):
                c[i] = 0.0
                s1[i] = 0.0
                s2[i] = 0.0
            for j in range(lo, hi):
                for i in range(3):
                    c[i] += acc[j, i]
            for i in range(3):
                c[i] /= hi - lo
            for j in range(lo, hi):
                for i in range(3):
                    d = acc[j, i] - c[i]
                    s1[i] += d
                    s2[i] += d * d
            cur_lo, cur_hi = lo, hi
        while cur_hi < hi:
            for i in range(3):
                d = acc[cur_hi, i] - c[i]
                s1[i] += d
                s2[i] += d * d
            cur_hi += 1
        while cur_lo < lo:
            for i in range(3):
                d = acc[cur_lo, i] - c[i]
                s1[i] -= d
                s2[i] -= d * d
            cur_lo += 1
        m = hi - lo
        v = 0.0
        for i in range(3):
            mi = s1[i] / m
            v += s2[i] / m - mi * mi
        out[k] = np.sqrt(v) if v > 0.0 else 0.0
    return out


@entry
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


@entry
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


@njit(cache=True)
def _quantile_sorted(buf, m, q):
    """Linear-interpolated ``q``-quantile of the first ``m`` (sorted) entries of ``buf``."""
    pos = q * (m - 1)
    i = int(np.floor(pos))
    if i >= m - 1:
        return buf[m - 1]
    f = pos - i
    return buf[i] + f * (buf[i + 1] - buf[i])


@njit(cache=True)
def _top2_of_smallest(x, lo, hi, k, sign, cap, hp):
    """The largest and the second largest of the ``k`` (>= 2) smallest values of ``sign * x``
    over the finite entries of ``x[lo:hi]`` that are ``<= cap`` (at least ``k``; then they hold
    the ``k`` smallest of all): a max-heap of ``k`` entries in the scratch ``hp`` over one pass,
    ``O(m log k)``, with few sift-downs when ``k << m`` and ``cap`` is near the ``k``-th value."""
    a = lo
    nh = 0
    while nh < k:  # heapify the first k finite values (sift up)
        v = sign * x[a]
        a += 1
        if not (np.isfinite(v) and v <= cap):
            continue
        c = nh
        while c > 0:
            par = (c - 1) // 2
            if hp[par] >= v:
                break
            hp[c] = hp[par]
            c = par
        hp[c] = v
        nh += 1
    for b in range(a, hi):
        v = sign * x[b]
        if not v < hp[0] or v == -np.inf:  # NaN and +-inf are not finite values
            continue
        c = 0  # replace the root, sift down
        while True:
            ch = 2 * c + 1
            if ch >= k:
                break
            if ch + 1 < k and hp[ch + 1] > hp[ch]:
                ch += 1
            if hp[ch] <= v:
                break
            hp[c] = hp[ch]
            c = ch
        hp[c] = v
    second = hp[1]
    if k > 2 and hp[2] > second:
        second = hp[2]
    return hp[0], second


@njit(cache=True)
def _quantile_select(x, lo, hi, m, q, hp, guess=np.inf):
    """:func:`_quantile_sorted` of the ``m`` finite entries of ``x[lo:hi]`` by selection: the
    two order statistics ``i``, ``i + 1`` it needs (``i = floor(q (m - 1))``) from a heap of the
    ``i + 2`` smallest (or the ``m - i`` largest) values, in one pass without a copy or a sort;
    ``hp``: scratch of ``m`` entries. ``guess``: a value expected just above the quantile (the
    previous window's order statistic ``i + 1``): when at least ``i + 2`` values are ``<=
    guess`` only those enter the heap (the result does not depend on it). Returns the quantile
    and the order statistic ``i + 1`` (inf where there is none)."""
    pos = q * (m - 1)
    i = int(np.floor(pos))
    if i >= m - 1:
        v = -np.inf
        for b in range(lo, hi):
            if np.isfinite(x[b]) and x[b] > v:
                v = x[b]
        return v, np.inf
    if i + 2 <= m - i:  # order statistics i + 1, i: the top two of the i + 2 smallest
        cap = np.inf
        if guess < np.inf:
            c = 0
            for b in range(lo, hi):
                if x[b] <= guess and x[b] > -np.inf:  # finite (guess is)
                    c += 1
            if c >= i + 2:
                cap = guess
        vhi, vlo = _top2_of_smallest(x, lo, hi, i + 2, 1.0, cap, hp)
    else:  # order statistics i, i + 1: the bottom two of the m - i largest
        vlo, vhi = _top2_of_smallest(x, lo, hi, m - i, -1.0, np.inf, hp)
        vlo, vhi = -vlo, -vhi
    return vlo + (pos - i) * (vhi - vlo), vhi


@entry
@njit(cache=True)
def running_quantile(x, half, q, step):
    """``q``-quantile of the finite values of ``x`` over ``[k - half, k + half]``.

    Evaluated exactly at every ``step``-th sample (and the last) and interpolated linearly in
    between (the level it is used for varies over a stride, not a sample); NaN where the window
    holds no finite value. Cost ``O(N / step * W)``: one selection pass per node
    (:func:`_quantile_select`), the finite count of each window from a running count.
    """
    n = x.shape[0]
    out = np.empty(n)
    hp = np.empty(2 * half + 1)
    cnt = np.empty(n + 1, np.int64)  # finite values in x[:k]
    cnt[0] = 0
    for i in range(n):
        cnt[i + 1] = cnt[i] + (1 if np.isfinite(x[i]) else 0)
    nodes = np.arange(0, n, max(step, 1))
    if nodes[-1] != n - 1:
        nodes = np.append(nodes, n - 1)
    val = np.empty(nodes.size)
    guess = np.inf  # the previous node's order statistic i + 1 (_quantile_select)
    for j in range(nodes.size):
        k = nodes[j]
        lo, hi = max(0, k - half), min(n, k + half + 1)
        m = cnt[hi] - cnt[lo]
        if m == 0:
            val[j] = np.nan
        else:
            val[j], guess = _quantile_select(x, lo, hi, m, q, hp, guess)
    for j in range(nodes.size - 1):
        a, b = nodes[j], nodes[j + 1]
        va, vb = val[j], val[j + 1]
        for k in range(a, b):
            if np.isnan(va) or np.isnan(vb):
                out[k] = va if k - a < b - k else vb
            else:
                out[k] = va + (vb - va) * (k - a) / (b - a)
    out[n - 1] = val[nodes.size - 1]
    return out


def gait_period(stat: np.ndarray, dt: float, shortest: float = 0.4, longest: float = 3.0,
                min_correlation: float = 0.2) -> float:
    """Gait-cycle (stride) period [s] of a recording from the autocorrelation of ``log T``.

    The highest local maximum of the normalised autocorrelation at lags in ``[shortest,
    longest]`` seconds (human strides: 0.6-0.8 s running, 1.0-1.6 s walking; the 28 PyShoe
    trials show 0.31-0.83 at their period); NaN when none reaches ``min_correlation`` (no
    gait: standing, motions without rhythm; white noise gives about ``1/sqrt(N)``).
    """
    x = np.log(np.maximum(np.asarray(stat, float), 1e-300))
    n = x.size
    a, b = int(round(shortest / dt)), min(int(round(longest / dt)), n - 2)
    if n < 4 or b - a < 3:
        return float("nan")
    x = x - x.mean()
    # linear (not circular) autocorrelation at the lags <= b: a circular one of length >= n + b
    # has no wrapped products there (x[i] x[i + k - L] needs i >= L - k >= n)
    nfft = next_fast_len(n + b + 1)
    f = np.fft.rfft(x, nfft)
    ac = np.fft.irfft(f * np.conj(f), nfft)[:b + 1]
    if not ac[0] > 0:
        return float("nan")
    seg = ac[a:b + 1] / ac[0]
    pk = np.flatnonzero((seg[1:-1] > seg[:-2]) & (seg[1:-1] >= seg[2:])) + 1
    pk = pk[seg[pk] >= min_correlation]
    if pk.size == 0:
        return float("nan")
    return float((a + pk[np.argmax(seg[pk])]) * dt)


def valley_level(stat: np.ndarray, dt: float, config: DetectorConfig) -> np.ndarray:
    """Stance-valley level ``v_k`` of the ``valley`` method (module docstring): the
    ``valley_quantile`` of the statistic over ``valley_strides`` gait periods (``adapt_window``
    seconds when no gait period is found), standing runs (below ``threshold`` for at least
    ``quiet_duration``) left out; ``inf`` where the window holds only standing."""
    stat = np.require(stat, float, ["C", "W"])
    period = gait_period(stat, dt)
    length = config.valley_strides * period if np.isfinite(period) else config.adapt_window
    half = sample_count(0.5 * length, dt)
    quiet = quiet_runs(stat, float(config.threshold), sample_count(config.quiet_duration, dt))
    logs = np.where(quiet, np.nan, np.log(np.maximum(stat, 1e-300)))
    v = running_quantile(logs, half, float(config.valley_quantile), max(1, half // 8))
    return np.where(np.isnan(v), np.inf, np.exp(v))


# --- compiled decision logic -----------------------------------------------------------------
@entry
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


@entry
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


@entry
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
    method : {"shoe", "amv", "are", "mag", "adaptive", "valley"}
    window : float
        Window length [s] (rounded to an odd-or-even sample count, at least 1).
    threshold : float
        ``shoe``/``adaptive``/``valley``: dimensionless GLRT threshold ``gamma`` (the floor
        ``gamma_lo`` for adaptive and valley, and the level below which a run is standing);
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
        ``adaptive``: length ``2h`` of the window of the valley and peak levels [s];
        ``valley``: the window length when the recording shows no gait period.
    adapt_factor, adapt_peak_ratio, adapt_gait_peak : float
        ``adaptive``: ``factor``, ``peak_ratio`` and ``gait_peak`` of the module docstring;
        ``valley``: ``adapt_factor`` is its ``factor``.
    quiet_duration : float
        ``adaptive``/``valley``: runs below ``threshold`` at least this long [s] are standing
        and are left out of the valley level.
    valley_quantile : float
        ``valley``: quantile of the statistic that is the valley level (0 < q < 1).
    valley_strides : float
        ``valley``: window length in gait periods (estimated from the recording).
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
    valley_quantile: float = 0.05
    valley_strides: float = 2.0

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
        if not 0.0 < self.valley_quantile < 1.0:
            raise ConfigError("valley_quantile must lie in (0, 1)", column="valley_quantile",
                              found=self.valley_quantile)
        if not self.valley_strides > 0.0:
            raise ConfigError("valley_strides must be positive", column="valley_strides",
                              found=self.valley_strides)

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
    samples halves the variance of white noise.
    """
    t = np.asarray(imu.index, dtype=float)
    if is_increment_table(imu):
        dt = np.diff(t)
        w = np.empty((t.size, 3))
        a = np.empty((t.size, 3))
        # into the results: no (N, 3) temporary per triad
        np.divide(imu[DTHETA_COLS].to_numpy(float)[1:], dt[:, None], out=w[1:])
        np.divide(imu[DV_COLS].to_numpy(float)[1:], dt[:, None], out=a[1:])
        w[0], a[0] = w[min(1, t.size - 1)], a[min(1, t.size - 1)]
        return t, w, a
    return t, imu[GYRO_COLS].to_numpy(float), imu[ACCEL_COLS].to_numpy(float)


def regular_samples(t: np.ndarray, tolerance: float = 0.5) -> np.ndarray:
    """True for the samples whose preceding interval is within ``tolerance`` (fraction) of
    the median interval (sample 0 follows sample 1).

    A sample that ends a bridged gap is no measure of noise: an increment table's row after a
    missing sample holds the increment of one interval divided here by two (``g / 2`` of
    apparent specific-force error), and a rate sample after a gap is not the neighbour of the
    one before it. One such sample in a 25 s static window raised the measured VRW from 0.042
    to 0.54 m/s/sqrt(h): noise estimates and thresholds taken from still windows
    use only regular samples.
    """
    t = np.asarray(t, float)
    ok = np.ones(t.size, bool)
    if t.size < 3:
        return ok
    d = np.diff(t)
    nominal = float(np.median(d))
    ok[1:] = np.abs(d - nominal) <= tolerance * nominal
    ok[0] = ok[1]
    return ok


def estimate_gravity(gyro: np.ndarray, acc: np.ndarray, window: int) -> float:
    """Median specific-force magnitude over the 20 % of windows with the least rotation."""
    rate = are_statistic(gyro, max(window, 1))
    k = max(1, int(0.2 * rate.size))
    idx = np.argpartition(rate, k - 1)[:k]
    return float(np.median(np.linalg.norm(acc[idx], axis=1)))


def in_intervals(t: np.ndarray, intervals, pad: float = 0.0) -> np.ndarray:
    """Samples of the increasing times ``t`` inside any closed interval ``[a - pad, b + pad]``
    of ``intervals`` (pairs ``(a, b)``), by binary search: one pass whatever their number."""
    t = np.asarray(t, float)
    edges = np.zeros(t.size + 1, np.int64)
    iv = np.asarray(list(intervals), float).reshape(-1, 2)
    if iv.size:
        np.add.at(edges, np.searchsorted(t, iv[:, 0] - pad, side="left"), 1)
        np.add.at(edges, np.searchsorted(t, iv[:, 1] + pad, side="right"), -1)
    return np.cumsum(edges[:-1]) > 0


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
    if g is None and m in SHOE_METHODS + ("mag",):
        g = estimate_gravity(gyro, acc, w)
    if m in SHOE_METHODS:
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
    elif m == "valley":
        v = valley_level(stat, dt, config)
        thr = np.where(np.isfinite(v), config.adapt_factor * v, float(config.threshold))
        thr = np.minimum(thr, float(config.threshold_max))
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


# --- per-recording threshold selection ------------------------------------------------------
#: candidate fixed SHOE thresholds ``10^g`` (log10 start, stop, step; pyshoe's sigmas put
#: standing near 1e4-1e5, walking stance valleys near 1e5-1e6, running ones near 1e7-1e8)
SELECTION_FIXED = (5.5, 9.5, 0.25)
#: candidate valley factors ``10^c`` (log10 start, stop, step)
SELECTION_RELATIVE = (0.25, 3.0, 0.25)


def _log_grid(spec) -> np.ndarray:
    lo, hi, step = (float(x) for x in spec)
    if not (np.isfinite(lo) and np.isfinite(hi) and step > 0 and hi >= lo):
        raise ConfigError("a candidate grid is (log10 start, stop, step) with stop >= start "
                          "and step > 0", found=spec)
    return np.arange(lo, hi + 1e-9 * max(1.0, abs(hi)), step)


def threshold_candidates(t, stat, config: DetectorConfig, fixed=SELECTION_FIXED,
                         relative=SELECTION_RELATIVE) -> list[tuple[str, float, np.ndarray]]:
    """Candidate thresholds of the per-recording selection (module docstring).

    Parameters
    ----------
    t, stat : array
        Sample times [s] and the SHOE statistic of the recording.
    config : DetectorConfig
        Valley settings (``valley_quantile``, ``valley_strides``, ``adapt_window``,
        ``threshold``, ``quiet_duration``).
    fixed, relative : (start, stop, step) or None
        log10 grids of the fixed thresholds and of the valley factors (None: family left out).

    Returns
    -------
    list of (family, log10 value, threshold array)
        ``("fixed", g, 10^g)`` and ``("valley", c, 10^c v_k)`` (``threshold`` where ``v_k`` is
        undefined).
    """
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    out = []
    if fixed is not None:
        out += [("fixed", float(g), np.full(t.size, 10.0**g)) for g in _log_grid(fixed)]
    if relative is not None:
        v = valley_level(stat, dt, config)
        ok = np.isfinite(v)
        out += [("valley", float(c), np.where(ok, 10.0**c * v, float(config.threshold)))
                for c in _log_grid(relative)]
    return out


def stance_entry_rms(innovations: np.ndarray, still: np.ndarray, min_stances: int = 3) -> float:
    """RMS norm of the ZUPT innovation at the first sample of each stance (module docstring).

    Parameters
    ----------
    innovations : (N, 3) array
        ZUPT velocity innovations per sample [m/s], NaN where no update was applied.
    still : (N,) bool array
        The stance samples the filter used.
    min_stances : int
        Fewer stances (after the first, which starts the record) give ``inf``.
    """
    nu = np.asarray(innovations, float)
    s = np.asarray(still, bool)
    starts = np.flatnonzero(np.diff(s.astype(np.int8)) == 1) + 1  # runs not starting at 0
    starts = starts[np.isfinite(nu[starts, 0])] if starts.size else starts
    if starts.size < max(1, int(min_stances)):
        return float("inf")
    return float(np.sqrt(np.mean(np.sum(nu[starts] ** 2, axis=1))))


@dataclass
class ThresholdSelection:
    """Outcome of :func:`select_threshold`: the chosen candidate, its decisions and threshold,
    and one row per candidate (``family``, ``log10``, ``criterion`` [m/s], ``stances``)."""

    family: str
    log10: float
    criterion: float
    still: np.ndarray
    threshold: np.ndarray
    table: pd.DataFrame


def select_threshold(t, stat, config: DetectorConfig, forward, fixed=SELECTION_FIXED,
                     relative=SELECTION_RELATIVE, min_stances: int = 3) -> ThresholdSelection:
    """Choose the stance threshold of one recording by the stance-entry innovation criterion.

    Parameters
    ----------
    t, stat : array
        Sample times [s] and the SHOE statistic.
    config : DetectorConfig
        Decision post-processing (hysteresis, minimum stance, margin) and valley settings.
    forward : callable
        ``forward(still) -> (N, 3)`` ZUPT innovations of a forward ZUPT filter run on the
        still mask ``still`` (NaN where none), supplied by the navigation layer.
    fixed, relative, min_stances
        See :func:`threshold_candidates` and :func:`stance_entry_rms`.

    Returns
    -------
    ThresholdSelection
        The candidate with the smallest criterion (the first of equals); when no candidate
        yields ``min_stances`` stances the one with the most stances.
    """
    t = np.asarray(t, float)
    rows = []
    best = None
    seen: dict[bytes, float] = {}  # candidates that give the same decisions: one filter run
    for family, value, thr in threshold_candidates(t, stat, config, fixed, relative):
        still = decide(t, stat, thr, config)
        n_st = int(np.count_nonzero(np.diff(np.concatenate([[0], still.astype(np.int8)])) == 1))
        key_still = np.packbits(still).tobytes()
        j = seen.get(key_still)
        if j is None:
            j = stance_entry_rms(forward(still), still, min_stances) if still.any() else np.inf
            seen[key_still] = j
        rows.append({"family": family, "log10": value, "criterion": j, "stances": n_st})
        key = (j, -n_st)
        if best is None or key < best[0]:
            best = (key, family, value, j, still, thr)
    if best is None:
        raise ConfigError("no candidate thresholds", column="selection", found=(fixed, relative))
    _, family, value, j, still, thr = best
    return ThresholdSelection(family, value, j, still, thr, pd.DataFrame(rows))


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


# --- static windows found in the data ----------------------------------------------------------
#: quantile of the windowed statistic that is the recording's noise floor
FLOOR_QUANTILE = 0.02


@dataclass
class StaticWindows:
    """Stationary and truly still periods of a recording (:func:`find_static_windows`).

    Attributes
    ----------
    stationary, still : list of (t_start, t_end)
        Periods below the platform's stillness limits, and the truly still ones among them.
    accel_floor, rate_floor : float
        Noise floor of the specific-force [m/s^2] and angular-rate [rad/s] statistics.
    accel_std, rate_std : pandas Series
        The windowed statistics (standard deviation of the vector over the window).
    """

    stationary: list
    still: list
    accel_floor: float
    rate_floor: float
    accel_std: pd.Series
    rate_std: pd.Series

    def motion(self, t0: float, t1: float) -> tuple[float, float]:
        """Median specific-force and angular-rate variation [m/s^2, rad/s] over [t0, t1]."""
        a = time_slice(self.accel_std, t0, t1).to_numpy()
        w = time_slice(self.rate_std, t0, t1).to_numpy()
        return (float(np.median(a)) if a.size else np.nan,
                float(np.median(w)) if w.size else np.nan)

    def initial(self, t0: float, tolerance: float) -> tuple[tuple | None, tuple | None]:
        """The stationary and the truly still period that start within ``tolerance`` seconds of
        ``t0`` (None where there is none)."""
        def first(runs):
            return next(((a, b) for a, b in runs if a <= t0 + tolerance and b > t0), None)

        return first(self.stationary), first(self.still)


def _runs(flags: np.ndarray, t: np.ndarray) -> list[tuple[float, float]]:
    d = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True)]


def find_static_windows(imu: pd.DataFrame, *, max_accel_std: float, max_rate_std: float,
                        window: float = 0.5, floor_factor: float = 5.0,
                        min_duration: float = 1.0, margin: float = 0.25,
                        exclude=()) -> StaticWindows:
    """Stationary and truly still periods of an IMU recording (module docstring, "Static
    windows found in the data").

    Parameters
    ----------
    imu : DataFrame
        IMU table (rates or increments) indexed by time [s].
    max_accel_std, max_rate_std : float
        Stillness limits of the platform [m/s^2], [rad/s] (vibration, tremor).
    window : float
        Length of the statistic's window [s].
    floor_factor : float
        A truly still sample is within this factor of the noise floor.
    min_duration, margin : float
        Shortest period kept; shortening at both ends [s].
    exclude : sequence of (t0, t1)
        Intervals that are never static (bridged gaps, GNSS showing motion).
    """
    t, gyro, acc = imu_rates(imu)
    if t.size < 3:
        empty = pd.Series(np.zeros(t.size), pd.Index(t, name="time"))
        return StaticWindows([], [], np.nan, np.nan, empty, empty)
    dt = float(np.median(np.diff(t)))
    w = sample_count(window, dt)
    sa = amv_statistic(np.require(acc, float, ["C", "W"]), w)
    sw = amv_statistic(np.require(gyro, float, ["C", "W"]), w)
    del gyro, acc  # the rate arrays (48 bytes per sample) before the statistics' temporaries
    fa, fw = float(np.quantile(sa, FLOOR_QUANTILE)), float(np.quantile(sw, FLOOR_QUANTILE))
    # a sample whose window reaches into an excluded interval
    ok = ~in_intervals(t, exclude, pad=0.5 * window)
    stationary = ok & (sa <= max_accel_std) & (sw <= max_rate_std)
    still = stationary & (sa <= floor_factor * fa) & (sw <= floor_factor * fw)
    n_min, n_margin = sample_count(min_duration, dt), sample_count(margin, dt)
    runs = []
    for flags in (stationary, still):
        flags = shrink_runs(drop_short_runs(flags, n_min), n_margin)
        runs.append(_runs(drop_short_runs(flags, max(n_min - 2 * n_margin, 1)), t))
    idx = pd.Index(t, name="time")
    return StaticWindows(runs[0], runs[1], fa, fw, pd.Series(sa, idx, name="accel_std"),
                         pd.Series(sw, idx, name="rate_std"))
