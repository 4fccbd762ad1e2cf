"""Evaluation of a trajectory against a reference.

Errors are computed at the reference epochs: the solution is interpolated linearly in ECEF
(bracketing samples at most ``max_gap`` apart) and the difference is expressed in the local
ENU frame of the reference point. A lever arm moves the solution to the point the reference
measures (``r_point = r_imu + C_b^l l^b``). Outage metrics follow the drive benchmark protocol
(shared/eval/README.md): per outage the horizontal error at its last reference epoch, the max
and the RMS inside it, the vertical error at its end; outside the outages the horizontal RMS
after a settling time, skipping a guard interval after each outage end.

Consistency at the outage ends (when the solution carries ``east_std north_std``): the ratio of
the horizontal error to the filter's horizontal sigma ``hypot(east_std, north_std)`` and the
two-axis 3-sigma test ``(e_E/s_E)^2 + (e_N/s_N)^2 <= 11.83`` (chi-square, 2 dof, 99.73 %); the
summary gives the ratio's mean/median/max and ``end_within_3sigma_fraction``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .aot import entry
from .attitude import euler_to_dcm
from .earth import enu_displacement_to_geodetic, geodetic_to_ecef_nb
from .jit import njit
from .outages import in_windows, window_index


def move_point(traj: pd.DataFrame, lever_arm) -> pd.DataFrame:
    """Trajectory of the point at ``lever_arm`` (body RFU, metres) from the IMU trajectory."""
    la = np.asarray(lever_arm, float)
    if not np.any(la):
        return traj
    C = euler_to_dcm(traj["roll"].to_numpy(), traj["pitch"].to_numpy(), traj["heading"].to_numpy())
    d = C @ la
    lat, h = traj["lat"].to_numpy(), traj["height"].to_numpy()
    dlat, dlon, dh = enu_displacement_to_geodetic(lat, h, d[:, 0], d[:, 1], d[:, 2])
    out = traj.copy()
    out["lat"] = lat + dlat
    out["lon"] = traj["lon"].to_numpy() + dlon
    out["height"] = h + dh
    return out


@entry
@njit(cache=True)
def _position_errors_nb(ts, slat, slon, sh, tr, rlat, rlon, rh, jr, max_gap):
    """ENU errors (N, 3) at the reference epochs ``tr`` (geodetic ``rlat rlon rh``) of the
    solution at ``ts`` (geodetic ``slat slon sh``): the bracketing solution samples (at most
    ``max_gap`` apart) converted to ECEF and interpolated linearly there, the difference to
    the reference point rotated into its ENU axes (``C_e^l``, :func:`ecef_to_enu_matrix`);
    an epoch within 1e-4 s of a solution sample and not bracketed takes that sample; NaN
    where not covered. ``jr``: the solution samples at or before each reference epoch
    (``searchsorted(ts, tr, "right")``)."""
    n, ns = tr.size, ts.size
    out = np.empty((n, 3))
    last = -1  # the solution sample converted last (x1): the next epoch's x0 at the same rate
    x1 = y1 = z1 = 0.0
    for k in range(n):
        t = tr[k]
        j = jr[k]
        jj = min(max(j, 1), ns - 1)
        jprev = min(max(j - 1, 0), ns - 1)
        t0, t1 = ts[jj - 1], ts[jj]
        ok = j > 0 and j < ns and (t1 - t0) <= max_gap
        exact = abs(ts[jprev] - t) <= 1e-4
        if ok:
            w = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
            if last == jj - 1:
                x0, y0, z0 = x1, y1, z1
            else:
                x0, y0, z0 = geodetic_to_ecef_nb(slat[jj - 1], slon[jj - 1], sh[jj - 1])
            if last != jj:
                x1, y1, z1 = geodetic_to_ecef_nb(slat[jj], slon[jj], sh[jj])
                last = jj
            x, y, z = x0 + w * (x1 - x0), y0 + w * (y1 - y0), z0 + w * (z1 - z0)
        elif exact:
            x, y, z = geodetic_to_ecef_nb(slat[jprev], slon[jprev], sh[jprev])
        else:
            out[k, 0] = out[k, 1] = out[k, 2] = np.nan
            continue
        xr, yr, zr = geodetic_to_ecef_nb(rlat[k], rlon[k], rh[k])
        dx, dy, dz = x - xr, y - yr, z - zr
        sl, cl, so, co = np.sin(rlat[k]), np.cos(rlat[k]), np.sin(rlon[k]), np.cos(rlon[k])
        out[k, 0] = -so * dx + co * dy
        out[k, 1] = -sl * co * dx - sl * so * dy + cl * dz
        out[k, 2] = cl * co * dx + cl * so * dy + sl * dz
    return out


def enu_errors(solution: pd.DataFrame, reference: pd.DataFrame, *,
               max_gap: float = 0.5) -> np.ndarray:
    """ENU position error (solution - reference) [m] at the reference epochs, (N, 3): the array
    of :func:`position_errors`."""
    ts = solution.index.to_numpy(float)
    tr = reference.index.to_numpy(float)
    if not ts.size:
        return np.full((tr.size, 3), np.nan)
    sol = [np.ascontiguousarray(solution[c].to_numpy(float)) for c in ("lat", "lon", "height")]
    ref = [np.ascontiguousarray(reference[c].to_numpy(float)) for c in ("lat", "lon", "height")]
    j = np.searchsorted(ts, tr, side="right")
    return _position_errors_nb(ts, *sol, tr, *ref, j, float(max_gap))


def position_errors(solution: pd.DataFrame, reference: pd.DataFrame, *,
                    max_gap: float = 0.5) -> pd.DataFrame:
    """ENU position error (solution - reference) [m] at the reference epochs.

    Returns a DataFrame indexed by the reference times with ``east north up horizontal``;
    epochs not covered by the solution (outside its span or across a gap) are NaN.
    """
    enu = enu_errors(solution, reference, max_gap=max_gap)
    out = pd.DataFrame(enu, index=reference.index, columns=["east", "north", "up"], copy=False)
    out["horizontal"] = np.hypot(enu[:, 0], enu[:, 1])
    return out


def trajectory_errors(solution: pd.DataFrame, reference: pd.DataFrame, *,
                      max_gap: float = 0.5) -> pd.DataFrame:
    """Errors (solution - reference) at the reference epochs: ``east north up horizontal``
    [m] (:func:`position_errors`), and where both tables have them ``vel_e vel_n vel_u``
    [m/s] and ``roll pitch heading`` [rad, wrapped to +-pi] (the solution interpolated
    linearly, angles unwrapped first). Epochs the solution does not cover are NaN."""
    from .attitude import wrap_pi

    out = position_errors(solution, reference, max_gap=max_gap)
    ts = solution.index.to_numpy(float)
    tr = reference.index.to_numpy(float)
    bad = out["horizontal"].isna().to_numpy()
    for cols, angle in ((("vel_e", "vel_n", "vel_u"), False), (("roll", "pitch", "heading"), True)):
        for c in cols:
            if c not in solution.columns or c not in reference.columns:
                continue
            s = solution[c].to_numpy(float)
            e = np.interp(tr, ts, np.unwrap(s) if angle else s) - reference[c].to_numpy(float)
            e = wrap_pi(e) if angle else e
            e[bad] = np.nan
            out[c] = e
    return out


def outage_metrics(errors: pd.DataFrame, windows, *, t_first: float | None = None,
                   settle_time: float = 10.0, guard_time: float = 1.0) -> tuple[pd.DataFrame, dict]:
    """Per-outage error table and a summary dict (drive benchmark protocol)."""
    t = errors.index.to_numpy(float)
    hz = errors["horizontal"].to_numpy()
    up = errors["up"].to_numpy()
    # the stds are read from each outage's last row only (no whole-length copy of the pair,
    # 11 MB at a 200 Hz reference over 1 h)
    has_sig = {"east_std", "north_std"} <= set(errors.columns)
    k_of = window_index(t, windows)
    rows = []
    for k, (a, b) in enumerate(windows):
        m = k_of == k
        valid = m & np.isfinite(hz)
        if not np.any(valid):
            rows.append({"outage": k, "start": a, "end": b, "n_epochs": 0,
                         "end_h_err_m": np.nan, "max_h_err_m": np.nan, "rms_h_err_m": np.nan,
                         "end_v_err_m": np.nan, "complete": False})
            continue
        last = np.nonzero(valid)[0][-1]
        row = {"outage": k, "start": a, "end": b, "n_epochs": int(valid.sum()),
               "end_h_err_m": float(hz[last]), "max_h_err_m": float(np.max(hz[valid])),
               "rms_h_err_m": float(np.sqrt(np.mean(hz[valid] ** 2))),
               "end_v_err_m": float(up[last]),
               "complete": bool(valid.sum() == m.sum())}
        if has_sig:
            end = errors.iloc[last]
            row.update(_end_consistency(end, end[["east_std", "north_std"]].to_numpy(float)))
        rows.append(row)
    table = pd.DataFrame(rows)
    t0 = t[0] if t_first is None else t_first
    outside = ~in_windows(t, windows) & (t >= t0 + settle_time) & np.isfinite(hz)
    guarded = outside & ~in_windows(t, [(b, b + guard_time) for _, b in windows])
    summary = {
        "n_outages": len(windows),
        "non_outage_rms_h_m": _rms(hz[guarded]),
        "non_outage_rms_h_no_guard_m": _rms(hz[outside]),
        "non_outage_rms_v_m": _rms(up[guarded]),
    }
    cols = ["end_h_err_m", "max_h_err_m", "rms_h_err_m"]
    if "end_h_err_sigma_ratio" in table.columns:
        cols.append("end_h_err_sigma_ratio")
    for col in cols:
        v = table[col].to_numpy(float) if len(table) else np.array([])
        v = v[np.isfinite(v)]
        summary[f"{col}_mean"] = float(np.mean(v)) if v.size else float("nan")
        summary[f"{col}_median"] = float(np.median(v)) if v.size else float("nan")
        summary[f"{col}_max"] = float(np.max(v)) if v.size else float("nan")
    if "end_within_3sigma" in table.columns:
        w = table["end_within_3sigma"].dropna()
        summary["end_within_3sigma_fraction"] = float(w.astype(float).mean()) if len(w) \
            else float("nan")
    return table, summary


#: 2-dof chi-square point of the 3-sigma probability (99.73 %): the horizontal "3 sigma" test
CHI2_2DOF_3SIGMA = 11.829


def _end_consistency(err: pd.Series, sig: np.ndarray) -> dict:
    """Filter consistency at an outage end: the horizontal sigma ``hypot(east_std,
    north_std)``, the ratio of the error to it (about 1 for an honest filter, RMS over
    outages) and the 3-sigma test ``(e_E / s_E)^2 + (e_N / s_N)^2 <= chi2_2(99.73 %)`` (the
    two-axis form of "within 3 sigma"; the stds' correlation is not in the output tables)."""
    s_h = float(np.hypot(sig[0], sig[1]))
    ok = bool(np.all(np.isfinite(sig)) and np.all(sig > 0))
    d2 = float((err["east"] / sig[0]) ** 2 + (err["north"] / sig[1]) ** 2) if ok else np.nan
    return {"end_h_sigma_m": s_h,
            "end_h_err_sigma_ratio": float(err["horizontal"]) / s_h if s_h > 0 else np.nan,
            "end_within_3sigma": (d2 <= CHI2_2DOF_3SIGMA) if np.isfinite(d2) else None}


def _rms(x) -> float:
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def error_summary(errors: pd.DataFrame) -> dict:
    """RMS and max of the horizontal and vertical errors."""
    hz = errors["horizontal"].dropna().to_numpy()
    up = errors["up"].dropna().to_numpy()
    return {"rms_h_m": _rms(hz), "max_h_m": float(hz.max()) if hz.size else float("nan"),
            "rms_v_m": _rms(up), "n_epochs": int(hz.size)}
