"""Single-point positioning (SPP) from pseudoranges and Doppler: weighted least squares with
one receiver clock bias per constellation, fault detection and exclusion, DOP, and the
velocity / clock drift from Doppler.

Position (Gauss-Newton on the model of :mod:`.observations`), state
``x = [r_ecef (3), b_S (one per system present)]``::

    H_i = [-u_i^T, e_S(i)^T],  v_i = P_i - P_hat_i(x),  dx = (H^T W H)^-1 H^T W v,
    W = diag(1 / sigma_i^2)

iterated until ``|dx| < 1 mm`` (troposphere, ionosphere and the elevation mask enter once
the position is within 10 km). Fault detection and exclusion (RAIM FDE, Brown 1992; Kuusniemi
2005): the weighted sum of squared residuals ``v^T W v`` is tested against
``chi2(1 - p_fa, m - n)``; while it fails and redundancy remains, the measurement with the
largest normalised residual ``|v_i| / sqrt((R - H (H^T W H)^-1 H^T)_ii)`` is excluded and the
solution recomputed. Dilution of precision from ``(G^T G)^-1`` with the ENU geometry matrix
``G = [-u_enu^T, e_S^T]`` (Misra & Enge 2011, 6.1).

Velocity (linear): ``rdot_i = -lambda_i D_i``, ``H_i = [-u_i^T, 1]`` for ``[v_ecef, d]`` with
one clock drift ``d`` [m/s] (one oscillator); the same FDE.

Output: a GNSS table in the layout of the other GNSS readers (``lat lon height`` [rad, m
ellipsoidal], ``east_std north_std up_std``, ``vel_e vel_n vel_u`` + ``vel_*_std`` from the
a-priori-weighted covariance, ``q = 5`` single, ``ns``), plus ``clock_bias_<S>`` [m],
``clock_drift`` [m/s], ``gdop pdop hdop vdop``, ``chi2 dof raim_ok n_excluded``, indexed by
the GPS time of reception (receiver time tag ``receiver_time`` minus the clock offset of the
first system, ``b / c``), and a residual table (one row per epoch and satellite, by tag).

References
----------
- Misra, P., Enge, P., *Global Positioning System*, 2nd ed. rev., 2011, ch. 6.
- Brown, R. G., "A baseline GPS RAIM scheme and a note on the equivalence of three RAIM
  methods", Navigation 39(3), 1992.
- Groves 2013, 9.4.1 (single-epoch least squares), 17.4 (FDE).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..earth import ecef_to_enu_matrix, ecef_to_geodetic, geodetic_to_ecef
from .constants import C_LIGHT
from .corrections import day_of_year
from .observations import (
    GnssModelConfig,
    epoch_arrays,
    epoch_model,
    klobuchar_parameters,
    prepare_observations,
)

#: columns of the residual table of :func:`spp`
RESIDUAL_COLUMNS = ["time", "sat", "signal", "el", "az", "cn0", "pr_residual", "pr_std",
                    "rate_residual", "rate_std", "used", "doppler_used", "tropo", "iono"]


@functools.lru_cache(maxsize=256)
def _chi2_threshold(p_fa: float, dof: int) -> float:
    from ..stats import chi2_ppf

    return float(chi2_ppf(1.0 - p_fa, dof))


@dataclass
class SppConfig:
    """Settings of :func:`spp`.

    Parameters
    ----------
    model : GnssModelConfig
        Signals, masks and noise model.
    false_alarm : float
        Probability of false alarm of the chi-square fault detection (0 disables FDE).
    max_exclusions : int
        Most measurements excluded per epoch (position and velocity each).
    max_iterations : int
    velocity : bool
        Also solve velocity and clock drift from Doppler.
    """

    model: GnssModelConfig = field(default_factory=GnssModelConfig)
    false_alarm: float = 1e-3
    max_exclusions: int = 3
    max_iterations: int = 10
    velocity: bool = True


@dataclass
class SppResult:
    """Output of :func:`spp`: ``solution`` (GNSS table), ``residuals`` (per satellite),
    ``prepared`` (the measurement rows used, :func:`.observations.prepare_observations`)."""

    solution: pd.DataFrame
    residuals: pd.DataFrame
    prepared: pd.DataFrame


def _wls(H, v, w):
    """Weighted least squares step: dx, covariance (H^T W H)^-1."""
    A = H.T * w
    N = A @ H
    Q = np.linalg.inv(N)
    return Q @ (A @ v), Q


def _fde(H, v, var, used, p_fa, max_excl, n_state):
    """Chi-square test and exclusion of the largest normalised residual (in place on
    ``used``); returns (chi2, dof, ok, n_excluded)."""
    n_ex = 0
    while True:
        idx = np.nonzero(used)[0]
        Hu = H[idx]
        cols = np.any(Hu != 0.0, axis=0)
        Hu = Hu[:, cols]
        dof = idx.size - Hu.shape[1]
        if dof < 0 or np.linalg.matrix_rank(Hu) < Hu.shape[1]:
            return np.nan, dof, False, n_ex
        w = 1.0 / var[idx]
        dx, Q = _wls(Hu, v[idx], w)
        r = v[idx] - Hu @ dx
        t = float(np.sum(r**2 * w))
        if dof == 0 or p_fa <= 0.0:
            return t, dof, dof > 0 or p_fa <= 0.0, n_ex
        if t <= _chi2_threshold(p_fa, dof):
            return t, dof, True, n_ex
        if n_ex >= max_excl or dof < 2:
            return t, dof, False, n_ex
        Cr = np.diag(var[idx]) - Hu @ Q @ Hu.T
        nr = np.abs(r) / np.sqrt(np.maximum(np.diag(Cr), 1e-12))
        used[idx[np.argmax(nr)]] = False
        n_ex += 1


def solve_epoch(rows, t: float, x0, iono_params, cfg: SppConfig, doy=None):
    """Position, clocks, velocity and drift of one epoch; see the module docstring.

    ``x0`` is ``(r_ecef (3,), {system: bias})`` or None (start at the Earth's centre).
    Returns a dict (or None when fewer than 4 + (systems - 1) measurements remain).
    """
    mc = cfg.model
    sysl = np.asarray(rows["system"], object)
    systems = sorted(set(sysl))
    col = {s: 3 + k for k, s in enumerate(systems)}
    n_state = 3 + len(systems)
    nrow = sysl.size
    if nrow < n_state:
        return None
    sys_idx = np.array([col[s] for s in sysl])
    pr_meas = np.asarray(rows["pr"], float)
    r = np.zeros(3) if x0 is None else np.array(x0[0], float)
    b = np.zeros(len(systems)) if x0 is None else np.array([x0[1].get(s, 0.0) for s in systems])
    used = np.ones(nrow, bool)
    prior_far = x0 is None
    for _ in range(cfg.max_iterations * 2):
        lat, lon, h = (ecef_to_geodetic(*r) if np.linalg.norm(r) > 1e6 else (0.0, 0.0, 0.0))
        near = np.linalg.norm(r) > 6.0e6 and not prior_far
        m = epoch_model(rows, r, lat, lon, h, t, iono_params, mc, doy, atmosphere=near)
        if near:
            used &= m.el >= mc.elevation_mask
        H = np.zeros((nrow, n_state))
        H[:, :3] = -m.los
        H[np.arange(nrow), sys_idx] = 1.0
        v = pr_meas - (m.pr + b[sys_idx - 3])
        idx = np.nonzero(used)[0]
        if idx.size < n_state:
            return None
        Hu = H[idx]
        present = np.any(Hu[:, 3:] != 0.0, axis=0)
        cols = np.r_[np.ones(3, bool), present]
        dx = np.zeros(n_state)
        step, _ = _wls(Hu[:, cols], v[idx], 1.0 / (m.var_pr[idx] if near else np.ones(idx.size)))
        dx[cols] = step
        r = r + dx[:3]
        b = b + dx[3:]
        if np.linalg.norm(dx[:3]) < 1e4:
            prior_far = False
        if near and np.linalg.norm(dx) < 1e-3:
            break
    else:
        return None
    # final model at the solution, fault detection and exclusion
    lat, lon, h = ecef_to_geodetic(*r)
    m = epoch_model(rows, r, lat, lon, h, t, iono_params, mc, doy)
    used &= m.el >= mc.elevation_mask
    H = np.zeros((nrow, n_state))
    H[:, :3] = -m.los
    H[np.arange(nrow), sys_idx] = 1.0
    v = pr_meas - (m.pr + b[sys_idx - 3])
    chi, dof, ok, n_ex = _fde(H, v, m.var_pr, used, cfg.false_alarm, cfg.max_exclusions, n_state)
    idx = np.nonzero(used)[0]
    Hu = H[idx]
    present = np.any(Hu[:, 3:] != 0.0, axis=0)
    cols = np.r_[np.ones(3, bool), present]
    if idx.size < cols.sum():
        return None
    step, Q = _wls(Hu[:, cols], v[idx], 1.0 / m.var_pr[idx])
    dx = np.zeros(n_state)
    dx[cols] = step
    r = r + dx[:3]
    b = b + dx[3:]
    lat, lon, h = ecef_to_geodetic(*r)
    Cel = ecef_to_enu_matrix(lat, lon)
    P_enu = Cel @ Q[:3, :3] @ Cel.T
    G = Hu[:, cols].copy()
    G[:, :3] = G[:, :3] @ Cel.T
    D = np.linalg.inv(G.T @ G)
    out = {
        "r": r, "lat": lat, "lon": lon, "height": h, "P_enu": P_enu,
        "bias": {s: (b[k] if present[k] else np.nan) for k, s in enumerate(systems)},
        "ns": idx.size, "gdop": np.sqrt(np.trace(D)), "pdop": np.sqrt(np.trace(D[:3, :3])),
        "hdop": np.sqrt(D[0, 0] + D[1, 1]), "vdop": np.sqrt(D[2, 2]),
        "chi2": chi, "dof": dof, "raim_ok": ok, "n_excluded": n_ex, "used": used.copy(),
    }
    # residuals at the final solution
    m = epoch_model(rows, r, lat, lon, h, t, iono_params, mc, doy)
    out["model"] = m
    out["pr_residual"] = pr_meas - (m.pr + b[sys_idx - 3])
    out["vel"] = out["P_vel"] = None
    out["drift"] = np.nan
    out["doppler_used"] = np.zeros(nrow, bool)
    out["rate_residual"] = np.full(nrow, np.nan)
    if cfg.velocity:
        lam = C_LIGHT / np.asarray(rows["freq"], float)
        rdot = -lam * np.asarray(rows["doppler"], float)
        du = used & np.isfinite(rdot)
        Hd = np.column_stack([-m.los, np.ones(nrow)])
        vd = rdot - m.rate
        if du.sum() >= 4:
            _fde(Hd, vd, m.var_rate, du, cfg.false_alarm, cfg.max_exclusions, 4)
            idd = np.nonzero(du)[0]
            if idd.size >= 4:
                sol, Qd = _wls(Hd[idd], vd[idd], 1.0 / m.var_rate[idd])
                out["vel"] = Cel @ sol[:3]
                out["P_vel"] = Cel @ Qd[:3, :3] @ Cel.T
                out["drift"] = sol[3]
                out["doppler_used"] = du
                out["rate_residual"] = vd - Hd @ sol
    return out


def spp(obs: pd.DataFrame, eph: pd.DataFrame, ion: pd.DataFrame | None = None,
        config: SppConfig | None = None, prepared: pd.DataFrame | None = None) -> SppResult:
    """Single-point positioning of every epoch of an observation table.

    Parameters
    ----------
    obs : DataFrame
        Observations (:func:`insgnss.gnss.read_ubx` ``.observations`` or
        :func:`insgnss.gnss.read_rinex_obs`).
    eph : DataFrame
        Broadcast ephemerides (:func:`insgnss.gnss.decode_subframes`,
        :func:`insgnss.gnss.read_rinex_nav`).
    ion : DataFrame, optional
        Broadcast ionosphere parameters (GPS Klobuchar); without them no ionospheric
        correction is applied and the variance is inflated.
    config : SppConfig
    prepared : DataFrame, optional
        The output of :func:`~.observations.prepare_observations` (computed if None).
    """
    cfg = config or SppConfig()
    prep = prepared if prepared is not None else prepare_observations(obs, eph, cfg.model)
    iono_params = klobuchar_parameters(ion)
    systems = [s for s in cfg.model.signals if s in set(prep["system"])]
    starts, arr = epoch_arrays(prep)
    times = arr["time"]
    sol_rows, res_parts = [], []
    x0 = None
    doy = day_of_year(times[0]) if times.size else 0.0
    for k in range(starts.size - 1):
        rows = {c: a[starts[k]:starts[k + 1]] for c, a in arr.items()}
        t = times[starts[k]]
        s = solve_epoch(rows, t, x0, iono_params, cfg, doy)
        if s is None:
            x0 = None
            continue
        x0 = (s["r"], {q: v for q, v in s["bias"].items() if np.isfinite(v)})
        P = s["P_enu"]
        # the solution is at the true reception time: tag minus the receiver clock offset
        b_ref = next((s["bias"][q] for q in systems if np.isfinite(s["bias"].get(q, np.nan))),
                     0.0)
        row = {"time": t - b_ref / C_LIGHT, "receiver_time": t, "lat": s["lat"], "lon": s["lon"],
               "height": s["height"],
               "east_std": np.sqrt(P[0, 0]), "north_std": np.sqrt(P[1, 1]),
               "up_std": np.sqrt(P[2, 2])}
        if s["vel"] is not None:
            Pv = s["P_vel"]
            row.update(vel_e=s["vel"][0], vel_n=s["vel"][1], vel_u=s["vel"][2],
                       vel_e_std=np.sqrt(Pv[0, 0]), vel_n_std=np.sqrt(Pv[1, 1]),
                       vel_u_std=np.sqrt(Pv[2, 2]))
        row.update(q=5.0, ns=float(s["ns"]), clock_drift=s["drift"])
        for q in systems:
            row[f"clock_bias_{q}"] = s["bias"].get(q, np.nan)
        row.update(gdop=s["gdop"], pdop=s["pdop"], hdop=s["hdop"], vdop=s["vdop"],
                   chi2=s["chi2"], dof=float(s["dof"]), raim_ok=bool(s["raim_ok"]),
                   n_excluded=float(s["n_excluded"]))
        sol_rows.append(row)
        m = s["model"]
        res_parts.append({
            "time": np.full(m.el.size, t), "sat": rows["sat"], "signal": rows["signal"],
            "el": m.el, "az": m.az, "cn0": rows["cn0"],
            "pr_residual": s["pr_residual"], "pr_std": np.sqrt(m.var_pr),
            "rate_residual": s["rate_residual"], "rate_std": np.sqrt(m.var_rate),
            "used": s["used"], "doppler_used": s["doppler_used"],
            "tropo": m.tropo, "iono": m.iono})
    cols = ["lat", "lon", "height", "east_std", "north_std", "up_std", "vel_e", "vel_n", "vel_u",
            "vel_e_std", "vel_n_std", "vel_u_std", "q", "ns", "clock_drift",
            *[f"clock_bias_{q}" for q in systems], "gdop", "pdop", "hdop", "vdop", "chi2", "dof",
            "raim_ok", "n_excluded", "receiver_time"]
    sol = pd.DataFrame(sol_rows, columns=["time", *cols]).set_index("time")
    res = pd.DataFrame({c: np.concatenate([p[c] for p in res_parts]) if res_parts else []
                        for c in RESIDUAL_COLUMNS})
    sol.attrs.update(obs.attrs)
    sol.attrs.update(format="spp", time_base=obs.attrs.get("time_base", "gps"),
                     height_reference="ellipsoid")
    return SppResult(sol, res, prep)


def ecef_of(sol: pd.DataFrame) -> np.ndarray:
    """ECEF positions (N, 3) of a solution table's ``lat lon height``."""
    x, y, z = geodetic_to_ecef(sol["lat"].to_numpy(float), sol["lon"].to_numpy(float),
                               sol["height"].to_numpy(float))
    return np.column_stack([x, y, z])
