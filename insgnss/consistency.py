"""Consistency of a solution with a reference: errors of position, velocity and attitude with the
filter's sigmas, NEES of the error-state blocks and chi-square bounds. Shared by the single-run
report (:mod:`insgnss.report_data`) and Monte Carlo studies (:mod:`insgnss.montecarlo`).

- errors (estimate minus truth): position in ENU metres with the local radii
  (``dE = dlon (N + h) cos(lat)``, ``dN = dlat (M + h)``, ``dU = dh``), ENU velocity,
  roll/pitch/heading wrapped to +-pi; the attitude error state is the misalignment ``phi`` of
  ``C_est = exp([phi x]) C_true`` (:func:`insgnss.attitude.attitude_error`);
- NEES ``e' P^-1 e`` of each 3-dof block (position, velocity, attitude);
- bounds of the average of ``n`` chi-square(``dof``) variables:
  ``chi2.ppf((1 -+ c) / 2, n dof) / n`` (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: error quantities of every run (units m, m/s, rad) and the filter std column of each
ERROR_QUANTITIES = ("east", "north", "up", "horizontal", "vel_e", "vel_n", "vel_u",
                    "roll", "pitch", "heading")
STD_OF = {"east": "east_std", "north": "north_std", "up": "up_std", "horizontal": None,
          "vel_e": "vel_e_std", "vel_n": "vel_n_std", "vel_u": "vel_u_std",
          "roll": "roll_std", "pitch": "pitch_std", "heading": "heading_std"}
#: NEES blocks: error-state slices (pos, vel, att = misalignment phi)
NEES_BLOCKS = {"pos": slice(0, 3), "vel": slice(3, 6), "att": slice(6, 9)}
ANGLE_QUANTITIES = ("roll", "pitch", "heading")
TIME_TOL = 1e-6  #: grid and epoch matching tolerance [s]


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def match_times(a: np.ndarray, b: np.ndarray, tol: float = TIME_TOL) -> np.ndarray:
    """Index into sorted ``b`` of the element nearest each ``a`` (-1 where none within
    ``tol``)."""
    if not b.size:
        return np.full(a.size, -1)
    j = np.searchsorted(b, a)
    lo = np.clip(j - 1, 0, b.size - 1)
    hi = np.clip(j, 0, b.size - 1)
    pick = np.where(np.abs(b[lo] - a) <= np.abs(b[hi] - a), lo, hi)
    return np.where(np.abs(b[pick] - a) <= tol, pick, -1)


def solution_errors(sol: pd.DataFrame, truth: pd.DataFrame, times: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Errors (T, Q), filter stds (T, Q) and the 9-vector error state ``(dr_enu, dv, phi)``
    (T, 9) of ``sol`` against ``truth`` at ``times`` (rows present in both tables)."""
    from .attitude import attitude_error, euler_to_dcm
    from .earth import radii

    i_s = match_times(times, sol.index.to_numpy(float))
    i_t = match_times(times, truth.index.to_numpy(float))
    if np.any(i_s < 0) or np.any(i_t < 0):
        raise ValueError("solution_errors: times missing from the solution or the truth")
    s = sol.iloc[i_s]
    tr = truth.iloc[i_t]
    lat = tr["lat"].to_numpy(float)
    h = tr["height"].to_numpy(float)
    M, N = radii(lat)
    de = wrap_angle(s["lon"].to_numpy(float) - tr["lon"].to_numpy(float)) * (N + h) * np.cos(lat)
    dn = (s["lat"].to_numpy(float) - lat) * (M + h)
    du = s["height"].to_numpy(float) - h
    dv = s[["vel_e", "vel_n", "vel_u"]].to_numpy(float) - \
        tr[["vel_e", "vel_n", "vel_u"]].to_numpy(float)
    eul_s = s[["roll", "pitch", "heading"]].to_numpy(float)
    eul_t = tr[["roll", "pitch", "heading"]].to_numpy(float)
    deul = wrap_angle(eul_s - eul_t)
    err = np.column_stack([de, dn, du, np.hypot(de, dn), dv, deul])
    sig = np.empty_like(err)

    def std(col):  # NaN for a solution without that sigma (e.g. a smoothed foot-mounted track)
        return s[col].to_numpy(float) if col in s.columns else np.full(len(s), np.nan)

    for q, name in enumerate(ERROR_QUANTITIES):
        col = STD_OF[name]
        sig[:, q] = np.hypot(std("east_std"), std("north_std")) if col is None else std(col)
    phi = attitude_error(euler_to_dcm(*eul_s.T), euler_to_dcm(*eul_t.T))
    x = np.column_stack([de, dn, du, dv, phi.reshape(-1, 3)])
    return err, sig, x


def nees_blocks(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """NEES ``e^T P^-1 e`` of each block of :data:`NEES_BLOCKS`: (T, 9) errors, (T, n, n)
    covariances -> (T, 3)."""
    out = np.empty((x.shape[0], len(NEES_BLOCKS)))
    for k, sl in enumerate(NEES_BLOCKS.values()):
        e = x[:, sl]
        out[:, k] = np.einsum("ti,ti->t", e, np.linalg.solve(P[:, sl, sl], e[..., None])[..., 0])
    return out


def chi2_bounds(dof: np.ndarray, n: np.ndarray, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided bounds of the average of ``n`` chi-square(``dof``) variables."""
    from .stats import chi2_ppf

    dof = np.asarray(dof, float)
    n = np.asarray(n, float)
    a = (1.0 - confidence) / 2.0
    ok = (n > 0) & (dof > 0)
    nd = np.where(ok, n * dof, 1.0)
    nn = np.where(ok, n, 1.0)
    lo = np.where(ok, chi2_ppf(a, nd) / nn, np.nan)
    hi = np.where(ok, chi2_ppf(1.0 - a, nd) / nn, np.nan)
    return lo, hi
