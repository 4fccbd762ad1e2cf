"""Seed 003 trajectory tools: llh_to_vne (exact inverse of the position rule), vne_to_rpy
(coordinated-turn attitude), est_wind."""

import numpy as np
import pandas as pd
import pytest
from mech_helpers import dynamic_trajectory

from insgnss.earth import normal_gravity
from insgnss.errors import InsgnssError
from insgnss.mechanization.inverse import integrate_position
from insgnss.simulate.trajectory import generate
from insgnss.trajectory_tools import est_wind, llh_to_vne, vne_to_rpy

D = np.pi / 180.0
VEL = ["vel_e", "vel_n", "vel_u"]


def test_llh_to_vne_round_trip_with_the_position_rule():
    traj = dynamic_trajectory(600.0, 100.0)  # positions = integrate_position(velocity)
    v = traj[VEL].to_numpy()
    est = llh_to_vne(traj[["lat", "lon", "height"]], vel0=v[0])
    assert list(est.columns) == VEL
    # positions in radians carry ulp(lat) R ~ 0.7 nm: differentiated over dt = 10 ms that is
    # ~1e-7 m/s per step, which the exact inverse sums in its alternating mode; the error stays
    # inside that worst case
    err = np.abs(est.to_numpy() - v).max(axis=1)
    k = np.arange(err.size)
    per_step = 2 * 6.4e6 * np.spacing(traj["lat"].abs().max()) / 0.01
    assert np.all(err <= k * per_step) and err.max() < 1e-4
    t = traj.index.to_numpy()
    pos = integrate_position(t, est.to_numpy(), *traj[["lat", "lon", "height"]].iloc[0])
    assert np.abs(pos - traj[["lat", "lon", "height"]].to_numpy()).max() < 1e-13
    # without the initial velocity: the smoothest solution, the same to well below a mm/s
    est0 = llh_to_vne(traj[["lat", "lon", "height"]].to_numpy(), t)
    assert np.abs(est0 - v).max() < 1e-4


def test_llh_to_vne_central_and_longitude_wrap():
    t = np.arange(0, 60.0, 0.1)
    vel = np.column_stack([np.full(t.size, 50.0), 10 * np.sin(t / 10), np.zeros(t.size)])
    pos = integrate_position(t, vel, 0.3, np.pi - 1e-4, 10.0)
    pos[:, 1] = np.mod(pos[:, 1] + np.pi, 2 * np.pi) - np.pi  # wraps through +-180 deg
    trap = llh_to_vne(pos, t, vel0=vel[0])
    assert np.abs(trap - vel).max() < 1e-5  # ulp(pi) R / dt per step, see above
    cen = llh_to_vne(pos, t, method="central")
    assert np.abs(cen - vel).max() < 1e-3
    with pytest.raises(InsgnssError, match="degrees"):
        llh_to_vne(np.column_stack([np.degrees(pos[:, 0]), pos[:, 1:]]), t)


def test_vne_to_rpy_recovers_the_bank_of_a_coordinated_turn():
    v, omega = 120.0, np.radians(3.0)  # 3 deg/s at 120 m/s
    t = np.arange(0, 60.0, 0.01)
    psi = 0.4 + omega * t
    vel = np.column_stack([v * np.sin(psi), v * np.cos(psi), np.full(t.size, 2.0)])
    g = normal_gravity(np.radians(50.0), 1000.0)
    roll, pitch, heading = vne_to_rpy(vel, t, lat=np.radians(50.0), height=1000.0)
    bank = np.arctan(v * omega / g)
    assert np.degrees(bank) == pytest.approx(32.65, abs=0.01)
    assert np.abs(roll - bank).max() < 1e-6
    assert np.abs(pitch - np.arctan2(2.0, v)).max() < 1e-12
    assert np.abs(np.angle(np.exp(1j * (heading - psi)))).max() < 1e-12
    # left turn: negative bank
    r2, _, _ = vne_to_rpy(vel[::-1] * [1, 1, 1], t, g=g)
    assert np.abs(r2 + bank).max() < 1e-6


def test_vne_to_rpy_reproduces_the_simulators_aircraft():
    plane = [{"type": "hold", "duration": 5.0},
             {"type": "coordinated_turn", "angle": 120 * D, "bank": 30 * D},
             {"type": "hold", "duration": 5.0}]
    tr = generate(rate=100.0, lat=0.8, lon=0.1, height=500.0, speed=70.0, vehicle="aircraft",
                  segments=plane).truth
    roll, pitch, heading = vne_to_rpy(tr[VEL], lat=0.8, height=500.0)
    assert np.degrees(roll.max()) == pytest.approx(30.0, abs=0.05)
    assert np.abs(roll - tr["roll"].to_numpy()).max() < 2e-4  # numerical vs analytic turn rate


def test_est_wind_recovers_a_simulated_wind():
    rng = np.random.default_rng(1)
    t = np.arange(0, 600.0, 0.1)
    heading = 0.3 + 2 * np.pi * t / 200.0  # circles
    airspeed = 60.0
    wind = np.array([7.0, -3.0])
    vg = airspeed * np.column_stack([np.sin(heading), np.cos(heading)]) + wind
    vg += rng.normal(0, 0.05, vg.shape)
    w, s = est_wind(vg, heading)
    assert np.abs(w - wind).max() < 0.01 and np.abs(s - airspeed).max() < 0.01
    w2, s2 = est_wind(vg, heading, airspeed)
    assert np.abs(w2.mean(axis=0) - wind).max() < 0.01 and np.all(s2 == airspeed)
    # slowly changing wind with a sliding window
    wind_t = wind + np.column_stack([np.sin(t / 300.0), np.zeros(t.size)])
    vg2 = airspeed * np.column_stack([np.sin(heading), np.cos(heading)]) + wind_t
    df = pd.DataFrame({"vel_e": vg2[:, 0], "vel_n": vg2[:, 1]}, index=t)
    w3, _ = est_wind(df, heading, window=200.0)
    inner = (t > 150) & (t < 450)
    assert np.abs(w3[inner] - wind_t[inner]).max() < 0.05
    with pytest.raises(InsgnssError, match="varies too little"):
        est_wind(vg, np.full(t.size, 0.3))
