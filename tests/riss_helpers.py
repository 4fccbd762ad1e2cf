"""Test helpers for RISS: an analytic land-vehicle drive (no side slip, no vertical body velocity)
with turns, slopes below 10 % and a varying roll, and its exact IMU by inverse mechanization."""

from __future__ import annotations

import numpy as np
import pandas as pd

from insgnss.mechanization.inverse import integrate_position, inverse_mechanize
from insgnss.mechanization.strapdown import NavState

LAT0 = np.radians(51.08)
LON0 = np.radians(-114.13)
H0 = 1100.0

#: (start [s], duration [s], heading change [rad]) of the turns
TURNS = [(20.0, 8.0, np.pi / 2), (70.0, 10.0, -np.pi / 2), (120.0, 6.0, np.pi / 2),
         (180.0, 20.0, np.pi), (260.0, 8.0, -np.pi / 2), (330.0, 12.0, -np.pi / 2),
         (400.0, 30.0, 2 * np.pi / 3), (470.0, 8.0, np.pi / 2), (540.0, 15.0, -np.pi)]


def _bump_integral(t, t0, T, total):
    """Integral of a raised-cosine rate bump of area ``total`` on [t0, t0+T] (and the rate)."""
    x = np.clip(t - t0, 0.0, T)
    val = total / T * (x - T / (2 * np.pi) * np.sin(2 * np.pi * x / T))
    inside = (t > t0) & (t < t0 + T)
    rate = np.where(inside, total / T * (1 - np.cos(2 * np.pi * (t - t0) / T)), 0.0)
    return val, rate


def land_vehicle_drive(duration=600.0, rate=100.0, heading0=0.3, speed_scale=1.0):
    """Truth table (NAV_COLS) and odometer speed [m/s] of a land-vehicle drive.

    Speed 3-19 m/s, nine turns (rates up to 0.4 rad/s), slopes up to 9 % (pitch < 0.09 rad),
    roll up to 0.05 rad. Position by :func:`integrate_position` (consistent with the forward
    mechanization), so ``inverse_mechanize`` gives its exact IMU.
    """
    t = np.arange(int(round(duration * rate)) + 1) / rate
    speed = speed_scale * (11.0 + 6.0 * np.sin(2 * np.pi * t / 97.0) - 2.0 * np.cos(2 * np.pi * t / 31.0))
    heading = np.full_like(t, heading0)
    for t0, T, ang in TURNS:
        if t0 + T <= duration:
            val, _ = _bump_integral(t, t0, T, ang)
            heading += val
    pitch = 0.055 * np.sin(2 * np.pi * t / 170.0) + 0.03 * np.sin(2 * np.pi * t / 53.0 + 1.0)
    roll = 0.035 * np.sin(2 * np.pi * t / 41.0 + 0.3) + 0.015 * np.sin(2 * np.pi * t / 13.0)
    vel = np.column_stack([speed * np.sin(heading) * np.cos(pitch),
                           speed * np.cos(heading) * np.cos(pitch), speed * np.sin(pitch)])
    pos = integrate_position(t, vel, LAT0, LON0, H0)
    truth = pd.DataFrame({"lat": pos[:, 0], "lon": pos[:, 1], "height": pos[:, 2],
                          "vel_e": vel[:, 0], "vel_n": vel[:, 1], "vel_u": vel[:, 2],
                          "roll": roll, "pitch": pitch, "heading": np.mod(heading, 2 * np.pi)},
                         index=pd.Index(t, name="time"))
    return truth, speed


def perfect_drive(duration=600.0, rate=100.0):
    """(truth, imu increments, odometer DataFrame, initial NavState) of :func:`land_vehicle_drive`."""
    truth, speed = land_vehicle_drive(duration, rate)
    imu = inverse_mechanize(truth)
    odo = pd.DataFrame({"speed": speed}, index=truth.index)
    return truth, imu, odo, initial_state(truth)


def initial_state(truth: pd.DataFrame, k: int = 0) -> NavState:
    r = truth.iloc[k]
    return NavState.from_euler(r.lat, r.lon, r.height, (r.vel_e, r.vel_n, r.vel_u), r.roll,
                               r.pitch, r.heading, time=float(truth.index[k]))


def enu_error(est: pd.DataFrame, ref: pd.DataFrame) -> np.ndarray:
    """(N, 3) ENU position error [m] of ``est`` against ``ref`` (local radii)."""
    from insgnss.earth import radii

    lat = ref["lat"].to_numpy()
    M, N = radii(lat)
    h = ref["height"].to_numpy()
    dn = (est["lat"].to_numpy() - lat) * (M + h)
    de = (est["lon"].to_numpy() - ref["lon"].to_numpy()) * (N + h) * np.cos(lat)
    du = est["height"].to_numpy() - h
    return np.column_stack([de, dn, du])


def add_riss_sensor_errors(imu, speed, model, rng, *, odometer_scale=0.01, odometer_std=0.02,
                           gyro_scale_z=0.0, full_imu=False, draws=None):
    """Noisy RISS sensors with known truth: vertical gyro and horizontal accelerometers (all six
    axes with ``full_imu``) with turn-on bias + first-order Gauss-Markov instability + white
    noise (the filters' model),
    odometer ``(1 + k) v + n``. Returns (imu, odometer DataFrame, bias DataFrame with the totals
    ``gyro_bias_z accel_bias_x accel_bias_y`` and the parts ``*_gm``, ``*_turn_on``).
    ``draws`` may give the standard-normal draws of the turn-on biases and of the initial
    Gauss-Markov values (``{name: (turn_on, gm0)}``)."""
    from scipy.signal import lfilter

    t = imu.index.to_numpy()
    dt = np.r_[0.0, np.diff(t)]
    n = t.size
    phi = np.exp(-np.median(dt[1:]) / model.bias_correlation_time)

    def gm(sigma, x0):
        w = rng.standard_normal(n) * sigma * np.sqrt(1 - phi**2)
        w[0] = x0 * sigma
        return lfilter([1.0], [1.0, -phi], w)

    parts = {}
    out = imu.copy()
    for ax in ("z", "x", "y") if not full_imu else ("x", "y", "z"):
        for kind, col, b0, bi, wn in (
                ("gyro", "dtheta", model.gyro_bias, model.gyro_bias_instability, model.gyro_arw),
                ("accel", "dv", model.accel_bias, model.accel_bias_instability, model.accel_vrw)):
            if not full_imu and (kind, ax) not in (("gyro", "z"), ("accel", "x"), ("accel", "y")):
                continue
            name = f"{kind}_bias_{ax}"
            d_on, d_gm = (draws or {}).get(name, rng.standard_normal(2))
            parts[name + "_turn_on"] = np.full(n, d_on * b0)
            parts[name + "_gm"] = gm(bi, d_gm)
            parts[name] = parts[name + "_turn_on"] + parts[name + "_gm"]
            scale = 1.0 + (gyro_scale_z if name == "gyro_bias_z" else 0.0)
            out[f"{col}_{ax}"] = (scale * imu[f"{col}_{ax}"] + parts[name] * dt
                                  + rng.standard_normal(n) * wn * np.sqrt(dt))
    odo = pd.DataFrame({"speed": (1 + odometer_scale) * speed + rng.standard_normal(n) * odometer_std},
                       index=imu.index)
    return out, odo, pd.DataFrame(parts, index=imu.index)


def gnss_from_truth(truth, rng, *, rate=1.0, pos_std=(0.5, 0.5, 1.0), vel_std=0.05,
                    outages=()):
    """GNSS position + velocity at ``rate`` from the truth with white noise; ``outages`` is a
    list of (start, end) times without GNSS."""
    from insgnss.earth import radii

    t = truth.index.to_numpy()
    step = int(round(1.0 / rate / np.median(np.diff(t))))
    g = truth.iloc[step::step]
    tg = g.index.to_numpy()
    keep = np.ones(tg.size, bool)
    for a, b in outages:
        keep &= ~((tg >= a) & (tg < b))
    g = g[keep]
    m = len(g)
    lat = g.lat.to_numpy()
    M, N = radii(lat)
    h = g.height.to_numpy()
    ps = np.asarray(pos_std, float)
    e = rng.standard_normal((m, 3)) * ps
    v = rng.standard_normal((m, 3)) * vel_std
    return pd.DataFrame({
        "lat": lat + e[:, 1] / (M + h), "lon": g.lon.to_numpy() + e[:, 0] / ((N + h) * np.cos(lat)),
        "height": h + e[:, 2], "east_std": ps[0], "north_std": ps[1], "up_std": ps[2],
        "vel_e": g.vel_e.to_numpy() + v[:, 0], "vel_n": g.vel_n.to_numpy() + v[:, 1],
        "vel_u": g.vel_u.to_numpy() + v[:, 2], "vel_e_std": vel_std, "vel_n_std": vel_std,
        "vel_u_std": vel_std}, index=g.index)


def riss_state_errors(res, truth, bias, k_true, gyro_scale_true=0.0):
    """(n_ep, n) true errors (nominal minus truth) of the forward RISS filter at its epochs, in
    the order of the RISS layout (bias parts from ``res.params``)."""
    lay = res.layout
    ep = res.epoch_times
    fwd = res.forward.loc[ep]
    tr = truth.loc[ep]
    b = bias.loc[ep]
    par = res.params
    e = np.zeros((len(ep), lay.n))
    e[:, 0:3] = enu_error(fwd, tr)
    e[:, 3:6] = fwd[["vel_e", "vel_n", "vel_u"]].to_numpy() - tr[["vel_e", "vel_n", "vel_u"]].to_numpy()
    e[:, 6] = np.angle(np.exp(1j * (fwd.heading.to_numpy() - tr.heading.to_numpy())))
    e[:, 7] = par[:, 0] - k_true
    names = ("gyro_bias_z", "accel_bias_x", "accel_bias_y")
    if lay.turn_on:
        t0 = lay["bias_turn_on"].start
        for i, nm in enumerate(names):
            e[:, 8 + i] = par[:, 5 + i] - b[nm + "_gm"].to_numpy()
            e[:, t0 + i] = par[:, 8 + i] - b[nm + "_turn_on"].to_numpy()
    else:
        for i, nm in enumerate(names):
            e[:, 8 + i] = par[:, 1 + i] - b[nm].to_numpy()
    if lay.gyro_scale:
        e[:, 11] = par[:, 4] - gyro_scale_true
    return e


def nees(errors, P):
    """Per-epoch NEES ``e^T P^-1 e`` for stacked errors (n_ep, n) and covariances (n_ep, n, n)."""
    return np.einsum("ki,ki->k", errors, np.linalg.solve(P, errors[..., None])[..., 0])


def output_map(layout):
    """(11, n) map from the RISS error state to the reported quantities: position, velocity,
    heading, odometer scale and the three *total* biases (Gauss-Markov + turn-on parts)."""
    A = np.zeros((11, layout.n))
    A[:, :11] = np.eye(11)
    if layout.turn_on:
        t0 = layout["bias_turn_on"].start
        A[8, t0] = A[9, t0 + 1] = A[10, t0 + 2] = 1.0
    return A


def riss_monte_carlo(n_runs, duration, model, *, seed=0, config_kw=None, riss_kw=None,
                     rate=100.0, outages=(), drive=None, gnss_kw=None, reported=False):
    """Monte Carlo of the RISS filter on :func:`land_vehicle_drive` with errors drawn from the
    filter's own model (initial heading and position errors, biases, odometer scale factor).
    Returns the per-run NEES (n_runs, n_ep), the epoch times and the last result. With
    ``reported`` the NEES is that of the 11 reported quantities (:func:`output_map`), else of
    the full error state.

    The constant quantities (turn-on biases, initial Gauss-Markov values, odometer scale factor,
    initial position and heading errors) are drawn moment-matched: for each of them the N
    standard-normal draws are rescaled to a mean square of exactly 1 (variance reduction; a
    handful of persistent, barely observable draws would otherwise decide the NEES of every
    epoch of a small Monte Carlo)."""
    from insgnss.earth import radii
    from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity
    from insgnss.filter.riss_model import RissConfig, run_riss_filter
    from insgnss.mechanization.riss import riss_inputs

    truth, imu, odo, _ = drive if drive is not None else perfect_drive(duration, rate)
    rng = np.random.default_rng(seed)
    kw = dict(imu_model=model, initial_pos_std=1.0,
              initial_att_std=(0.01, 0.01, np.radians(2.0)), smoother=False)
    kw.update(config_kw or {})
    cfg = FilterConfig(**kw)
    rkw = dict(odometer_speed_std=0.02, odometer_scale_std=0.02)
    rkw.update(riss_kw or {})
    rcfg = RissConfig(**rkw)
    out = []
    r0 = truth.iloc[0]
    M, N = radii(r0.lat)
    const = rng.standard_normal((11, n_runs))
    const /= np.sqrt(np.mean(const**2, axis=1, keepdims=True))
    for i in range(n_runs):
        k_true = const[0, i] * rcfg.odometer_scale_std
        draws = {"gyro_bias_z": const[1:3, i], "accel_bias_x": const[3:5, i],
                 "accel_bias_y": const[5:7, i]}
        imu_n, odo_n, bias = add_riss_sensor_errors(imu, odo.speed.to_numpy(), model, rng,
                                                    odometer_scale=k_true,
                                                    odometer_std=rcfg.odometer_speed_std,
                                                    draws=draws)
        gnss = gnss_from_truth(truth, rng, outages=outages, **(gnss_kw or {}))
        d = const[7:11, i]
        s0 = cfg.initial_pos_std
        init_n = NavState.from_euler(
            r0.lat + d[1] * s0 / (M + r0.height),
            r0.lon + d[0] * s0 / ((N + r0.height) * np.cos(r0.lat)), r0.height + d[2] * s0,
            (0, 0, 0), r0.roll, r0.pitch, r0.heading + d[3] * cfg.initial_att_std[2])
        inputs = riss_inputs(imu_n, odo_n, window=rcfg.window)
        res = run_riss_filter(imu_n, odo_n, init_n, [GnssPosition(gnss), GnssVelocity(gnss)], cfg,
                              rcfg, inputs=inputs)
        e = riss_state_errors(res, truth, bias, k_true)
        if reported:
            A = output_map(res.layout)
            out.append(nees(e @ A.T, A @ res.P_filtered @ A.T))
        else:
            out.append(nees(e, res.P_filtered))
    return np.array(out), res.epoch_times, res
