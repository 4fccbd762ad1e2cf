"""The size and correlation time of a land vehicle's NHC violations, measured in the data.

The non-holonomic constraint says that the vehicle-frame lateral and vertical velocities are
zero; side slip and suspension heave make them not quite zero, correlated over about a second.
Where GNSS aids the filter, a smoothed solution resolves those velocities to a few cm/s, so the
violation can be read off it, like the other self-tuned parameters come from the data
(``aiding.nhc_violation_from_data``, docs/filter.md "Time-correlated NHC violations"):

    v_v = (I - [mu x]) C^T v            (body-frame velocity turned into the vehicle frame by the
                                         smoothed misalignment ``mu``, state ``nhc_misalignment``)
    lateral  = v_v[0]
    vertical = v_v[2] + kappa a_f v_f   (minus the suspension's squat/dive ``kappa``, state
                                         ``nhc_pitch_compliance``; ``a_f`` the forward
                                         acceleration, ``v_f`` the forward velocity)

over the moving samples (forward speed above ``min_speed``) outside the outage windows (with
``guard`` s either side: no GNSS inside, the smoothed velocity there follows the constraint
itself). Each component, resampled on a ``dt`` grid, gives its sigma (RMS about its mean) and
its autocorrelation ``r(lag)``; the correlation time is the least-squares fit of
``ln r = -lag / tau`` over the lags from ``min_lag`` (twice the NHC interval: below it the
smoothed series carries the structure of the 4 Hz updates) to ``max_lag`` where ``r > 0.05``,
pooled over both axes. The lever arm ``w x l`` to the constrained point is not subtracted (the
smoothed table has no angular rate), so the constrained point should be the IMU's or close to it.

The smoothed velocity is pulled toward the constraint by the NHC of the first pass, so the
sigma is a lower bound where GNSS velocity is weak; with RTK at 4 Hz (a few cm/s) the pull is
small.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .attitude import euler_to_dcm, skew

__all__ = ["NhcViolation", "nhc_violation_estimate"]


@dataclass
class NhcViolation:
    """Measured NHC violation: ``std`` (lateral, vertical) [m/s], correlation time ``tau`` [s]
    (0: no correlation found beyond ``min_lag``), ``samples`` used and the autocorrelation
    ``acf`` per axis at ``lags`` [s]."""

    std: tuple[float, float]
    tau: float
    samples: int
    lags: np.ndarray
    acf: np.ndarray

    def as_dict(self) -> dict:
        return {"std_m_s": [float(x) for x in self.std], "tau_s": float(self.tau),
                "samples": int(self.samples), "lags_s": [float(x) for x in self.lags],
                "acf": [[float(x) for x in row] for row in self.acf]}


def _component(t, x, keep, grid):
    """``x`` on ``grid`` where every stored sample between grid points is kept, else NaN."""
    out = np.interp(grid, t, x)
    ok = np.interp(grid, t, keep.astype(float)) > 0.999
    out[~ok] = np.nan
    return out


def nhc_violation_estimate(smoothed: pd.DataFrame, windows=(), *, min_speed: float = 2.0,
                           guard: float = 1.0, settle: float = 10.0, dt: float = 0.05,
                           min_lag: float = 0.5, max_lag: float = 2.0,
                           misalignment: str = "nhc_misalignment",
                           pitch_compliance: str = "nhc_pitch_compliance") -> NhcViolation:
    """Sigma and correlation time of the NHC's violations from a smoothed solution (module
    docstring).

    Parameters
    ----------
    smoothed : DataFrame
        Smoothed table of the filter (time index; ``vel_e vel_n vel_u`` [m/s], ``roll pitch
        heading`` [rad]; the misalignment and pitch-compliance states when they exist).
    windows : sequence of (start, end)
        GNSS outage windows [s].
    min_speed : float
        Forward speed [m/s] below which samples are left out (a standing car says nothing).
    guard, settle : float
        Seconds left out either side of each window and after the first sample.
    dt, min_lag, max_lag : float
        Resampling interval and the lag range [s] of the correlation-time fit.
    """
    t = smoothed.index.to_numpy(float)
    C = euler_to_dcm(smoothed["roll"].to_numpy(float), smoothed["pitch"].to_numpy(float),
                     smoothed["heading"].to_numpy(float))
    v = smoothed[["vel_e", "vel_n", "vel_u"]].to_numpy(float)
    vb = np.einsum("kji,kj->ki", C, v)
    mcols = [f"{misalignment}_{a}" for a in "xyz"]
    if all(c in smoothed.columns for c in mcols):
        mu = smoothed[mcols].to_numpy(float)
        vb = vb - np.einsum("kij,kj->ki", skew(mu), vb)
    lat, up = vb[:, 0].copy(), vb[:, 2].copy()
    if pitch_compliance in smoothed.columns:
        a_f = np.gradient(vb[:, 1], t)
        up += smoothed[pitch_compliance].to_numpy(float) * a_f * vb[:, 1]
    keep = (vb[:, 1] > min_speed) & (t > t[0] + settle)
    for a, b in windows:
        keep &= ~((t >= a - guard) & (t < b + guard))
    n = int(np.count_nonzero(keep))
    grid = np.arange(t[0], t[-1], dt)
    series = [_component(t, x, keep, grid) for x in (lat, up)]
    std = tuple(float(np.sqrt(np.nanvar(s))) if np.isfinite(s).sum() > 1 else float("nan")
                for s in series)
    lags = np.arange(int(round(min_lag / dt)), int(round(max_lag / dt)) + 1) * dt
    acf = np.full((2, lags.size), np.nan)
    for k, s in enumerate(series):
        s = s - np.nanmean(s)
        for j, lag in enumerate(lags):
            m = int(round(lag / dt))
            x, y = s[:-m], s[m:]
            ok = np.isfinite(x) & np.isfinite(y)
            if ok.sum() > 10:
                acf[k, j] = np.corrcoef(x[ok], y[ok])[0, 1]
    use = np.isfinite(acf) & (acf > 0.05)
    L = np.broadcast_to(lags, acf.shape)[use]
    tau = 0.0
    if L.size:
        slope = float(np.sum(L * np.log(acf[use])) / np.sum(L * L))
        tau = -1.0 / slope if slope < 0 else 0.0
    return NhcViolation(std, tau, n, lags, acf)
