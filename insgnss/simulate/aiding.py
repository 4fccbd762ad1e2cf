"""Aiding-sensor synthesis from a truth trajectory: GNSS, odometer, magnetometer heading.

GNSS
----
Epochs on a grid of ``1 / rate`` seconds from the start of the truth, each taken at the truth
sample nearest to the grid time (the truth runs at the IMU rate, so the sample is exact when the
IMU rate is a multiple of the GNSS rate). The antenna at lever arm ``l`` (body frame RFU, from the
IMU to the antenna phase centre) is at::

    r_ant^e = r_imu^e + C_l^e C_b^l l           (exact, through ECEF)
    v_ant^l = v_imu^l + C_b^l (omega_lb^b x l)   (omega_lb^b from the truth attitude, central
                                                  differences; omega_el is neglected: < 1e-5 m/s)

Noise: per axis ENU position errors with standard deviations ``(east_std, north_std, up_std)``
(``horizontal_std`` and ``vertical_std``, times the factor of any ``degraded`` window). With
``correlation_time > 0`` the errors are first-order Gauss-Markov (stationary, same std) as for
real single-point / float solutions; with 0 they are white. The declared ``*_std`` columns carry
the same standard deviations, so the normalised errors of an undisturbed run are N(0, 1)
(checked by a chi-square test). Velocity errors are white with ``velocity_std`` /
``vertical_velocity_std``.

Outages remove epochs: explicit ``[start, stop)`` windows and/or a periodic schedule (first
outage at ``start``, each ``length`` long, separated by ``gap`` seconds of GNSS, none starting
later than ``stop_before_end`` before the end of the run). All times are relative to the start of
the truth.

Multipath-like outliers: bursts that start at an epoch with probability ``outlier_probability``
and last a geometric number of epochs of mean ``outlier_duration``; during a burst a constant
offset of ``outlier_magnitude`` metres in a random direction (vertical component doubled, as in
real multipath geometry) is added to the noise. Affected epochs have ``outlier = 1``; their
declared std is *not* inflated, so that they test innovation gating.

Odometer
--------
Forward body speed of the odometer point (lever arm ``l`` from the IMU, body frame):
``v_odo = [C_b^l^T v^l + omega_lb^b x l]_forward``, scaled by ``(1 + s)`` (scale-factor error,
fixed or drawn) plus white noise, quantized to ``speed_quantum``. Distance increments
(``distance``, over the interval that ends at the epoch) are the trapezoidal integral of the true
forward speed on the truth samples, scaled, quantized to whole encoder pulses of
``distance_quantum`` metres with the residual carried over, plus optional white noise.

Magnetometer heading
--------------------
``heading_m = heading + declination_error + deviation sin(heading + phase) + n``, wrapped to
``[0, 2 pi)``: a constant declination offset (the error of the declination model), an optional
one-cycle compass deviation (residual hard iron) and white noise. ``heading_std`` declares the
noise std only.

References
----------
- Groves 2013, sections 9.4 (GNSS error models), 6.1 (magnetic heading), 6.3 (odometers), 14.3
  (lever arms).
- RTKLIB position output (quality flag ``q``: 1 fix, 2 float, 5 single).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..attitude import dcm_to_rotvec, euler_to_dcm
from ..earth import (
    ecef_to_enu_vectors,
    ecef_to_geodetic,
    enu_displacement_to_geodetic,
    enu_to_ecef_vectors,
    geodetic_to_ecef,
)
from ..outages import periodic_windows as _periodic
from .sensors import gauss_markov

GNSS_POS_COLS = ["lat", "lon", "height", "east_std", "north_std", "up_std"]
GNSS_VEL_COLS = ["vel_e", "vel_n", "vel_u", "vel_e_std", "vel_n_std", "vel_u_std"]


# --- shared helpers -----------------------------------------------------------------------------
def _attitude(truth: pd.DataFrame, idx: np.ndarray | None = None) -> np.ndarray:
    r, p, h = (truth[c].to_numpy(float) for c in ("roll", "pitch", "heading"))
    if idx is not None:
        r, p, h = r[idx], p[idx], h[idx]
    return euler_to_dcm(r, p, h)


def body_rate_lb(truth: pd.DataFrame, idx: np.ndarray) -> np.ndarray:
    """Angular rate of the body relative to the local-level frame, body axes [rad/s], at the
    truth samples ``idx``, by central differences of the attitude (one-sided at the ends)."""
    n = len(truth)
    t = truth.index.to_numpy(float)
    i0 = np.clip(idx - 1, 0, n - 1)
    i1 = np.clip(idx + 1, 0, n - 1)
    same = i0 == i1
    i1 = np.where(same, np.clip(i1 + 1, 0, n - 1), i1)
    C0 = _attitude(truth, i0)
    C1 = _attitude(truth, i1)
    rv = dcm_to_rotvec(np.swapaxes(C0, 1, 2) @ C1)
    return rv / (t[i1] - t[i0])[:, None]


def _time_mask(tr: np.ndarray, windows) -> np.ndarray:
    """True where ``tr`` falls inside one of the ``[start, stop)`` windows."""
    mask = np.zeros(tr.size, bool)
    for start, stop in windows:
        mask |= (tr >= start) & (tr < stop)
    return mask


def periodic_windows(duration: float, start: float, length: float, gap: float,
                     stop_before_end: float = 0.0) -> list[tuple[float, float]]:
    """Outage windows ``[s, s + length)`` for ``s = start, start + length + gap, ...`` [s from
    the first sample], with the same rule as processing jobs (:func:`insgnss.outages.
    periodic_windows`): no outage starts at or after ``duration - stop_before_end``, and one
    still running there is cut."""
    return _periodic(0.0, duration, start, length, gap, stop_before_end)


def _epochs(t: np.ndarray, rate: float) -> np.ndarray:
    """Indices of truth samples nearest to a ``1/rate`` grid from the first sample."""
    if not rate > 0:
        raise ValueError(f"rate must be positive; got {rate}")
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * rate + 1e-9)) + 1) / rate
    idx = np.clip(np.searchsorted(t, grid), 0, t.size - 1)
    prev = np.clip(idx - 1, 0, t.size - 1)
    idx = np.where(np.abs(t[prev] - grid) < np.abs(t[idx] - grid), prev, idx)
    return np.unique(idx)


# --- GNSS ---------------------------------------------------------------------------------------
def antenna_position(truth: pd.DataFrame, idx: np.ndarray, lever_arm) -> np.ndarray:
    """Geodetic position (N, 3: lat, lon, h) of a point at ``lever_arm`` (body RFU, m) from the
    IMU, at truth samples ``idx``; exact through ECEF."""
    lat = truth["lat"].to_numpy(float)[idx]
    lon = truth["lon"].to_numpy(float)[idx]
    h = truth["height"].to_numpy(float)[idx]
    l = np.asarray(lever_arm, float)
    if not np.any(l):
        return np.column_stack([lat, lon, h])
    d = _enu_to_ecef(_attitude(truth, idx) @ l, lat, lon)
    x, y, z = geodetic_to_ecef(lat, lon, h)
    la, lo, hh = ecef_to_geodetic(x + d[:, 0], y + d[:, 1], z + d[:, 2])
    return np.column_stack([la, lo, hh])


_enu_to_ecef = enu_to_ecef_vectors
_ecef_to_enu = ecef_to_enu_vectors


def antenna_velocity(truth: pd.DataFrame, idx: np.ndarray, lever_arm) -> np.ndarray:
    """ENU velocity (N, 3) of the point at ``lever_arm`` at truth samples ``idx``."""
    v = truth[["vel_e", "vel_n", "vel_u"]].to_numpy(float)[idx]
    l = np.asarray(lever_arm, float)
    if not np.any(l):
        return v
    w = body_rate_lb(truth, idx)
    return v + np.einsum("kij,kj->ki", _attitude(truth, idx), np.cross(w, l))


def simulate_gnss(
    truth: pd.DataFrame,
    rng: np.random.Generator | int | None = None,
    *,
    rate: float = 1.0,
    horizontal_std: float = 1.5,
    vertical_std: float = 3.0,
    correlation_time: float = 0.0,
    velocity: bool = False,
    velocity_std: float = 0.05,
    vertical_velocity_std: float | None = None,
    lever_arm: Sequence[float] = (0.0, 0.0, 0.0),
    outages: Sequence[Sequence[float]] = (),
    periodic_outages: dict | None = None,
    degraded: Sequence[dict] = (),
    outlier_probability: float = 0.0,
    outlier_duration: float = 3.0,
    outlier_magnitude: float = 20.0,
    q: int = 5,
    ns: int | None = None,
) -> pd.DataFrame:
    """Simulated GNSS solutions (see the module docstring for the model).

    Parameters
    ----------
    truth : DataFrame
        Truth trajectory (NAV_COLS) indexed by time.
    rng : Generator or seed
    rate : float
        Output rate [Hz].
    horizontal_std, vertical_std : float
        Position error std [m] (east and north share ``horizontal_std``).
    correlation_time : float
        Gauss-Markov correlation time of the position errors [s]; 0 for white errors.
    velocity : bool
        Also output ``vel_e vel_n vel_u`` and their std.
    velocity_std, vertical_velocity_std : float
        Velocity error std [m/s] (vertical defaults to twice the horizontal).
    lever_arm : 3 floats
        Antenna position relative to the IMU, body frame RFU [m].
    outages : list of [start, stop]
        Explicit outage windows [s from the start].
    periodic_outages : dict, optional
        ``{start, length, gap, stop_before_end}`` [s].
    degraded : list of dict
        ``{start, stop, factor}``: std multiplied by ``factor`` (declared and actual) in the window.
    outlier_probability, outlier_duration, outlier_magnitude
        Multipath-like bursts: onset probability per epoch, mean length [epochs], offset [m].
    q, ns : int
        RTKLIB quality flag written to every epoch, and (optionally) a satellite count.

    Returns
    -------
    DataFrame
        Indexed by time: ``lat lon height east_std north_std up_std`` [rad, m],
        optional ``vel_e vel_n vel_u vel_e_std vel_n_std vel_u_std``, ``q``, optional ``ns``,
        ``outlier`` (0/1).
    """
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    s_noise, s_vel, s_out = rng.spawn(3)
    t = truth.index.to_numpy(float)
    idx = _epochs(t, rate)
    te = t[idx]
    tr = te - t[0]
    n = idx.size
    std = np.empty((n, 3))
    std[:, :2] = horizontal_std
    std[:, 2] = vertical_std
    factor = np.ones(n)
    for d in degraded:
        factor = np.where(_time_mask(tr, [(d["start"], d["stop"])]), factor * d["factor"], factor)
    std *= factor[:, None]
    # position errors (unit-variance, white or Gauss-Markov), scaled per epoch
    if correlation_time > 0:
        unit = gauss_markov(s_noise, n, 1.0 / rate, 1.0, correlation_time, 3)
    else:
        unit = s_noise.standard_normal((n, 3))
    err = unit * std
    # multipath-like bursts
    outlier = np.zeros(n, bool)
    if outlier_probability > 0:
        onset = s_out.random(n) < outlier_probability
        lengths = s_out.geometric(1.0 / max(outlier_duration, 1.0), n)
        direction = s_out.standard_normal((n, 3))
        direction[:, 2] *= 2.0
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        for k in np.flatnonzero(onset):  # one iteration per burst (rare), not per sample
            e = min(k + int(lengths[k]), n)
            err[k:e] += direction[k] * outlier_magnitude
            outlier[k:e] = True
    pos = antenna_position(truth, idx, lever_arm)
    dlat, dlon, dh = enu_displacement_to_geodetic(pos[:, 0], pos[:, 2], err[:, 0], err[:, 1],
                                                  err[:, 2])
    cols = {"lat": pos[:, 0] + dlat, "lon": pos[:, 1] + dlon, "height": pos[:, 2] + dh,
            "east_std": std[:, 0], "north_std": std[:, 1], "up_std": std[:, 2]}
    if velocity:
        vstd = np.empty((n, 3))
        vstd[:, :2] = velocity_std
        vstd[:, 2] = 2.0 * velocity_std if vertical_velocity_std is None else vertical_velocity_std
        vstd *= factor[:, None]
        vel = antenna_velocity(truth, idx, lever_arm) + s_vel.standard_normal((n, 3)) * vstd
        cols.update({"vel_e": vel[:, 0], "vel_n": vel[:, 1], "vel_u": vel[:, 2],
                     "vel_e_std": vstd[:, 0], "vel_n_std": vstd[:, 1], "vel_u_std": vstd[:, 2]})
    cols["q"] = np.full(n, float(q))
    if ns is not None:
        cols["ns"] = np.full(n, float(ns))
    cols["outlier"] = outlier.astype(float)
    df = pd.DataFrame(cols, index=pd.Index(te, name="time"))
    windows = [tuple(map(float, w)) for w in outages]
    if periodic_outages:
        po = periodic_outages
        windows += periodic_windows(t[-1] - t[0], po["start"], po["length"], po["gap"],
                                    po.get("stop_before_end", 0.0))
    if windows:
        df = df[~_time_mask(tr, windows)]
    return df


def gnss_errors_enu(gnss: pd.DataFrame, truth: pd.DataFrame, lever_arm=(0.0, 0.0, 0.0)) -> np.ndarray:
    """ENU position errors [m] (N, 3) of GNSS solutions against the truth antenna position at the
    same time stamps (exact ECEF difference rotated to the local ENU)."""
    t = truth.index.to_numpy(float)
    idx = np.searchsorted(t, gnss.index.to_numpy(float))
    ref = antenna_position(truth, idx, lever_arm)
    xg = np.column_stack(geodetic_to_ecef(*(gnss[c].to_numpy(float) for c in ("lat", "lon", "height"))))
    xr = np.column_stack(geodetic_to_ecef(ref[:, 0], ref[:, 1], ref[:, 2]))
    return _ecef_to_enu(xg - xr, ref[:, 0], ref[:, 1])


# --- odometer -----------------------------------------------------------------------------------
def forward_speed(truth: pd.DataFrame, lever_arm=(0.0, 0.0, 0.0), idx: np.ndarray | None = None):
    """True forward (body y) speed [m/s] of the point at ``lever_arm`` at samples ``idx``."""
    if idx is None:
        idx = np.arange(len(truth))
    v = truth[["vel_e", "vel_n", "vel_u"]].to_numpy(float)[idx]
    C = _attitude(truth, idx)
    vb = np.einsum("kji,kj->ki", C, v)
    l = np.asarray(lever_arm, float)
    if np.any(l):
        vb = vb + np.cross(body_rate_lb(truth, idx), l)
    return vb[:, 1]


def simulate_odometer(
    truth: pd.DataFrame,
    rng: np.random.Generator | int | None = None,
    *,
    rate: float = 10.0,
    output: str = "speed",
    scale_factor: float | None = None,
    scale_factor_std: float = 0.0,
    noise_std: float = 0.0,
    speed_quantum: float = 0.0,
    distance_quantum: float = 0.0,
    distance_noise_std: float = 0.0,
    lever_arm: Sequence[float] = (0.0, 0.0, 0.0),
) -> tuple[pd.DataFrame, dict]:
    """Simulated odometer: forward speed and/or distance increments.

    Parameters
    ----------
    output : {"speed", "distance", "both"}
    scale_factor : float, optional
        Fixed scale-factor error (fraction); if None it is drawn ``N(0, scale_factor_std^2)``.
    noise_std : float
        White noise on the speed [m/s].
    speed_quantum : float
        Speed resolution [m/s] (0: none).
    distance_quantum : float
        Distance per encoder pulse [m] (0: none); the residual is carried over.
    distance_noise_std : float
        White noise on each distance increment [m].
    lever_arm : 3 floats
        Odometer reference point relative to the IMU, body RFU [m].

    Returns
    -------
    (DataFrame, dict)
        Table indexed by time with ``speed`` [m/s] and/or ``distance`` [m]; the drawn parameters
        (``scale_factor``).
    """
    if output not in ("speed", "distance", "both"):
        raise ValueError(f"odometer output must be speed, distance or both; got {output!r}")
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    s_sf, s_noise, s_dist = rng.spawn(3)
    sf = float(s_sf.standard_normal() * scale_factor_std) if scale_factor is None else float(scale_factor)
    t = truth.index.to_numpy(float)
    idx = _epochs(t, rate)
    cols = {}
    if output in ("speed", "both"):
        v = forward_speed(truth, lever_arm, idx) * (1.0 + sf)
        v = v + s_noise.standard_normal(idx.size) * noise_std
        if speed_quantum > 0:
            v = np.round(v / speed_quantum) * speed_quantum
        cols["speed"] = v
    if output in ("distance", "both"):
        vf = forward_speed(truth, lever_arm)
        travelled = np.concatenate([[0.0], np.cumsum(0.5 * (vf[1:] + vf[:-1]) * np.diff(t))])
        s = travelled[idx] * (1.0 + sf)
        if distance_quantum > 0:
            s = np.round(s / distance_quantum) * distance_quantum
        d = np.diff(s, prepend=s[0])
        d = d + s_dist.standard_normal(idx.size) * distance_noise_std
        d[0] = 0.0
        cols["distance"] = d
    df = pd.DataFrame(cols, index=pd.Index(t[idx], name="time"))
    return df, {"scale_factor": sf}


# --- magnetometer heading -----------------------------------------------------------------------
def simulate_magnetometer(
    truth: pd.DataFrame,
    rng: np.random.Generator | int | None = None,
    *,
    rate: float = 10.0,
    noise_std: float = np.radians(2.0),
    declination_error: float = 0.0,
    deviation: float = 0.0,
    deviation_phase: float = 0.0,
) -> pd.DataFrame:
    """Simulated magnetic heading (corrected for the modelled declination) [rad].

    ``declination_error`` is the constant error left after the declination correction,
    ``deviation`` the amplitude of a one-cycle compass deviation ``sin(heading + phase)``.
    Returns a table with ``heading`` (wrapped to [0, 2 pi)) and ``heading_std`` (= noise_std).
    """
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    t = truth.index.to_numpy(float)
    idx = _epochs(t, rate)
    h = truth["heading"].to_numpy(float)[idx]
    meas = (h + declination_error + deviation * np.sin(h + deviation_phase)
            + rng.standard_normal(idx.size) * noise_std)
    return pd.DataFrame({"heading": np.mod(meas, 2.0 * np.pi),
                         "heading_std": np.full(idx.size, float(noise_std))},
                        index=pd.Index(t[idx], name="time"))
