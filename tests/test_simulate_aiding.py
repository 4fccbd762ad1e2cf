"""GNSS, odometer and magnetometer synthesis."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from insgnss.attitude import wrap_pi
from insgnss.earth import geodetic_to_enu
from insgnss.simulate.aiding import (
    antenna_position,
    gnss_errors_enu,
    periodic_windows,
    simulate_gnss,
    simulate_magnetometer,
    simulate_odometer,
)
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0
LAT, LON, H = 40.0 * D, -3.7 * D, 650.0


@pytest.fixture(scope="module")
def truth():
    segs = [{"type": "static", "duration": 20.0},
            {"type": "accelerate", "speed": 15.0, "acceleration": 2.0},
            {"type": "turn", "angle": 90 * D, "rate": 10 * D},
            {"type": "climb", "height_change": 10.0, "rate": 1.0},
            {"type": "turn", "angle": -270 * D, "rate": 6 * D},
            {"type": "hold", "duration": 1500.0},
            {"type": "decelerate", "speed": 0.0, "acceleration": 1.5},
            {"type": "static", "duration": 10.0}]
    return generate(rate=50.0, lat=LAT, lon=LON, height=H, heading=20 * D, segments=segs,
                    roll_gain=1.0 * D).truth


def chi2_two_sided_ok(z: np.ndarray, alpha: float = 0.01) -> tuple[bool, float, float]:
    """Sum of squares of N(0,1) values inside the two-sided (1 - alpha) chi-square interval."""
    s = float(np.sum(z**2))
    dof = z.size
    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], dof)
    return lo <= s <= hi, s / dof, dof


def test_gnss_position_statistics_match_declared_std(truth):
    lever = (0.3, 1.2, 1.6)
    g = simulate_gnss(truth, 11, rate=2.0, horizontal_std=1.5, vertical_std=3.0, lever_arm=lever,
                      degraded=[{"start": 300.0, "stop": 500.0, "factor": 4.0}])
    e = gnss_errors_enu(g, truth, lever)
    z = e / g[["east_std", "north_std", "up_std"]].to_numpy()
    for j in range(3):  # each axis, and all together
        ok, ratio, dof = chi2_two_sided_ok(z[:, j])
        assert ok, (j, ratio, dof)
    assert chi2_two_sided_ok(z.ravel())[0]
    assert abs(z.mean()) < 3 / np.sqrt(z.size)
    # the degraded window really has larger declared and actual errors
    t = g.index.to_numpy() - truth.index[0]
    inside = (t >= 300) & (t < 500)
    assert np.allclose(g["east_std"].to_numpy()[inside], 6.0)
    assert np.std(e[inside, 0]) > 3 * np.std(e[~inside, 0])


def test_gnss_velocity_statistics_and_correlated_errors(truth):
    lever = (0.0, 2.0, 1.0)
    g = simulate_gnss(truth, 12, rate=1.0, velocity=True, velocity_std=0.05,
                      vertical_velocity_std=0.08, lever_arm=lever, correlation_time=30.0)
    from insgnss.simulate.aiding import antenna_velocity

    idx = np.searchsorted(truth.index.to_numpy(), g.index.to_numpy())
    ev = g[["vel_e", "vel_n", "vel_u"]].to_numpy() - antenna_velocity(truth, idx, lever)
    zv = ev / g[["vel_e_std", "vel_n_std", "vel_u_std"]].to_numpy()
    assert chi2_two_sided_ok(zv.ravel())[0]
    # Gauss-Markov position errors: marginal std as declared, strongly correlated epoch to epoch
    e = gnss_errors_enu(g, truth, lever)
    z = e / g[["east_std", "north_std", "up_std"]].to_numpy()
    assert np.all(np.abs(z.std(axis=0) - 1) < 0.35)  # ~ 50 correlation times: loose
    r1 = np.corrcoef(z[1:, 0], z[:-1, 0])[0, 1]
    assert abs(r1 - np.exp(-1 / 30.0)) < 0.05


def test_lever_arm_geometry():
    """Static vehicle heading east: the antenna 1 m forward, 2 m up is 1 m east, 2 m up."""
    tr = generate(rate=10.0, lat=LAT, lon=LON, height=H, heading=90 * D,
                  segments=[{"type": "static", "duration": 1.0}]).truth
    pos = antenna_position(tr, np.array([0]), (0.0, 1.0, 2.0))
    e, n, u = geodetic_to_enu(pos[0, 0], pos[0, 1], pos[0, 2], LAT, LON, H)
    assert abs(e - 1.0) < 1e-9 and abs(n) < 1e-9 and abs(u - 2.0) < 1e-9


def test_lever_arm_velocity_in_a_turn(truth):
    """During a constant-rate turn the antenna 2 m ahead moves faster sideways by omega * 2."""
    from insgnss.simulate.aiding import antenna_velocity

    t = truth.index.to_numpy()
    psid = np.gradient(np.unwrap(truth["heading"].to_numpy()), t)
    k = int(np.argmax(np.abs(psid)))
    v0 = antenna_velocity(truth, np.array([k]), (0.0, 0.0, 0.0))[0]
    v1 = antenna_velocity(truth, np.array([k]), (0.0, 2.0, 0.0))[0]
    assert abs(np.linalg.norm(v1 - v0) - abs(psid[k]) * 2.0) < 1e-3


def test_outages_explicit_and_periodic(truth):
    g = simulate_gnss(truth, 1, rate=1.0, outages=[[50.0, 80.0]],
                      periodic_outages={"start": 200.0, "length": 60.0, "gap": 240.0,
                                        "stop_before_end": 120.0})
    t = g.index.to_numpy() - truth.index[0]
    T = truth.index[-1] - truth.index[0]
    assert not np.any((t >= 50) & (t < 80))
    windows = periodic_windows(T, 200.0, 60.0, 240.0, 120.0)
    assert windows[0] == (200.0, 260.0) and windows[1] == (500.0, 560.0)
    assert windows[-1][0] <= T - 120.0 - 60.0 < windows[-1][0] + 300.0
    for a, b in windows:
        assert not np.any((t >= a) & (t < b))
        assert np.any((t >= b) & (t < b + 2))  # GNSS returns after each outage
    expected = int(np.floor(T)) + 1 - 30 - 60 * len(windows)
    assert len(g) == expected


def test_outliers_flagged(truth):
    g = simulate_gnss(truth, 3, rate=1.0, horizontal_std=1.0, vertical_std=1.0,
                      outlier_probability=0.02, outlier_duration=5.0, outlier_magnitude=25.0)
    e = gnss_errors_enu(g, truth)
    flag = g["outlier"].to_numpy() > 0
    assert 0.03 < flag.mean() < 0.3
    norm = np.linalg.norm(e, axis=1)
    assert np.median(norm[flag]) > 15.0 and np.median(norm[~flag]) < 3.0
    # declared std is not inflated for outliers; clean epochs pass the chi-square test
    assert np.allclose(g["east_std"], 1.0)
    assert chi2_two_sided_ok(e[~flag].ravel())[0]


def test_gnss_reproducible(truth):
    a = simulate_gnss(truth, 5, rate=1.0, velocity=True)
    b = simulate_gnss(truth, 5, rate=1.0, velocity=True)
    assert a.equals(b)
    assert list(a.columns[:6]) == ["lat", "lon", "height", "east_std", "north_std", "up_std"]


def test_odometer_speed_and_distance(truth):
    odo, p = simulate_odometer(truth, 1, rate=10.0, output="both", scale_factor=0.02)
    # speed: truth forward speed (the body y axis is along the velocity) times 1.02
    t = truth.index.to_numpy()
    idx = np.searchsorted(t, odo.index.to_numpy())
    speed = np.linalg.norm(truth[["vel_e", "vel_n", "vel_u"]].to_numpy()[idx], axis=1)
    assert np.abs(odo["speed"].to_numpy() - 1.02 * speed).max() < 1e-9
    assert p["scale_factor"] == 0.02
    # distance increments sum to the travelled distance times 1.02
    trav = np.sum(np.diff(t) * 0.5 * (np.linalg.norm(truth[["vel_e", "vel_n", "vel_u"]].to_numpy(),
                                                       axis=1)[1:] +
                                       np.linalg.norm(truth[["vel_e", "vel_n", "vel_u"]].to_numpy(),
                                                      axis=1)[:-1]))
    assert abs(odo["distance"].sum() - 1.02 * trav) < 1e-6


def test_odometer_noise_quantization_and_drawn_scale(truth):
    odo, p = simulate_odometer(truth, 2, rate=10.0, output="both", scale_factor_std=0.01,
                               noise_std=0.1, speed_quantum=0.05, distance_quantum=0.02)
    s = odo["speed"].to_numpy()
    assert np.allclose(s / 0.05, np.round(s / 0.05), atol=1e-9)
    d = odo["distance"].to_numpy()
    assert np.allclose(d / 0.02, np.round(d / 0.02), atol=1e-6)
    assert 0 < abs(p["scale_factor"]) < 0.05
    odo2, p2 = simulate_odometer(truth, 2, rate=10.0, output="speed", scale_factor_std=0.01)
    assert p2["scale_factor"] == p["scale_factor"]  # same seed, same draw
    # speed noise std as declared (static part at the end: truth speed 0)
    t = odo.index.to_numpy() - truth.index[0]
    T = t[-1]
    still = t > T - 9.0
    noisy, _ = simulate_odometer(truth, 3, rate=50.0, noise_std=0.1)
    tn = noisy.index.to_numpy() - truth.index[0]
    z = noisy["speed"].to_numpy()[tn < 19.0]
    assert abs(z.std() / 0.1 - 1) < 0.15 and abs(z.mean()) < 0.05
    assert np.all(odo["distance"].to_numpy()[still] == 0.0)
    with pytest.raises(ValueError):
        simulate_odometer(truth, 1, output="pulses")


def test_odometer_lever_arm_in_turn(truth):
    """A point 1 m to the right of the IMU is faster in a left turn, slower in a right turn."""
    o0, _ = simulate_odometer(truth, 1, rate=50.0)
    o1, _ = simulate_odometer(truth, 1, rate=50.0, lever_arm=(1.0, 0.0, 0.0))
    t = truth.index.to_numpy()
    psid = np.gradient(np.unwrap(truth["heading"].to_numpy()), t)
    idx = np.searchsorted(t, o0.index.to_numpy())
    # omega_lb^b has z = -psid (heading clockwise); (w x l)_y = w_z * 1 = -psid
    d = o1["speed"].to_numpy() - o0["speed"].to_numpy()
    assert np.abs(d + psid[idx]).max() < 2e-3


def test_magnetometer(truth):
    m = simulate_magnetometer(truth, 4, rate=10.0, noise_std=2 * D, declination_error=3 * D)
    idx = np.searchsorted(truth.index.to_numpy(), m.index.to_numpy())
    err = wrap_pi(m["heading"].to_numpy() - truth["heading"].to_numpy()[idx])
    assert abs(err.mean() - 3 * D) < 4 * 2 * D / np.sqrt(err.size)
    assert abs(err.std() / (2 * D) - 1) < 0.05
    assert np.all((m["heading"] >= 0) & (m["heading"] < 2 * np.pi))
    assert np.allclose(m["heading_std"], 2 * D)
    dev = simulate_magnetometer(truth, 4, rate=10.0, noise_std=0.0, deviation=5 * D)
    e2 = wrap_pi(dev["heading"].to_numpy() - truth["heading"].to_numpy()[idx])
    assert np.allclose(e2, 5 * D * np.sin(truth["heading"].to_numpy()[idx]), atol=1e-12)
