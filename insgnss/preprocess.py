"""Data-driven preprocessing: IMU-GNSS time offset, GNSS velocity time tags, white-noise
levels from a static window.

Time offset
-----------
A logging delay between the IMU and GNSS clocks biases every update (at 16 m/s, 0.1 s is
1.6 m along track). For a land vehicle the yaw rate is seen by both sensors: the GNSS course over
ground ``psi = atan2(v_e, v_n)`` (velocity by central differences of the *positions*, which are
time-tagged at the measurement epoch, unlike velocities that some receivers derive by backward
differences) and the vertical gyro (``-w_z`` in the right-forward-up body frame, clockwise
positive like the course). :func:`estimate_time_offset` finds the shift ``dt`` of the IMU time
stamps that minimises the RMS difference between the GNSS course rate and the gyro yaw rate
averaged over the same span, using only GNSS epochs above ``min_speed`` and outside outage
windows (so it never uses withheld data), refined to sub-sample precision by a parabola through
the three best shifts. Corrected IMU time = IMU time + ``dt``. A best shift whose RMS is within
:data:`TIME_TAG_EVIDENCE` (5 %) of the RMS at zero shift is no evidence of an offset (noisy
positions make the course rate noise): the estimate is then 0 (``info["applied"]`` false).
An increment (the mean rate over ``(t[k-1], t[k]]``) is compared at its interval's midpoint,
a rate sample at its stamp (before: an increment table's offset came out about half an IMU
interval early).

The offset may drift: a logger that stamps the IMU samples by counting them at the nominal rate
(or scales the IMU's counter onto a time-tag span) runs at the IMU oscillator's rate error
against GPS time; the rtklibexplorer drive drifts by -0.33 ms/s (-0.15 s over its 8 minutes,
the offsets of its 100 s stretches fall from -0.006 to -0.126 s). :func:`estimate_time_correction`
(the job's estimate, ``inputs.imu.estimate_time_drift``) fits ``offset + drift (t - t_ref)``
to the offsets of the log's stretches when their t-statistic shows one
(:class:`TimeCorrection`); the stretches' agreement is also the evidence of a constant offset
on RTK-quality logs, where a real offset can gain less than the 5 % RMS margin.

GNSS position outliers (a float solution jumping tens of metres) make the central-difference
course rate absurd at the neighbouring epochs; they are excluded before the fit: epochs whose
rate residual (at zero shift, then again at the first estimate) is farther than
``max(5 * 1.4826 * MAD, 5 deg/s)`` from the median residual do not take part
(``info["outliers"]`` counts them).

GNSS velocity time tags
-----------------------
Receivers and RTK engines that difference positions report, at epoch ``t_k``, the mean
velocity over ``[t_{k-1}, t_k]``: the velocity of ``t_k - dt/2``, half an epoch behind its tag
(the rtklibexplorer drive and walk both show it). Used at its tag, it lags the truth by
``a dt / 2`` (0.125 s at 4 Hz). :func:`estimate_velocity_lag` finds the lag from the data: the
positions' central differences ``(p_{k+1} - p_k) / (t_{k+1} - t_k)`` are velocities at the
interval midpoints; the lag is the shift of the reported velocities (interpolated) that
minimises their RMS difference, over shifts within one epoch interval, refined by a parabola
through the three best. Only epochs outside the outage windows and intervals without gaps take
part, and position outliers are left out (the pairs whose velocity difference at zero shift is
farther than ``max(5 * 1.4826 * MAD, 0.5 m/s)`` from the median). The velocities then belong to
``tag - lag``.

Noise from a static window
--------------------------
``ARW = std(w) sqrt(dt)``, ``VRW = std(f) sqrt(dt)`` per axis (largest axis), the white-noise
densities the filter needs. ``w`` and ``f`` are the samples as recorded
(:func:`insgnss.detect.imu_rates`: rates as they are, increments divided by their interval),
never the trapezoidal increments of the mechanization, whose averaging of neighbours would halve
the variance of white noise. On a vehicle with the engine running this captures the
vibration, which datasheet values do not. Samples that end a bridged gap are left out
(:func:`insgnss.detect.regular_samples`): their interval is not the nominal one.

Vibration in quiet windows
--------------------------
A parked car with the engine idling shakes its IMU well above the datasheet noise. What drives
the attitude and velocity errors is the noise density at the filter's time scale, not at the
sample rate (a vibration at 30 Hz of bounded amplitude integrates to nothing): from the
overlapping Allan variance at ``tau`` = :data:`VIBRATION_TAU` (1 s) of each axis in each quiet
window (the stationary periods of :func:`insgnss.detect.find_static_windows`: a vehicle
standing, or driving straight at a steady speed, which the statistic cannot tell apart),
``N^2 = tau AVAR(tau)`` (white noise: ``AVAR = N^2 / tau``; IEEE Std 952 annex C), averaged over
the three axes. :func:`vibration_noise` adds what exceeds the filter's own ``ARW^2`` / ``VRW^2``
as extra attitude and velocity process noise over that window (``FilterConfig.extra_noise``),
``(N^2 - ARW^2) dt`` per step: the filter keeps its datasheet noise while the vehicle moves and
takes the measured one while it stands. Windows shorter than :data:`VIBRATION_MIN_WINDOW` give
no estimate (fewer than 3 independent clusters at ``tau``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .detect import imu_rates, regular_samples
from .earth import geodetic_to_enu
from .errors import InvalidValueError
from .imu import ImuErrorModel, is_increment_table
from .outages import in_windows
from .stats import chi2_ppf
from .validate import check_time_overlap, time_slice

#: a time shift (IMU offset, velocity lag) is applied only when it lowers the RMS misfit by this
#: share against no shift (otherwise the data cannot tell: noisy or static data, correct tags)
TIME_TAG_EVIDENCE = 0.05
#: the stretches of a log whose offsets are the evidence of a time correction: at least this
#: many, and a t-statistic of the drift (or of the mean offset) against their scatter of at
#: least :data:`DRIFT_T_MIN` (:func:`estimate_time_correction`)
DRIFT_MIN_WINDOWS = 4
DRIFT_T_MIN = 5.0


#: values of the course-rate misfit evaluated at once (shifts x epochs): bounded memory
_MISFIT_BLOCK = 1 << 20


class _CourseRateMatch:
    """The GNSS course rate and the gyro yaw rate of a log, prepared once for the time-offset
    fits (:func:`estimate_time_offset`, :func:`estimate_time_correction`; module docstring)."""

    def __init__(self, imu: pd.DataFrame, gnss: pd.DataFrame, windows, min_speed: float,
                 search: float):
        check_time_overlap(imu, gnss)
        tg = gnss.index.to_numpy(float)
        e, n, _ = geodetic_to_enu(gnss["lat"].to_numpy(), gnss["lon"].to_numpy(),
                                  gnss["height"].to_numpy(), float(gnss["lat"].iloc[0]),
                                  float(gnss["lon"].iloc[0]), float(gnss["height"].iloc[0]))
        # central differences over neighbouring epochs; only where both neighbours are 'close'
        ve, vn = np.gradient(e, tg), np.gradient(n, tg)
        speed = np.hypot(ve, vn)
        course_rate = np.gradient(np.unwrap(np.arctan2(ve, vn)), tg)
        span = np.gradient(tg) * 2.0  # the time span the central difference covers
        gap_ok = np.r_[False, np.diff(tg) < 1.5 * np.median(np.diff(tg))]
        gap_ok &= np.r_[gap_ok[1:], False]
        ok = (speed > min_speed) & gap_ok & ~in_windows(tg, list(windows))
        t, w, _ = imu_rates(imu)
        ok &= (tg - span > t[0] + search) & (tg + span < t[-1] - search)
        if is_increment_table(imu):  # an increment is the mean rate of (t[k-1], t[k]]: its
            # midpoint is its time (rates are sampled at their stamps)
            t = t - 0.5 * np.diff(t, prepend=2.0 * t[0] - t[min(1, t.size - 1)])
        self.t = t
        self.t_mid = 0.5 * float(imu.index[0] + imu.index[-1])  # the log's middle (stamps)
        self.cs = np.concatenate([[0.0], np.cumsum(-w[:, 2])])  # yaw rate: -w_z (RFU body)
        self.tc, self.half, self.cr = tg[ok], 0.5 * span[ok], course_rate[ok]
        self.src = gnss.attrs.get("source")

    def check(self, sel, min_speed: float, search: float) -> None:
        """Raise :class:`InvalidValueError` when the epochs ``sel`` cannot tell an offset."""
        n = int(sel.sum())
        if n < 50:
            raise InvalidValueError(
                "too few moving GNSS epochs to estimate the IMU-GNSS time offset", file=self.src,
                expected=f">= 50 epochs faster than {min_speed:g} m/s inside the IMU span (less "
                         f"{search:g} s at each end), outside outages and gaps",
                found=f"{n} epochs")
        if np.std(self.cr[sel]) < np.radians(1.0):
            raise InvalidValueError(
                "too little turning motion to estimate the IMU-GNSS time offset", file=self.src,
                expected="a course-rate spread >= 1 deg/s over the moving epochs",
                found=f"{np.degrees(np.std(self.cr[sel])):.3g} deg/s over {n} epochs")

    def mean_rate(self, tt, half):
        a = np.searchsorted(self.t, tt - half)
        b = np.searchsorted(self.t, tt + half)
        return (self.cs[b] - self.cs[a]) / np.maximum(b - a, 1)

    def rms_misfit(self, tc, half, cr, shifts) -> np.ndarray:
        """RMS of the course rate ``cr`` at ``tc`` minus the yaw rate at ``tc - shift`` for
        each shift (every shift at once, in blocks of about :data:`_MISFIT_BLOCK` values)."""
        out = np.empty(len(shifts))
        step = max(1, _MISFIT_BLOCK // max(tc.size, 1))
        for i in range(0, len(shifts), step):
            s = np.asarray(shifts[i:i + step], float)[:, None]
            r = cr - self.mean_rate(tc - s, half)
            out[i:i + step] = np.sqrt(np.mean(r ** 2, axis=1))
        return out

    def fit(self, sel, shifts: np.ndarray, base=None) -> tuple[float, dict]:
        """The best of the constant ``shifts`` over the epochs ``sel`` (added to ``base``, a
        time-varying shift per epoch, when given), refined by a parabola through the three
        best; ``(dt, info)`` with the RMS misfit at the best shift and at a zero shift."""
        tc, half, cr = self.tc[sel], self.half[sel], self.cr[sel]
        b0 = np.zeros(tc.size) if base is None else base[sel]

        def inliers(shift):
            r = cr - self.mean_rate(tc - b0 - shift, half)
            d = np.abs(r - np.median(r))
            return d <= max(5.0 * 1.4826 * float(np.median(d)), np.radians(5.0))

        use = inliers(0.0)
        for _ in range(2):  # inliers at zero shift, then at the first estimate
            # IMU stamp t_imu holds the motion at t_imu + dt: GNSS at tc against IMU at tc - dt
            rms = self.rms_misfit(tc[use] - b0[use], half[use], cr[use], shifts)
            k = int(np.argmin(rms))
            use = inliers(float(shifts[k]))
        dt = float(shifts[k])
        if 0 < k < len(shifts) - 1:
            y0, y1, y2 = rms[k - 1], rms[k], rms[k + 1]
            den = y0 - 2 * y1 + y2
            if den > 0:
                dt += 0.5 * (shifts[1] - shifts[0]) * (y0 - y2) / den
        r0 = float(rms[np.argmin(np.abs(shifts))])
        return dt, {"epochs": int(sel.sum()), "outliers": int(sel.sum() - use.sum()),
                    "rms_rate_deg_s": float(np.degrees(rms[k])),
                    "rms_rate_at_zero_deg_s": float(np.degrees(r0)),
                    "at_search_edge": bool(k in (0, len(shifts) - 1)),
                    "evidence": bool(r0 - float(rms[k]) > TIME_TAG_EVIDENCE * float(rms[k]))}

    def fit_fine(self, sel, shifts: np.ndarray, step: float, base=None) -> tuple[float, dict]:
        """:meth:`fit` over ``shifts``, then again at a fifth of ``step`` within two steps of
        its best (the parabola through a coarse grid can move by a few milliseconds)."""
        d, info = self.fit(sel, shifts, base)
        if info["at_search_edge"]:
            return d, info
        fine = step / 5.0
        d2, info2 = self.fit(sel, d + np.arange(-2.0 * step, 2.0 * step + fine / 2, fine), base)
        info2["at_search_edge"] = False
        return d2, info2


def estimate_time_offset(imu: pd.DataFrame, gnss: pd.DataFrame, windows=(), *,
                         min_speed: float = 3.0, search: float = 0.5, step: float = 0.005
                         ) -> tuple[float, dict]:
    """Shift to add to the IMU time stamps so that the gyro yaw rate matches the GNSS course
    rate (see the module docstring). Returns ``(dt, info)``.

    Raises :class:`~insgnss.errors.TimeOrderError` when IMU and GNSS do not overlap in time
    (both spans printed), :class:`InvalidValueError` when too few GNSS epochs are moving or
    there is too little turning motion to tell.
    """
    m = _CourseRateMatch(imu, gnss, windows, min_speed, search)
    sel = np.ones(m.tc.size, bool)
    m.check(sel, min_speed, search)
    dt, info = m.fit(sel, np.arange(-search, search + step / 2, step))
    # noisy positions (a single-point fix at 1 Hz) make the course rate noise: a best shift
    # that hardly beats no shift is no evidence of an offset
    info["applied"] = info.pop("evidence")
    if not info["applied"]:
        info["reason"] = "no evidence of an offset"
        return 0.0, info
    return dt, info


@dataclass(frozen=True)
class TimeCorrection:
    """Correction of IMU time stamps: ``corrected = t + offset + drift (t - t_ref)`` [s, s, s/s].

    ``drift`` is the rate error of the IMU's time base against GNSS time (a logger that counts
    samples at a nominal rate, or scales its counter onto a time-tag span, drifts by the
    oscillator's tolerance: 300 ppm is 0.18 s in 10 minutes)."""

    offset: float = 0.0
    drift: float = 0.0
    t_ref: float = 0.0

    def __call__(self, t):
        return t + self.offset + self.drift * (np.asarray(t, float) - self.t_ref)

    def __bool__(self) -> bool:
        return bool(self.offset or self.drift)


def estimate_time_correction(imu: pd.DataFrame, gnss: pd.DataFrame, windows=(), *,
                             min_speed: float = 3.0, search: float = 0.5, step: float = 0.005,
                             drift: bool = True, drift_window: float = 100.0
                             ) -> tuple[TimeCorrection, dict]:
    """IMU time correction from the gyro yaw rate against the GNSS course rate: a constant
    offset and, with ``drift``, a linear drift of it (module docstring, "Time offset").

    The log is cut into ``drift_window``-long stretches (non-overlapping); the offset of each
    that can tell one (at least 50 moving epochs, a course-rate spread of 1 deg/s) is searched
    within ``search / 2`` of the whole-log offset. With at least :data:`DRIFT_MIN_WINDOWS` of
    them their offsets are the evidence: ``a + b (t - t_ref)`` by weighted least squares
    (weights: epochs; ``t_ref`` their weighted mean time); the drift ``b`` is applied (the
    correction's ``t_ref`` then the middle of the IMU log) when its
    t-statistic against the residual scatter reaches :data:`DRIFT_T_MIN`, it moves the offset
    by two search steps over the log and the pair, refitted over the whole log, fits it better
    than a constant; otherwise the whole-log constant offset is applied when the stretches'
    mean offset reaches the same t-statistic or the whole-log RMS margin
    (:data:`TIME_TAG_EVIDENCE`) holds. A shorter log has only the RMS margin
    (:func:`estimate_time_offset`). On RTK-quality positions the stretches agree to a few
    milliseconds while a constant offset may gain less than the margin in RMS: the margin was
    made for noisy single-point positions, whose stretches scatter. Returns
    ``(correction, info)``: ``info`` has the whole-log fit's keys, ``drift_windows`` (time,
    offset, epochs of each stretch), ``offset_t``, ``drift_t``, ``drift_ppm`` and
    ``drift_applied``. Raises as :func:`estimate_time_offset`.
    """
    m = _CourseRateMatch(imu, gnss, windows, min_speed, search)
    sel = np.ones(m.tc.size, bool)
    m.check(sel, min_speed, search)
    shifts = np.arange(-search, search + step / 2, step)
    dt, info = m.fit(sel, shifts)
    rms_margin = info.pop("evidence")
    info.update(applied=False, drift_applied=False, drift_ppm=0.0)
    rows = _stretch_offsets(m, dt, search, step, drift_window)
    info["drift_windows"] = [list(r) for r in rows]
    if len(rows) < DRIFT_MIN_WINDOWS:  # too short to tell by stretches: the RMS margin
        info["applied"] = rms_margin
        if not rms_margin:
            info["reason"] = "no evidence of an offset"
        return TimeCorrection(dt if rms_margin else 0.0), info
    tw, y, wt = (np.array(c, float) for c in zip(*rows, strict=True))
    wt = wt / wt.mean()
    t_ref = float(np.sum(wt * tw) / np.sum(wt))
    # the offset: the stretches' weighted mean against their scatter (t-statistic)
    mean = float(np.sum(wt * y) / np.sum(wt))
    s2c = max(float(np.sum(wt * (y - mean) ** 2)) / (tw.size - 1), (0.2 * step) ** 2)
    t_off = abs(mean) / np.sqrt(s2c / np.sum(wt))
    # the drift: a + b (t - t_ref) by weighted least squares (t_ref the weighted mean time:
    # intercept and slope uncorrelated)
    X = np.column_stack([np.ones(tw.size), tw - t_ref])
    A = X.T @ (wt[:, None] * X)
    beta = np.linalg.solve(A, X.T @ (wt * y))
    res = y - X @ beta
    s2 = max(float(np.sum(wt * res**2)) / (tw.size - 2), (0.2 * step) ** 2)
    b = float(beta[1])
    t_b = abs(b) / float(np.sqrt(s2 * np.linalg.inv(A)[1, 1]))
    change = abs(b) * float(m.tc[-1] - m.tc[0])
    info.update(offset_t=t_off, drift_t=t_b, drift_fit_ppm=b * 1e6,
                drift_residual_rms_s=float(np.sqrt(np.sum(wt * res**2) / np.sum(wt))))
    if drift and t_b >= DRIFT_T_MIN and change >= 2.0 * step:
        # the offset over the whole log with the drift applied, at the log's middle (a fixed
        # reference: the stretches' mean time moves with the epochs they keep): the pair must
        # fit the whole log better than the constant offset does
        off, inf = m.fit_fine(sel, shifts, step, base=b * (m.tc - m.t_mid))
        if inf["rms_rate_deg_s"] < info["rms_rate_deg_s"]:
            info.update(applied=True, drift_applied=True, drift_ppm=b * 1e6, t_ref=m.t_mid,
                        offset_at_t_ref=off, rms_rate_deg_s=inf["rms_rate_deg_s"])
            return TimeCorrection(off, b, m.t_mid), info
        info["drift_reason"] = "the drifting offset does not fit better than a constant one"
    elif drift:
        info["drift_reason"] = (f"no evidence of a drift (t = {t_b:.2g}, offset change "
                                f"{change:.3g} s over the log)")
    info["applied"] = bool(rms_margin or t_off >= DRIFT_T_MIN)
    if not info["applied"]:
        info["reason"] = f"no evidence of an offset (t = {t_off:.2g} over the stretches)"
    return TimeCorrection(dt if info["applied"] else 0.0), info


def _stretch_offsets(m: _CourseRateMatch, dt: float, search: float, step: float,
                     window: float) -> list[tuple[float, float, int]]:
    """``(mean time, offset, epochs)`` of each ``window``-long stretch of the log that can tell
    an offset (at least 50 moving epochs, a course-rate spread of 1 deg/s, a best shift inside
    the search range): searched at ``step`` within ``search / 2`` of the whole-log offset
    ``dt``, then refined to a fifth of the step."""
    rows = []
    local = dt + np.arange(-0.5 * search, 0.5 * search + step / 2, step)
    for a in np.arange(m.tc[0], m.tc[-1], window):
        s = (m.tc >= a) & (m.tc < a + window)
        if s.sum() < 50 or np.std(m.cr[s]) < np.radians(1.0):
            continue
        d, inf = m.fit_fine(s, local, step)
        if not inf["at_search_edge"]:
            rows.append((float(np.mean(m.tc[s])), d, int(s.sum())))
    return rows


def estimate_velocity_lag(gnss: pd.DataFrame, windows=(), *, steps: int = 50
                          ) -> tuple[float, dict]:
    """How far the GNSS velocity time tags lag the positions [s] (module docstring).

    Returns ``(lag, info)``; ``lag`` is 0 when the data shows no evidence of one
    (:data:`TIME_TAG_EVIDENCE`) or too few moving epochs. The velocities belong to
    ``tag - lag``.
    """
    tg = gnss.index.to_numpy(float)
    cols = ("vel_e", "vel_n", "vel_u")
    if tg.size < 20 or not all(c in gnss.columns for c in cols):
        return 0.0, {"epochs": int(tg.size), "applied": False, "reason": "too few epochs"}
    e, n, u = geodetic_to_enu(gnss["lat"].to_numpy(), gnss["lon"].to_numpy(),
                              gnss["height"].to_numpy(), float(gnss["lat"].iloc[0]),
                              float(gnss["lon"].iloc[0]), float(gnss["height"].iloc[0]))
    dt = np.diff(tg)
    dt_med = float(np.median(dt))
    pos = np.column_stack([e, n, u])
    vel = gnss[list(cols)].to_numpy(float)
    inside = in_windows(tg, list(windows))
    ok = (dt < 1.5 * dt_med) & ~inside[1:] & ~inside[:-1]
    ok &= np.all(np.isfinite(pos[1:]) & np.isfinite(pos[:-1]), axis=1)
    tm = 0.5 * (tg[1:] + tg[:-1])
    vm = np.diff(pos, axis=0) / dt[:, None]
    ok &= (tm - dt_med >= tg[0]) & (tm + dt_med <= tg[-1])
    good = np.all(np.isfinite(vel), axis=1) & ~inside
    if ok.sum() < 20 or good.sum() < 20:
        return 0.0, {"epochs": int(ok.sum()), "applied": False, "reason": "too few epochs"}
    shifts = np.linspace(-dt_med, dt_med, 2 * steps + 1)

    def resid(s, use):
        vi = np.column_stack([np.interp(tm[use] + s, tg[good], vel[good, k]) for k in range(3)])
        return np.linalg.norm(vm[use] - vi, axis=1)

    # position outliers (a float fix jumping) make their two differences absurd: only the
    # pairs within max(5 * 1.4826 * MAD, 0.5 m/s) of the median difference at zero shift
    r0 = resid(0.0, ok)
    dev = np.abs(r0 - np.median(r0))
    keep = dev <= max(5.0 * 1.4826 * float(np.median(dev)), 0.5)
    ok[np.flatnonzero(ok)[~keep]] = False

    def rms(s):
        return float(np.sqrt(np.mean(resid(s, ok) ** 2)))

    r = np.array([rms(s) for s in shifts])
    k = int(np.argmin(r))
    lag = float(shifts[k])
    if 0 < k < r.size - 1:
        den = r[k - 1] - 2 * r[k] + r[k + 1]
        if den > 0:
            lag += 0.5 * (shifts[1] - shifts[0]) * (r[k - 1] - r[k + 1]) / den
    r0 = float(r[steps])
    info = {"epochs": int(ok.sum()), "outliers": int((~keep).sum()), "lag_s": lag,
            "rms_at_lag_m_s": float(r[k]),
            "rms_at_zero_m_s": r0, "epoch_interval_s": dt_med}
    info["applied"] = bool(r0 - float(r[k]) > TIME_TAG_EVIDENCE * float(r[k]))
    if not info["applied"]:
        info["reason"] = "no evidence of a lag"
        return 0.0, info
    return lag, info


def static_noise(imu: pd.DataFrame) -> tuple[float, float]:
    """White-noise densities (ARW [rad/sqrt(s)], VRW [m/s/sqrt(s)]) from a static window
    (regular samples only: module docstring)."""
    t, w, f = imu_rates(imu)
    if t.size < 20:
        raise InvalidValueError("static window too short for a noise estimate", found=t.size)
    dt = float(np.median(np.diff(t)))
    ok = regular_samples(t)
    w, f = w[ok], f[ok]
    return float(np.max(np.std(w, axis=0)) * np.sqrt(dt)), \
        float(np.max(np.std(f, axis=0)) * np.sqrt(dt))


#: averaging time of the vibration noise density [s] (the filter's epoch interval)
VIBRATION_TAU = 1.0
#: shortest quiet window whose vibration is measured [s]
VIBRATION_MIN_WINDOW = 4.0
#: spacing of the extra-noise rows over a quiet window [s]
VIBRATION_STEP = 1.0


#: probability with which a measured density must exceed the model's to count as vibration
VIBRATION_SIGNIFICANCE = 0.99


def allan_edf_white(n: int, m: int) -> float:
    """Equivalent degrees of freedom of the overlapping Allan variance of white rate noise
    (white FM) from ``n`` samples at averaging factor ``m`` (NIST SP 1065, Table 5)."""
    if n <= 2 * m:
        return 0.0
    return (3.0 * (n - 1) / (2.0 * m) - 2.0 * (n - 2) / n) * 4.0 * m * m / (4.0 * m * m + 5.0)


def vibration_density(imu: pd.DataFrame, tau: float = VIBRATION_TAU
                      ) -> tuple[float, float, float]:
    """Gyro and accelerometer white-noise densities squared (``N^2 = tau AVAR(tau)``, mean of
    the three axes) [rad^2/s, (m/s)^2/s] of a quiet IMU window (module docstring), and the
    equivalent degrees of freedom of each mean (:func:`allan_edf_white`, three axes)."""
    from .analysis.allan import allan_deviation_series

    t, w, f = imu_rates(imu)
    ok = regular_samples(t)
    rate = 1.0 / float(np.median(np.diff(t)))
    out = []
    for x in (w[ok], f[ok]):
        adev = [allan_deviation_series(x[:, k], rate, np.array([tau]))[1] for k in range(3)]
        a = np.concatenate(adev)
        out.append(float(tau * np.mean(a ** 2)) if a.size == 3 else 0.0)
    edf = 3.0 * allan_edf_white(int(ok.sum()), max(int(round(tau * rate)), 1))
    return out[0], out[1], edf


def _significant_excess(q: float, q_model: float, edf: float) -> float:
    """``q - q_model`` when a window with ``edf`` degrees of freedom shows ``q`` above the
    model's white-noise level with probability :data:`VIBRATION_SIGNIFICANCE` (chi-square of
    the Allan variance estimate), else 0: an IMU that matches its model adds nothing."""
    if edf < 1.0 or q <= q_model:
        return 0.0
    if q <= q_model * chi2_ppf(VIBRATION_SIGNIFICANCE, edf) / edf:
        return 0.0
    return q - q_model


def vibration_noise(imu: pd.DataFrame, windows, model: ImuErrorModel, *,
                    tau: float = VIBRATION_TAU, step: float = VIBRATION_STEP,
                    min_window: float = VIBRATION_MIN_WINDOW) -> pd.DataFrame | None:
    """Extra process noise for the vibration of the quiet ``windows`` ((t0, t1) pairs [s]) of
    ``imu``: the measured densities (:func:`vibration_density`) above ``model``'s ARW and VRW,
    as rows of :attr:`insgnss.filter.engine.FilterConfig.extra_noise` every ``step`` seconds
    over each window (``att_std^2 = (N_g^2 - ARW^2) dt``, ``vel_std^2 = (N_a^2 - VRW^2) dt``).
    None when no window shows more than the model."""
    rows = []
    for a, b in windows:
        if b - a < min_window:
            continue
        qg, qa, edf = vibration_density(time_slice(imu, a, b), tau)
        xg = _significant_excess(qg, model.gyro_arw ** 2, edf)
        xa = _significant_excess(qa, model.accel_vrw ** 2, edf)
        if xg == 0.0 and xa == 0.0:
            continue
        n = max(int(np.ceil((b - a) / step)), 1)
        ts = np.linspace(a, b, n + 1)
        dt = np.diff(ts)
        rows += [(t1, np.sqrt(xa * d), np.sqrt(xg * d)) for t1, d in zip(ts[1:], dt, strict=True)]
    if not rows:
        return None
    r = np.asarray(rows)
    return pd.DataFrame({"pos_std": 0.0, "vel_std": r[:, 1], "att_std": r[:, 2]},
                        index=pd.Index(r[:, 0], name="time"))


def with_static_noise(model: ImuErrorModel, imu_static: pd.DataFrame) -> ImuErrorModel:
    """``model`` with its ARW/VRW raised to the levels measured in a static window."""
    arw, vrw = static_noise(imu_static)
    return model.scaled(gyro_arw=max(model.gyro_arw, arw), accel_vrw=max(model.accel_vrw, vrw))


def shift_time(df: pd.DataFrame, dt) -> pd.DataFrame:
    """Copy with ``dt`` added to the time index (attrs kept); ``dt`` a number [s] or a
    :class:`TimeCorrection` (the index mapped through it)."""
    if isinstance(dt, TimeCorrection):
        idx = pd.Index(dt(df.index.to_numpy(float)), name=df.index.name)
    else:
        idx = df.index + dt
    out = df.set_axis(idx, axis=0)
    out.attrs = dict(df.attrs)
    return out
