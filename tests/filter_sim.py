"""Small, seeded simulation helpers for the filter tests and benchmark.

Truth is built from smooth closed-form kinematic channels, positions by
:func:`insgnss.mechanization.inverse.integrate_position`, and error-free IMU increments by
:func:`insgnss.mechanization.inverse.inverse_mechanize`, so the forward mechanization of the
clean increments reproduces the truth to rounding. Sensor errors are added with the same
models the filter assumes (Gauss-Markov biases started from the filter's initial
distribution, white ARW / VRW), which is what consistency (NEES/NIS) tests need.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from insgnss.attitude import attitude_error, euler_to_dcm, rotvec_to_dcm
from insgnss.earth import enu_displacement_to_geodetic, radii
from insgnss.imu import ImuErrorModel, increments, increments_table
from insgnss.mechanization.inverse import integrate_position, inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS, NavState

DEG = np.pi / 180.0


def _window(t, stops, ramp):
    """1 while moving, 0 in each stop interval, raised-cosine transitions of ``ramp`` s."""
    w = np.ones_like(t)
    for a, b in stops:
        u_in = np.clip((t - (a - ramp)) / ramp, 0, 1)  # 0 -> 1 entering the stop
        u_out = np.clip((t - b) / ramp, 0, 1)  # 0 -> 1 leaving the stop
        down = 0.5 * (1 + np.cos(np.pi * u_in))  # 1 -> 0
        up = 0.5 * (1 - np.cos(np.pi * u_out))  # 0 -> 1
        f = np.where(t < b, down, up)
        w = w * f
    return w


def car_truth(duration=300.0, rate=50.0, stops=(), speed=12.0, turn_rate=0.08, start_time=0.0,
              lat0=45.0 * DEG, lon0=7.0 * DEG, h0=250.0, heading0=30.0 * DEG, ramp=8.0,
              start_at_rest=False) -> pd.DataFrame:
    """A manoeuvring car: varying speed, S-turns, gentle hills, optional stops."""
    n = int(round(duration * rate)) + 1
    t = start_time + np.arange(n) / rate
    tr = t - start_time
    stops_rel = [(a - start_time, b - start_time) for a, b in stops]
    if start_at_rest:
        stops_rel = [(-2 * ramp, 0.0)] + stops_rel
    w = _window(tr, stops_rel, ramp)
    v = w * (speed + 0.35 * speed * np.sin(2 * np.pi * tr / 47.0))
    psid = w * turn_rate * (np.sin(2 * np.pi * tr / 41.0) + 0.5 * np.sin(2 * np.pi * tr / 13.0 + 1.0))
    heading = heading0 + np.concatenate([[0.0], np.cumsum(0.5 * (psid[1:] + psid[:-1]) * np.diff(tr))])
    pitch = 0.03 * np.sin(2 * np.pi * tr / 53.0)
    roll = -0.01 * psid * v / 2.0
    vh = v * np.cos(pitch)
    vel = np.column_stack([vh * np.sin(heading), vh * np.cos(heading), v * np.sin(pitch)])
    pos = integrate_position(t, vel, lat0, lon0, h0)
    df = pd.DataFrame(
        np.column_stack([pos, vel, roll, pitch, np.mod(heading, 2 * np.pi)]),
        index=pd.Index(t, name="time"), columns=NAV_COLS,
    )
    return df


def static_truth(duration=60.0, rate=100.0, lat0=45.0 * DEG, lon0=7.0 * DEG, h0=250.0,
                 roll=0.01, pitch=-0.02, heading=1.0) -> pd.DataFrame:
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    data = np.tile([lat0, lon0, h0, 0, 0, 0, roll, pitch, heading], (n, 1))
    return pd.DataFrame(data, index=pd.Index(t, name="time"), columns=NAV_COLS)


def _gm(rng, n, dt, x0, sigma, tau):
    """Discrete first-order Gauss-Markov paths (n, 3) starting at x0."""
    if sigma > 0 and np.isfinite(tau):
        a = np.exp(-dt / tau)
        w = rng.standard_normal((n, 3)) * sigma * np.sqrt(1 - a * a)
        w[0] = x0
        return lfilter([1.0], [1.0, -a], w, axis=0)
    return np.tile(np.asarray(x0, float), (n, 1))


def corrupt_imu(truth: pd.DataFrame, model: ImuErrorModel, rng: np.random.Generator,
                bias: str = "turn_on_gm", scale=False, bias0=None):
    """Sensor measurements (increment table) of a truth trajectory, and the true errors.

    Biases (``bias``):

    - ``"turn_on_gm"`` (default, what real sensors do): a constant turn-on bias
      ``N(0, turn_on^2)`` plus a stationary first-order Gauss-Markov instability
      ``(sigma, tau)``; the filter's ``random_walk`` model (PSD ``2 sigma^2 / tau``) is
      consistent with it for runs shorter than ``tau``;
    - ``"gm"``: a Gauss-Markov process started from ``N(0, turn_on^2 + sigma^2)``, exactly the
      filter's ``gauss_markov`` model;
    - ``"constant"``: ``N(0, turn_on^2 + sigma^2)`` held constant.

    ``bias0`` (6,) overrides the initial draw. White noise: ARW / VRW. Scale factors (if
    ``scale``): ``N(0, gyro_scale^2)`` etc., measured = (1 + s) true + b.

    Returns
    -------
    imu : DataFrame (increments)
    errors : dict with ``gyro_bias`` (N, 3), ``accel_bias`` (N, 3), ``gyro_scale``,
        ``accel_scale`` (3,)
    """
    clean = inverse_mechanize(truth)
    t, dth, dv = increments(clean)
    n = t.size
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    d0 = float(np.median(np.diff(t)))
    tau = model.bias_correlation_time
    out = []
    for turn_on, instab, k in ((model.gyro_bias, model.gyro_bias_instability, 0),
                               (model.accel_bias, model.accel_bias_instability, 3)):
        if bias == "turn_on_gm":
            b0 = rng.standard_normal(3) * turn_on if bias0 is None else np.asarray(bias0[k:k + 3], float)
            g0 = rng.standard_normal(3) * instab
            b = b0 + _gm(rng, n, d0, g0, instab, tau)
        elif bias == "gm":
            s0 = np.hypot(turn_on, instab)
            b0 = rng.standard_normal(3) * s0 if bias0 is None else np.asarray(bias0[k:k + 3], float)
            b = _gm(rng, n, d0, b0, instab, tau)
        elif bias == "constant":
            s0 = np.hypot(turn_on, instab)
            b0 = rng.standard_normal(3) * s0 if bias0 is None else np.asarray(bias0[k:k + 3], float)
            b = np.tile(b0, (n, 1))
        else:
            raise ValueError(bias)
        out.append(b)
    bg, ba = out
    sg = rng.standard_normal(3) * model.gyro_scale if scale else np.zeros(3)
    sa = rng.standard_normal(3) * model.accel_scale if scale else np.zeros(3)
    sq = np.sqrt(dt)[:, None]
    dth_m = dth * (1 + sg) + bg * dt[:, None] + rng.standard_normal((n, 3)) * model.gyro_arw * sq
    dv_m = dv * (1 + sa) + ba * dt[:, None] + rng.standard_normal((n, 3)) * model.accel_vrw * sq
    dth_m[0] = 0.0
    dv_m[0] = 0.0
    imu = increments_table(t, dth_m, dv_m)
    return imu, {"gyro_bias": bg, "accel_bias": ba, "gyro_scale": sg, "accel_scale": sa}


def gnss_from_truth(truth: pd.DataFrame, every: int, rng: np.random.Generator, pos_std=(1.0, 1.0, 2.0),
                    vel_std=(0.05, 0.05, 0.1), lever_arm=(0.0, 0.0, 0.0), start: int = 0,
                    omega_b=None) -> pd.DataFrame:
    """GNSS table sampled every ``every`` truth rows, with antenna lever arm and white noise.

    ``omega_b`` (N, 3) true body angular rate for the lever-arm velocity (optional).
    """
    rows = np.arange(start, len(truth), every)
    tr = truth.iloc[rows]
    C = euler_to_dcm(tr["roll"].to_numpy(), tr["pitch"].to_numpy(), tr["heading"].to_numpy())
    la = C @ np.asarray(lever_arm, float)
    ps = np.asarray(pos_std, float)
    vs = np.asarray(vel_std, float)
    noise = rng.standard_normal((rows.size, 3)) * ps
    d = la + noise
    lat = tr["lat"].to_numpy()
    h = tr["height"].to_numpy()
    dlat, dlon, dh = enu_displacement_to_geodetic(lat, h, d[:, 0], d[:, 1], d[:, 2])
    vel = tr[["vel_e", "vel_n", "vel_u"]].to_numpy()
    if omega_b is not None:
        vel = vel + np.einsum("kij,kj->ki", C, np.cross(omega_b[rows], np.asarray(lever_arm, float)))
    vel = vel + rng.standard_normal((rows.size, 3)) * vs
    df = pd.DataFrame({
        "lat": lat + dlat, "lon": tr["lon"].to_numpy() + dlon, "height": h + dh,
        "east_std": ps[0], "north_std": ps[1], "up_std": ps[2],
        "vel_e": vel[:, 0], "vel_n": vel[:, 1], "vel_u": vel[:, 2],
        "vel_e_std": vs[0], "vel_n_std": vs[1], "vel_u_std": vs[2],
    }, index=pd.Index(truth.index.to_numpy()[rows], name="time"))
    return df


def perturbed_initial(truth: pd.DataFrame, rng: np.random.Generator, pos_std=0.0, vel_std=0.0,
                      att_std=(0.0, 0.0, 0.0)) -> tuple[NavState, np.ndarray]:
    """Initial NavState with errors drawn from N(0, std^2) (nominal minus true convention).

    Returns the state and the drawn 9-vector error (dr ENU, dv, phi).
    """
    err = np.concatenate([rng.standard_normal(3) * np.broadcast_to(pos_std, 3),
                          rng.standard_normal(3) * np.broadcast_to(vel_std, 3),
                          rng.standard_normal(3) * np.broadcast_to(att_std, 3)])
    return initial_with_error(truth, err), err


def initial_with_error(truth: pd.DataFrame, err) -> NavState:
    r0 = truth.iloc[0]
    err = np.asarray(err, float)
    dlat, dlon, dh = enu_displacement_to_geodetic(r0["lat"], r0["height"], err[0], err[1], err[2])
    C = euler_to_dcm(r0["roll"], r0["pitch"], r0["heading"])
    C = rotvec_to_dcm(err[6:9]) @ C
    vel = r0[["vel_e", "vel_n", "vel_u"]].to_numpy(float) + err[3:6]
    return NavState(r0["lat"] + dlat, r0["lon"] + dlon, r0["height"] + dh, vel, C,
                    float(truth.index[0]))


def nav_errors(est: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Errors (estimate minus truth) at the common times: ENU metres, velocity, misalignment."""
    idx = est.index.intersection(truth.index)
    e = est.loc[idx]
    tr = truth.loc[idx]
    M, N = radii(tr["lat"].to_numpy())
    h = tr["height"].to_numpy()
    de = (e["lon"].to_numpy() - tr["lon"].to_numpy()) * (N + h) * np.cos(tr["lat"].to_numpy())
    dn = (e["lat"].to_numpy() - tr["lat"].to_numpy()) * (M + h)
    du = e["height"].to_numpy() - h
    dv = e[["vel_e", "vel_n", "vel_u"]].to_numpy() - tr[["vel_e", "vel_n", "vel_u"]].to_numpy()
    Ce = euler_to_dcm(e["roll"].to_numpy(), e["pitch"].to_numpy(), e["heading"].to_numpy())
    Ct = euler_to_dcm(tr["roll"].to_numpy(), tr["pitch"].to_numpy(), tr["heading"].to_numpy())
    phi = attitude_error(Ce, Ct)
    dh_ = np.angle(np.exp(1j * (e["heading"].to_numpy() - tr["heading"].to_numpy())))
    return pd.DataFrame({
        "east": de, "north": dn, "up": du, "vel_e": dv[:, 0], "vel_n": dv[:, 1], "vel_u": dv[:, 2],
        "phi_e": phi[:, 0], "phi_n": phi[:, 1], "phi_u": phi[:, 2], "heading": dh_,
    }, index=idx)


def error_vector_at(est_row_times, errors: pd.DataFrame) -> np.ndarray:
    """(E, 9) error vectors (dr, dv, phi) at the given times."""
    e = errors.loc[est_row_times]
    return e[["east", "north", "up", "vel_e", "vel_n", "vel_u", "phi_e", "phi_n", "phi_u"]].to_numpy()


def true_body_rates(truth: pd.DataFrame) -> np.ndarray:
    """Approximate true body angular rate (N, 3) from the clean increments (for lever arms)."""
    t, dth, _ = increments(inverse_mechanize(truth))
    w = np.zeros_like(dth)
    w[1:] = dth[1:] / np.diff(t)[:, None]
    w[0] = w[1]
    return w
