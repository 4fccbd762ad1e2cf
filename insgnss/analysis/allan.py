"""Allan variance analysis of a static IMU log and extraction of the noise coefficients.

Allan deviation
---------------
The overlapping Allan deviation of each axis is computed from the
"phase" of the axis, i.e. the accumulated angle or velocity ``x_k = sum_{j<=k} (y_j - mean(y)) dt``::

    sigma^2(m tau0) = 1 / (2 (m tau0)^2 (N - 2m)) sum_n (x_{n+2m} - 2 x_{n+m} + x_n)^2

(NIST SP 1065 eq. 11), evaluated directly: one vectorised second difference of the phase per
averaging factor ``m`` (O(N) per tau). ``allantools.oadev`` computes the same estimator; it is not
a runtime dependency because its current releases pull pytest, numpydoc and matplotlib into a
user's install, and a test checks that both agree to rounding. The tau grid is log-spaced
(averaging factors, ~``points_per_decade`` per decade, up to ``max_fraction`` of the record);
the phase is formed as follows:

- **rate tables** (``gyro_*``, ``accel_*``): each sample is taken as the sensor's average rate over
  its interval (what the sensor's own filter/decimation delivers), so the phase is the cumulative
  sum of ``rate x dt`` of the samples *as recorded*. The trapezoidal increments the mechanization
  uses (:func:`insgnss.imu.increments`, each the mean of two neighbouring samples) must not be
  used here: averaging neighbours low-passes white noise, halving its variance at one sample and
  correlating neighbours (for white noise ADEV 50 % low at ``tau = tau0``, 21 % at ``2 tau0``,
  10 % at ``4 tau0``), exactly where ARW/VRW are read;
- **increment tables** (``dtheta_*``, ``dv_*``): their cumulative sum *is* the phase; row 0 (the
  unknown interval before the first sample) is dropped.

Coefficients (IEEE Std 952-1997 annex C; El-Sheimy, Hou & Niu 2008)
-------------------------------------------------------------------
With the local log-log slope ``s(tau) = d log sigma / d log tau``:

- **quantisation noise** ``Q`` (``sigma^2 = 3 Q^2 / tau^2``, slope -1): on the first run of the
  curve (shortest taus) whose slope is ``-1 +- 2 slope_tol``, a line of fixed slope -1 is fitted,
  ``Q = mean(sigma tau) / sqrt(3)`` [rad, m/s]. An angle (velocity) quantum ``q`` gives
  ``Q = q / sqrt(12)``; :func:`coefficients_table` also gives the quantum expressed as a rate over
  one sample, ``sqrt(12) Q / tau0`` (deg/s, mg), to compare with a datasheet LSB;
- **white noise** (angle / velocity random walk) ``N``: on the part of the curve left of the
  minimum whose slope is ``-1/2 +- slope_tol``, a line of fixed slope -1/2 is fitted in log-log
  (mean of ``log sigma + 1/2 log tau``); ``N`` is its value at ``tau = 1 s``
  [rad/sqrt(s) = rad/s/sqrt(Hz), m/s/sqrt(s)]. Where a quantisation region was found, the fit
  ignores it: only taus beyond it take part, and its term ``3 Q^2 / tau^2`` is removed from
  ``sigma^2`` before the slope test and the fit;
- **bias instability** ``B``: the flicker floor ``sigma = sqrt(2 ln 2 / pi) B = 0.664 B`` around
  the minimum. ``bias_instability_min`` is the classic reading ``sigma_min / 0.664``.
  ``bias_instability`` refines it: over the *flat region* (the contiguous taus around the
  minimum with ``sigma <= flat_factor * sigma_min``) the white-noise and rate-random-walk
  contributions already fitted are removed, ``C_i = sigma_i^2 - N^2 / tau_i - K^2 tau_i / 3``, and
  ``B = sqrt(mean_w(C_i)) / 0.664`` with weights proportional to the number of clusters
  ``T / tau_i``. When the floor is flat the two agree; near the noisy long-tau end of a record,
  where the minimum of a few noisy points is biased low and the white noise has not yet died
  out, the refined value is markedly more accurate (see ``tests/test_allan.py``);
- **rate random walk** ``K``: right of the minimum, on the part with slope ``+1/2 +- slope_tol``,
  a line of fixed slope +1/2; ``K`` is its value at ``tau = 3 s`` [rad/s/sqrt(s), m/s^2/sqrt(s)].

Coefficients that have no region of the required slope are NaN. The coefficients are reported
in SI and, by :func:`coefficients_table`, in datasheet units (deg/sqrt(h), deg/h, deg/h/sqrt(h),
m/s/sqrt(h), ug, ug/sqrt(s), arcsec, m/s) with the conversions of :mod:`insgnss.imu`.

Only taus with at least ``min_clusters`` independent clusters (``T / tau``) take part in the
extraction; the curve is computed further for plotting.

References
----------
- IEEE Std 952-1997, annex C.
- El-Sheimy, Hou, Niu, "Analysis and modeling of inertial sensors using Allan variance",
  IEEE Trans. Instrum. Meas. 57 (2008).
- Riley, *Handbook of Frequency Stability Analysis*, NIST SP 1065 (2008).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..imu import (
    ACCEL_COLS,
    DEG,
    DEG_PER_HOUR,
    DEG_PER_HOUR_PER_SQRT_HOUR,
    DEG_PER_SQRT_HOUR,
    DTHETA_COLS,
    DV_COLS,
    GYRO_COLS,
    M_S_PER_SQRT_HOUR,
    MG,
    UG,
    is_increment_table,
)

AXES = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
FLICKER_FACTOR = float(np.sqrt(2.0 * np.log(2.0) / np.pi))  # 0.6643
COEFF_COLS = ["quantization", "white", "bias_instability", "bias_instability_min", "tau_min", "rrw"]
ARCSEC = DEG / 3600.0  #: arcsec -> rad


@dataclass
class AllanResult:
    """Allan deviation of the six axes and the extracted coefficients.

    Attributes
    ----------
    adev : DataFrame
        Index ``tau`` [s], columns ``gyro_x .. accel_z`` [rad/s, m/s^2].
    clusters : ndarray
        ``T / tau`` for each tau (number of independent averaging windows).
    coefficients : DataFrame
        Index the six axes; columns ``quantization`` (Q [rad, m/s]), ``white`` (N: ARW
        [rad/sqrt(s)] or VRW [m/s/sqrt(s)]),
        ``bias_instability`` (B [rad/s, m/s^2], refined), ``bias_instability_min``
        (``sigma_min / 0.664``), ``tau_min`` [s], ``rrw`` (K [rad/s/sqrt(s), m/s^2/sqrt(s)]).
    duration, rate : float
        Record length [s] and sample rate [Hz].
    """

    adev: pd.DataFrame
    clusters: np.ndarray
    coefficients: pd.DataFrame
    duration: float
    rate: float


def tau_grid(n: int, rate: float, points_per_decade: int = 10, max_fraction: float = 0.25):
    """Log-spaced averaging times ``m / rate`` with integer ``m`` from 1 to ``max_fraction n``."""
    m_max = max(int(max_fraction * n), 1)
    m = np.unique(np.round(np.logspace(0, np.log10(m_max),
                                       max(int(points_per_decade * np.log10(m_max)) + 1, 2))))
    return m.astype(int) / rate


def allan_deviation_series(y: np.ndarray, rate: float, taus: np.ndarray,
                           increments_input: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of one series (NIST SP 1065 eq. 11).

    ``y`` holds rates (``increments_input=False``) or increments over ``1/rate``. ``taus`` are
    rounded to whole averaging factors ``m = round(tau rate)``; factors below 1 or without one
    full second difference (``2 m > N``) are dropped, duplicates merged. Returns
    ``(taus_used, adev)`` in the unit of the rate.
    """
    y = np.asarray(y, float)
    if increments_input:
        y = y * rate
    phase = np.concatenate([[0.0], np.cumsum(y - y.mean()) / rate])
    m_all = np.unique(np.round(np.asarray(taus, float) * rate).astype(np.int64))
    m_all = m_all[(m_all >= 1) & (2 * m_all < phase.size)]
    adev = np.empty(m_all.size)
    for k, m in enumerate(m_all):  # one vectorised pass per tau (tens of taus)
        d = phase[2 * m:] - 2.0 * phase[m:-m] + phase[:-2 * m]
        adev[k] = np.sqrt(np.mean(d * d) / 2.0) * rate / m
    return m_all / rate, adev


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the runs of consecutive True values in ``mask``."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def extract_coefficients(taus: np.ndarray, adev: np.ndarray, duration: float, *,
                         slope_tol: float = 0.05, min_clusters: float = 8.0) -> dict:
    """Noise coefficients of one axis from its Allan deviation (see module docstring)."""
    taus = np.asarray(taus, float)
    adev = np.asarray(adev, float)
    ok = (duration / taus >= min_clusters) & (adev > 0) & np.isfinite(adev)
    t, s = taus[ok], adev[ok]
    out = dict.fromkeys(COEFF_COLS, np.nan)
    if t.size < 3:
        return out
    lt, ls = np.log(t), np.log(s)
    slope = np.gradient(ls, lt)
    i_min = int(np.argmin(s))
    out["tau_min"] = float(t[i_min])
    out["bias_instability_min"] = float(s[i_min] / FLICKER_FACTOR)
    left = np.arange(t.size) <= i_min
    # quantisation: the run of slope -1 that starts at the shortest tau (the -1 region can only
    # be the left end of the curve); wider tolerance than the other slopes because the
    # quantisation-to-white transition bends the curve early
    runs = _runs(left & (np.abs(slope + 1.0) <= 2.0 * slope_tol))
    q_sel = runs[0] if runs and runs[0][0] == 0 and runs[0].size >= 2 else None
    white_from = 0 if q_sel is None else int(q_sel[-1]) + 1
    beyond = np.arange(t.size) >= white_from
    Q, N = np.nan, np.nan
    q_term = np.zeros_like(t)
    # Q and N each from their own region with the other's (fixed-slope) term removed; the two
    # regions overlap in their tails, so alternate a few times (converges in 2-3 passes)
    for _ in range(4 if q_sel is not None else 1):
        # white noise: the first run (shortest taus) of slope -1/2 left of the minimum, beyond
        # the quantisation region and with its 3 Q^2 / tau^2 removed
        sw2 = s**2 - q_term
        ok_w = beyond & (sw2 > 0)
        N = np.nan
        if np.count_nonzero(ok_w) >= 3:
            lsw = np.full_like(ls, np.nan)
            lsw[ok_w] = 0.5 * np.log(sw2[ok_w])
            slope_w = np.full_like(ls, np.nan)
            slope_w[ok_w] = np.gradient(lsw[ok_w], lt[ok_w])
            runs = _runs(left & ok_w & (np.abs(slope_w + 0.5) <= slope_tol))
            if runs:
                sel = runs[0]
                N = float(np.exp(np.mean(lsw[sel] + 0.5 * lt[sel])))
        if q_sel is None:
            break
        sq2 = s[q_sel] ** 2 - (N**2 / t[q_sel] if np.isfinite(N) else 0.0)
        sq2 = np.maximum(sq2, 1e-3 * s[q_sel] ** 2)
        Q = float(np.exp(np.mean(0.5 * np.log(sq2) + lt[q_sel])) / np.sqrt(3.0))
        q_term = 3.0 * Q**2 / t**2
    out["quantization"] = Q
    out["white"] = N
    # rate random walk: the longest run of slope +1/2 right of the minimum
    runs = _runs(~left & (np.abs(slope - 0.5) <= slope_tol))
    K = np.nan
    if runs:
        sel = max(runs, key=len)
        K = float(np.exp(np.mean(ls[sel] - 0.5 * (lt[sel] - np.log(3.0)))))
    out["rrw"] = K
    # bias instability: the flat region is where the floor C dominates the fitted white-noise
    # and rate-random-walk lines; C is the weighted mean of sigma^2 minus those lines there
    white = N**2 / t if np.isfinite(N) else np.zeros_like(t)
    white = white + (3.0 * Q**2 / t**2 if np.isfinite(Q) else 0.0)
    rrw = K**2 * t / 3.0 if np.isfinite(K) else np.zeros_like(t)
    resid = s**2 - white - rrw
    w = 1.0 / (t * s**4)  # 1 / var(sigma^2 estimate), up to a constant
    C = float(s[i_min] ** 2)
    for _ in range(5):
        flat = (white <= C) & (rrw <= C)
        if not np.any(flat):
            break
        C_new = float(np.sum(w[flat] * resid[flat]) / np.sum(w[flat]))
        if not C_new > 0 or C_new == C:
            C = C_new
            break
        C = C_new
    out["bias_instability"] = float(np.sqrt(C) / FLICKER_FACTOR) if C > 0 else np.nan
    return out


def allan_analysis(imu: pd.DataFrame, *, points_per_decade: int = 10, max_fraction: float = 0.25,
                   slope_tol: float = 0.05, min_clusters: float = 8.0) -> AllanResult:
    """Allan deviation of the six axes of a static IMU table and its noise coefficients.

    Parameters
    ----------
    imu : DataFrame
        IMU table (increments or rates, see :mod:`insgnss.imu`) at a uniform rate, recorded
        at rest.
    points_per_decade, max_fraction
        Tau grid (see :func:`tau_grid`).
    slope_tol, min_clusters
        Extraction settings (see the module docstring).
    """
    t = np.asarray(imu.index, dtype=float)
    if t.size < 16:
        raise ValueError("Allan analysis needs a longer record (at least 16 samples)")
    dts = np.diff(t)
    dt = float(np.median(dts))
    if np.max(np.abs(dts - dt)) > 0.01 * dt:
        raise ValueError("Allan analysis needs a uniform sample rate (time steps vary by > 1 %)")
    rate = 1.0 / dt
    inc = is_increment_table(imu)
    if inc:
        # drop row 0: the unknown interval before the first sample
        data = imu[DTHETA_COLS + DV_COLS].to_numpy(float)[1:]
    else:
        # the rates as sampled (never the trapezoidal increments: see the module docstring)
        data = imu[GYRO_COLS + ACCEL_COLS].to_numpy(float)
    n = data.shape[0]
    duration = n * dt
    taus = tau_grid(n, rate, points_per_decade, max_fraction)
    cols = {}
    t_used = taus
    for j, ax in enumerate(AXES):
        t_used, cols[ax] = allan_deviation_series(data[:, j], rate, taus, increments_input=inc)
    adev = pd.DataFrame(cols, index=pd.Index(t_used, name="tau"))
    coeffs = pd.DataFrame(
        [extract_coefficients(t_used, adev[ax].to_numpy(), duration, slope_tol=slope_tol,
                              min_clusters=min_clusters) for ax in AXES],
        index=pd.Index(AXES, name="axis"), columns=COEFF_COLS)
    return AllanResult(adev=adev, clusters=duration / t_used, coefficients=coeffs,
                       duration=duration, rate=rate)


#: datasheet units of the coefficient table: (column, gyro unit, gyro factor, accel unit, accel factor)
DATASHEET_UNITS = [
    ("white", "deg/sqrt(h)", DEG_PER_SQRT_HOUR, "m/s/sqrt(h)", M_S_PER_SQRT_HOUR),
    ("bias_instability", "deg/h", DEG_PER_HOUR, "ug", UG),
    ("bias_instability_min", "deg/h", DEG_PER_HOUR, "ug", UG),
    ("rrw", "deg/h/sqrt(h)", DEG_PER_HOUR_PER_SQRT_HOUR, "ug/sqrt(s)", UG),
    ("quantization", "arcsec", ARCSEC, "m/s", 1.0),
]


def coefficients_table(result: AllanResult) -> pd.DataFrame:
    """The coefficients in datasheet units, one row per axis, with a ``unit`` note per column.

    Columns: ``arw_vrw`` (deg/sqrt(h) for gyros, m/s/sqrt(h) for accelerometers),
    ``bias_instability`` and ``bias_instability_min`` (deg/h, ug), ``rrw`` (deg/h/sqrt(h),
    ug/sqrt(s)), ``quantization`` (Q: arcsec, m/s), ``quantization_lsb`` (the quantum
    ``sqrt(12) Q`` as a rate over one sample, ``sqrt(12) Q / tau0``: deg/s, mg), ``tau_min`` [s].
    """
    c = result.coefficients
    rows = []
    for ax in AXES:
        g = ax.startswith("gyro")
        row = {"axis": ax}
        for col, ug_, fg, ua, fa in DATASHEET_UNITS:
            name = "arw_vrw" if col == "white" else col
            row[name] = c.loc[ax, col] / (fg if g else fa)
            row[f"{name}_unit"] = ug_ if g else ua
        row["quantization_lsb"] = np.sqrt(12.0) * c.loc[ax, "quantization"] * result.rate \
            / (DEG if g else MG)
        row["quantization_lsb_unit"] = "deg/s" if g else "mg"
        row["tau_min"] = c.loc[ax, "tau_min"]
        rows.append(row)
    return pd.DataFrame(rows).set_index("axis")


def plot_allan(result: AllanResult, title: str | None = None):
    """Figure with the Allan deviation of gyros (deg/h) and accelerometers (ug) and the fitted
    reference slopes (-1/2 through N at tau = 1, the 0.664 B floor, +1/2 through K at tau = 3).

    Returns the matplotlib Figure (the caller saves it).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    tau = result.adev.index.to_numpy()
    colors = ["tab:red", "tab:green", "tab:blue"]
    for k, (sensor, unit, scale) in enumerate([("gyro", "deg/h", DEG_PER_HOUR),
                                               ("accel", "ug", UG)]):
        ax = axs[k]
        for j, comp in enumerate("xyz"):
            name = f"{sensor}_{comp}"
            c = result.coefficients.loc[name]
            col = colors[j]
            ax.loglog(tau, result.adev[name] / scale, color=col, lw=1.5, label=name)
            if np.isfinite(c["quantization"]):
                ax.loglog(tau, np.sqrt(3.0) * c["quantization"] / tau / scale, ls=(0, (1, 3)),
                          color=col, lw=1)
            if np.isfinite(c["white"]):
                ax.loglog(tau, c["white"] / np.sqrt(tau) / scale, ":", color=col, lw=1)
                ax.plot([1.0], [c["white"] / scale], "o", color=col, ms=4)
            if np.isfinite(c["bias_instability"]):
                ax.axhline(FLICKER_FACTOR * c["bias_instability"] / scale, ls="--", color=col,
                           lw=0.8)
            if np.isfinite(c["rrw"]):
                ax.loglog(tau, c["rrw"] * np.sqrt(tau / 3.0) / scale, "-.", color=col, lw=1)
                ax.plot([3.0], [c["rrw"] / scale], "s", color=col, ms=4)
        lo = np.nanmin(result.adev[[f"{sensor}_{c}" for c in "xyz"]].to_numpy()) / scale
        hi = np.nanmax(result.adev[[f"{sensor}_{c}" for c in "xyz"]].to_numpy()) / scale
        ax.set_ylim(lo / 3.0, hi * 3.0)
        ax.set_xlabel("averaging time tau [s]")
        ax.set_ylabel(f"Allan deviation [{unit}]")
        ax.set_title({"gyro": "gyroscopes", "accel": "accelerometers"}[sensor])
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(title="sparse dots: -1 (Q), dotted: -1/2 (N at 1 s),\n"
                        "dashed: 0.664 B, dash-dot: +1/2 (K at 3 s)",
                  fontsize=8, title_fontsize=7)
    if title:
        fig.suptitle(title)
    return fig
