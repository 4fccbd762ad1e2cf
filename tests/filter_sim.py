"""Seeded simulation helpers for the filter tests and benchmark, on :mod:`insgnss.simulate`.

- Truth: :func:`insgnss.simulate.trajectory.generate` (segments; positions by the forward
  mechanization's own trapezoidal rule, so ``mechanize(inverse_mechanize(truth)) == truth``).
  :func:`car_truth` strings together a manoeuvre cycle (turns, speed changes, hills) and
  optional stops.
- IMU: :func:`insgnss.simulate.sensors.simulate_imu` on the ideal increments of
  :func:`insgnss.mechanization.inverse.inverse_mechanize`, restricted to the errors the filter
  models (turn-on bias + Gauss-Markov instability, ARW/VRW, optional scale factors; no
  non-orthogonality, g-sensitivity, quantization), which is what consistency tests need. Two
  extra bias modes used by single tests ("gm": the filter's ``gauss_markov`` model exactly;
  "constant" with a chosen value) are synthesised here.
- GNSS: :func:`insgnss.simulate.aiding.simulate_gnss` (white noise, antenna lever arm).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.signal import lfilter

from insgnss.attitude import attitude_error, euler_to_dcm, rotvec_to_dcm
from insgnss.earth import enu_displacement_to_geodetic, radii
from insgnss.imu import ImuErrorModel, grade, increments, increments_table
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS, NavState
from insgnss.simulate.aiding import simulate_gnss
from insgnss.simulate.sensors import simulate_imu
from insgnss.simulate.trajectory import generate

DEG = np.pi / 180.0
LAT0, LON0, H0 = 45.0 * DEG, 7.0 * DEG, 250.0

#: one manoeuvre cycle of the simulated car (~50 s): turns at speed, speed changes, a hill
CAR_CYCLE = [
    {"type": "turn", "angle": 70 * DEG, "rate": 14 * DEG},
    {"type": "accelerate", "speed": 16.0, "acceleration": 1.2},
    {"type": "turn", "angle": -110 * DEG, "rate": 14 * DEG},
    {"type": "climb", "height_change": 3.0, "rate": 0.6},
    {"type": "decelerate", "speed": 12.0, "acceleration": 1.2},
    {"type": "turn", "angle": 40 * DEG, "rate": 10 * DEG},
    {"type": "descend", "height_change": 3.0, "rate": 0.6},
    {"type": "hold", "duration": 3.0},
]
STOP = [
    {"type": "decelerate", "speed": 0.0, "acceleration": 1.5},
    {"type": "static", "duration": None},
    {"type": "accelerate", "speed": 12.0, "acceleration": 1.5},
]


def car_truth(duration=300.0, rate=50.0, stops_after=(), stop_duration=20.0, start_at_rest=False,
              heading0=30.0 * DEG, start_time=0.0) -> pd.DataFrame:
    """A manoeuvring car (12-16 m/s) for ``duration`` s; a stop of ``stop_duration`` s after
    each cycle index in ``stops_after``. Columns NAV_COLS + ``stationary``."""
    segs = []
    if start_at_rest:
        segs += [{"type": "static", "duration": 5.0}, dict(STOP[2])]
    for c in range(int(duration // 40) + 2):
        segs += [dict(x) for x in CAR_CYCLE]
        if c in stops_after:
            segs += [dict(STOP[0]), {"type": "static", "duration": stop_duration}, dict(STOP[2])]
    traj = generate(rate=rate, lat=LAT0, lon=LON0, height=H0, heading=heading0,
                    speed=0.0 if start_at_rest else 12.0, vehicle="land", segments=segs,
                    duration=duration, start_time=start_time)
    return traj.truth


def turning_truth(rate=100.0, speed=20.0, turn_rate=17 * DEG) -> pd.DataFrame:
    """1.5 s inside the plateau of a fast turn (centripetal acceleration, yaw rate)."""
    traj = generate(rate=rate, lat=LAT0, lon=LON0, height=H0, heading=0.3, speed=speed,
                    segments=[{"type": "turn", "angle": 120 * DEG, "rate": turn_rate}])
    t = traj.truth.index.to_numpy()
    return traj.truth[(t >= 2.0) & (t <= 3.5 + 1e-9)]


def stop_windows(truth: pd.DataFrame) -> list[tuple[float, float]]:
    """(start, end) of the stationary intervals of a truth table."""
    s = truth["stationary"].to_numpy() > 0.5
    t = truth.index.to_numpy()
    d = np.diff(np.r_[0, s.astype(int), 0])
    return [(t[a], t[b - 1]) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)]


def static_truth(duration=60.0, rate=100.0, roll=0.01, pitch=-0.02, heading=1.0) -> pd.DataFrame:
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    data = np.tile([LAT0, LON0, H0, 0, 0, 0, roll, pitch, heading], (n, 1))
    return pd.DataFrame(data, index=pd.Index(t, name="time"), columns=NAV_COLS)


def _gm(rng, n, dt, x0, sigma, tau):
    """Discrete first-order Gauss-Markov paths (n, 3) starting at x0."""
    if sigma > 0 and np.isfinite(tau):
        a = np.exp(-dt / tau)
        w = rng.standard_normal((n, 3)) * sigma * np.sqrt(1 - a * a)
        w[0] = x0
        return lfilter([1.0], [1.0, -a], w, axis=0)
    return np.tile(np.asarray(x0, float), (n, 1))


def filter_model_errors(model: ImuErrorModel, scale: bool = False) -> ImuErrorModel:
    """The part of an IMU error model that the 15/21-state filter models."""
    return model.scaled(gyro_misalignment=0.0, accel_misalignment=0.0, gyro_quantization=0.0,
                        accel_quantization=0.0, gyro_range=0.0, accel_range=0.0,
                        gyro_g_sensitivity=0.0,
                        gyro_scale=model.gyro_scale if scale else 0.0,
                        accel_scale=model.accel_scale if scale else 0.0)


def corrupt_imu(truth: pd.DataFrame, model: ImuErrorModel, rng: np.random.Generator,
                bias: str = "turn_on_gm", scale=False, bias0=None):
    """Sensor measurements (increment table) of a truth trajectory, and the true errors.

    ``bias``: ``"turn_on_gm"`` (default; :func:`insgnss.simulate.sensors.simulate_imu`: constant
    turn-on bias + stationary Gauss-Markov instability, the filter's ``random_walk`` model is
    consistent with it for runs shorter than the correlation time), ``"gm"`` (a Gauss-Markov
    process started from ``N(0, turn_on^2 + sigma^2)``: the filter's ``gauss_markov`` model),
    ``"constant"`` (``bias0`` (6,) or a draw, held constant).

    Returns ``(imu, errors)`` with ``errors`` holding ``gyro_bias``, ``accel_bias`` (N, 3)
    and ``gyro_scale``, ``accel_scale`` (3,).
    """
    ideal = inverse_mechanize(truth.drop(columns=["stationary"], errors="ignore"))
    m = filter_model_errors(model, scale)
    if bias == "turn_on_gm" and bias0 is None:
        sim = simulate_imu(ideal, m, rng)
        b = sim.bias.to_numpy()
        return sim.imu, {"gyro_bias": b[:, :3], "accel_bias": b[:, 3:],
                         "gyro_scale": sim.params["gyro_scale"], "accel_scale": sim.params["accel_scale"]}
    t, dth, dv = increments(ideal)
    n = t.size
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    d0 = float(np.median(np.diff(t)))
    out = []
    for turn_on, instab, k in ((m.gyro_bias, m.gyro_bias_instability, 0),
                               (m.accel_bias, m.accel_bias_instability, 3)):
        s0 = np.hypot(turn_on, instab)
        b0 = rng.standard_normal(3) * s0 if bias0 is None else np.asarray(bias0[k:k + 3], float)
        if bias == "gm":
            out.append(_gm(rng, n, d0, b0, instab, m.bias_correlation_time))
        elif bias == "constant":
            out.append(np.tile(b0, (n, 1)))
        else:
            raise ValueError(bias)
    bg, ba = out
    sg = rng.standard_normal(3) * m.gyro_scale
    sa = rng.standard_normal(3) * m.accel_scale
    sq = np.sqrt(dt)[:, None]
    dth_m = dth * (1 + sg) + bg * dt[:, None] + rng.standard_normal((n, 3)) * m.gyro_arw * sq
    dv_m = dv * (1 + sa) + ba * dt[:, None] + rng.standard_normal((n, 3)) * m.accel_vrw * sq
    dth_m[0] = 0.0
    dv_m[0] = 0.0
    imu = increments_table(t, dth_m, dv_m)
    return imu, {"gyro_bias": bg, "accel_bias": ba, "gyro_scale": sg, "accel_scale": sa}


def gnss_from_truth(truth: pd.DataFrame, rng: np.random.Generator, rate: float = 1.0,
                    horizontal_std: float = 1.0, vertical_std: float = 2.0, velocity_std: float = 0.05,
                    vertical_velocity_std: float = 0.1, lever_arm=(0.0, 0.0, 0.0)) -> pd.DataFrame:
    """GNSS position + velocity with white errors and antenna lever arm
    (:func:`insgnss.simulate.aiding.simulate_gnss`), epochs every ``1/rate`` s from the first
    truth sample."""
    return simulate_gnss(truth, rng, rate=rate, horizontal_std=horizontal_std, vertical_std=vertical_std,
                         velocity=True, velocity_std=velocity_std,
                         vertical_velocity_std=vertical_velocity_std, lever_arm=lever_arm)


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


def polar_flight(rng: np.random.Generator, imu_grade: str = "tactical"):
    """The over-the-pole flight of issue 17 with sensors and GNSS: 250 m/s, 1 km, from 89.5 N on
    lon 0 over the pole (within 1 m of it) to lon 180, 450 s at 100 Hz; IMU of ``imu_grade``
    (the errors the filter models), GNSS positions at 1 Hz with 1 m / 2 m white noise drawn in
    ECEF (exact next to the pole), initial errors of 2 m, 0.1 m/s, 0.1-0.6 deg.

    Returns ``(truth, imu, gnss, initial, config)``."""
    import insgnss.earth as earth
    from insgnss.filter.engine import FilterConfig

    D = np.pi / 180.0
    truth = generate(rate=100.0, lat=89.5 * D, lon=0.0, height=1000.0, heading=0.0,
                     speed=250.0, vehicle="aircraft",
                     segments=[{"type": "hold", "duration": 450.0}], frame="wander").truth
    model = grade(imu_grade) if isinstance(imu_grade, str) else imu_grade
    sim = simulate_imu(inverse_mechanize(truth, frame="wander"), filter_model_errors(model), rng)
    tr = truth.iloc[::100]
    noise = rng.standard_normal((len(tr), 3)) * [1.0, 1.0, 2.0]
    r = np.column_stack(earth.geodetic_to_ecef(tr["lat"].to_numpy(), tr["lon"].to_numpy(),
                                               tr["height"].to_numpy()))
    r += np.einsum("kij,kj->ki", earth.enu_to_ecef_dcm(tr["lat"], tr["lon"]), noise)
    la, lo, hh = earth.ecef_to_geodetic(r[:, 0], r[:, 1], r[:, 2])
    gnss = pd.DataFrame({"lat": la, "lon": lo, "height": hh, "east_std": 1.0,
                         "north_std": 1.0, "up_std": 2.0}, index=tr.index)
    r0 = truth.iloc[0]
    C0 = rotvec_to_dcm(np.array([0.002, -0.002, 0.01])) @ euler_to_dcm(
        r0["roll"], r0["pitch"], r0["heading"])
    x0 = NavState(r0["lat"] + 2.0 / 6.4e6, r0["lon"], r0["height"] - 1.5,
                  r0[["vel_e", "vel_n", "vel_u"]].to_numpy(float) + [0.1, -0.05, 0.05], C0,
                  float(truth.index[0]))
    x0.wander_angle = float(r0["wander_angle"])
    cfg = FilterConfig(imu_model=model, initial_pos_std=3.0, initial_vel_std=0.2,
                       initial_att_std=(0.005, 0.005, 0.02))
    return truth, sim.imu, gnss, x0, cfg


def car_outage_setup(truth: pd.DataFrame, rng: np.random.Generator,
                     outages: list[tuple[float, float]], *, smoother: bool = False):
    """The simulated car of the NHC tests and benches: a consumer IMU (its gyros trusted at 20 x
    the white noise, a running engine's vibration as a static window measures it), RTK GNSS
    position and velocity at 4 Hz withheld in the half-open ``outages`` windows [s], an initial
    state with small errors and the 4 Hz NHC epochs.

    Returns ``(imu, init, gnss_measurements, nhc_times, cfg)``.
    """
    from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity

    model = grade("consumer")
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng, rate=4.0, horizontal_std=0.02, vertical_std=0.03,
                           velocity_std=0.03, vertical_velocity_std=0.05)
    init, _ = perturbed_initial(truth, rng, 0.02, 0.03, (0.005, 0.005, 0.01))
    t_g = gnss.index.to_numpy()
    keep = np.ones(t_g.size, bool)
    for a, b in outages:
        keep &= ~((t_g >= a) & (t_g < b))
    t = truth.index.to_numpy()
    tn = np.arange(t[0] + 0.25, t[-1], 0.25)
    cfg = FilterConfig(imu_model=model.scaled(gyro_arw=20 * model.gyro_arw), smoother=smoother,
                       initial_att_std=(0.005, 0.005, 0.01))
    return imu, init, [GnssPosition(gnss[keep]), GnssVelocity(gnss[keep])], tn, cfg


def outage_end_error(solution: pd.DataFrame, truth: pd.DataFrame,
                     outages: list[tuple[float, float]]) -> float:
    """Mean horizontal error [m] at the last 4 Hz epoch of each outage window."""
    e = nav_errors(solution, truth)
    rows = e.index.get_indexer([b - 0.26 for _, b in outages], method="nearest")
    return float(np.hypot(e["east"].to_numpy()[rows], e["north"].to_numpy()[rows]).mean())


def outage_rms(solution: pd.DataFrame, truth: pd.DataFrame,
               outages: list[tuple[float, float]]) -> float:
    """Mean over the outage windows of the horizontal RMS error inside each [m]."""
    e = nav_errors(solution, truth)
    ts = e.index.to_numpy()
    east, north = e["east"].to_numpy(), e["north"].to_numpy()
    return float(np.mean([np.sqrt(np.mean(east[w] ** 2 + north[w] ** 2))
                          for w in ((ts >= a) & (ts < b) for a, b in outages)]))
