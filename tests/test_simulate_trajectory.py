"""Trajectory generator: self-consistency, continuity, waypoints, vehicle models, duality."""

from __future__ import annotations

import numpy as np
import pytest

from insgnss.attitude import dcm_to_rotvec, euler_to_dcm, wrap_pi
from insgnss.earth import OMEGA_E, geodetic_to_enu, normal_gravity, radii
from insgnss.errors import ConfigError
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS, NavState, mechanize
from insgnss.simulate.trajectory import generate, smooth_step

D = np.pi / 180.0
LAT, LON, H = 45.0 * D, 7.0 * D, 250.0

CAR = [
    {"type": "static", "duration": 5.0},
    {"type": "accelerate", "speed": 15.0, "acceleration": 2.0},
    {"type": "turn", "angle": 90 * D, "rate": 12 * D},
    {"type": "climb", "height_change": 10.0, "rate": 1.0},
    {"type": "hold", "duration": 10.0},
    {"type": "turn", "angle": -120 * D, "duration": 15.0, "ramp": 0.5},
    {"type": "descend", "height_change": 5.0, "duration": 10.0},
    {"type": "decelerate", "speed": 0.0, "acceleration": 2.5},
    {"type": "static", "duration": 3.0},
]
PLANE = [
    {"type": "hold", "duration": 5.0},
    {"type": "coordinated_turn", "angle": 180 * D, "bank": 25 * D},
    {"type": "climb", "height_change": 100.0, "rate": 5.0},
    {"type": "coordinated_turn", "angle": -90 * D, "duration": 20.0},
    {"type": "accelerate", "speed": 80.0, "duration": 10.0},
]
WALK = [
    {"type": "stand", "duration": 2.0},
    {"type": "walk", "steps": 6, "turn": 90 * D},
    {"type": "stand", "duration": 1.0},
    {"type": "walk", "steps": 4, "height_change": 1.2, "stride_length": 0.6},
    {"type": "stand", "duration": 2.0},
]
WAYPOINTS = [
    {"time": 0.0, "east": 0.0, "north": 0.0},
    {"time": 20.0, "east": 120.0, "north": 60.0},
    {"time": 45.0, "east": 260.0, "north": -30.0, "up": 4.0},
    {"time": 70.0, "east": 200.0, "north": -250.0, "up": 1.0},
    {"time": 90.0, "east": 50.0, "north": -300.0},
]


def trajectories():
    return {
        "car": generate(rate=100.0, lat=LAT, lon=LON, height=H, heading=30 * D, segments=CAR,
                        roll_gain=0.5 * D),
        "aircraft": generate(rate=100.0, lat=LAT, lon=LON, height=1000.0, heading=250 * D,
                             speed=60.0, vehicle="aircraft", segments=PLANE),
        "pedestrian": generate(rate=200.0, lat=LAT, lon=LON, height=H, heading=10 * D,
                               vehicle="pedestrian", segments=WALK),
        "waypoints": generate(rate=100.0, lat=LAT, lon=LON, height=H, waypoints=WAYPOINTS,
                              start_at_rest=True, end_at_rest=True),
    }


@pytest.fixture(scope="module")
def trajs():
    return trajectories()


def test_smooth_step_properties():
    u = np.linspace(0, 1, 100001)
    for r in (0.1, 0.25, 0.5):
        S, dS = smooth_step(u, r)
        assert S[0] == 0.0 and abs(S[-1] - 1.0) < 1e-15
        assert dS[0] == 0.0 and abs(dS[-1]) < 1e-15
        assert np.all(np.diff(S) >= 0)
        # dS is the derivative of S and has unit integral
        assert np.max(np.abs(np.gradient(S, u) - dS)) < 1e-3
        assert abs(np.trapezoid(dS, u) - 1.0) < 1e-8
        assert abs(dS.max() - 1.0 / (1.0 - r)) < 1e-9  # plateau rate
    with pytest.raises(ValueError):
        smooth_step(u, 0.0)


@pytest.mark.parametrize("name", ["car", "aircraft", "pedestrian", "waypoints"])
def test_position_derivative_equals_velocity(trajs, name):
    """(p_k - p_{k-1})/dt in metres (radii at the mid-interval point predicted from the start
    state, the strapdown step's rule) equals the trapezoid mean velocity within 1e-6 m/s."""
    T = trajs[name].truth
    t = T.index.to_numpy()
    lat, lon, h = (T[c].to_numpy() for c in ("lat", "lon", "height"))
    v = T[["vel_e", "vel_n", "vel_u"]].to_numpy()
    dt = np.diff(t)
    M0, _ = radii(lat[:-1])
    lat_m = lat[:-1] + 0.5 * dt * v[:-1, 1] / (M0 + h[:-1])
    h_m = h[:-1] + 0.5 * dt * v[:-1, 2]
    M, N = radii(lat_m)
    ve = np.diff(lon) * (N + h_m) * np.cos(lat_m) / dt
    vn = np.diff(lat) * (M + h_m) / dt
    vu = np.diff(h) / dt
    vmean = 0.5 * (v[1:] + v[:-1])
    err = np.abs(np.column_stack([ve, vn, vu]) - vmean)
    assert err.max() < 1e-6
    # and the velocity is the analytic derivative of the motion, not noise: it is smooth
    assert np.abs(np.diff(v, 2, axis=0)).max() < 0.1


@pytest.mark.parametrize("name", ["car", "aircraft", "pedestrian", "waypoints"])
def test_attitude_and_rate_continuous(trajs, name):
    """No attitude jumps: per-step rotation and its change are bounded by the smooth profiles."""
    T = trajs[name].truth
    C = euler_to_dcm(T["roll"].to_numpy(), T["pitch"].to_numpy(), T["heading"].to_numpy())
    step = dcm_to_rotvec(np.swapaxes(C[:-1], 1, 2) @ C[1:])
    dt = np.diff(T.index.to_numpy())[:, None]
    rate = step / dt
    max_rate = {"car": 20 * D, "aircraft": 15 * D, "pedestrian": 700 * D, "waypoints": 20 * D}[name]
    assert np.linalg.norm(rate, axis=1).max() < max_rate
    # angular rate changes by a bounded amount per step (a jump of the attitude or of the
    # turn rate would show as a spike here)
    max_acc = {"car": 60 * D, "aircraft": 10 * D, "pedestrian": 2e4 * D, "waypoints": 10 * D}[name]
    assert (np.linalg.norm(np.diff(rate, axis=0), axis=1) / dt[1:, 0]).max() < max_acc


def test_waypoint_times_honoured(trajs):
    T = trajs["waypoints"].truth
    for wp in WAYPOINTS:
        r = T.loc[wp["time"]]
        e, n, u = geodetic_to_enu(r.lat, r.lon, r.height, LAT, LON, H)
        assert abs(e - wp["east"]) < 0.01 and abs(n - wp["north"]) < 0.01
        assert abs(u - wp.get("up", 0.0)) < 0.01
    v = T[["vel_e", "vel_n", "vel_u"]].to_numpy()
    assert np.all(v[0] == 0.0) and np.abs(v[-1]).max() < 1e-9
    # heading follows the velocity while moving (land vehicle model)
    moving = np.hypot(v[:, 0], v[:, 1]) > 0.5
    course = np.arctan2(v[moving, 0], v[moving, 1])
    assert np.abs(wrap_pi(course - T["heading"].to_numpy()[moving])).max() < 1e-9


def test_waypoints_geodetic_equivalent(trajs):
    from insgnss.earth import enu_to_geodetic

    geo = []
    for wp in WAYPOINTS:
        la, lo, hh = enu_to_geodetic(wp["east"], wp["north"], wp.get("up", 0.0), LAT, LON, H)
        geo.append({"time": wp["time"], "lat": float(np.degrees(la)), "lon": float(np.degrees(lo)),
                    "height": float(hh)})
    T2 = generate(rate=100.0, lat=LAT, lon=LON, height=H, waypoints=geo, start_at_rest=True,
                  end_at_rest=True).truth
    T1 = trajs["waypoints"].truth
    assert np.abs(T1[["lat", "lon"]].to_numpy() - T2[["lat", "lon"]].to_numpy()).max() < 1e-12
    assert np.abs(T1["height"].to_numpy() - T2["height"].to_numpy()).max() < 1e-6


def test_segment_durations_and_final_state(trajs):
    tr = trajs["car"]
    T = tr.truth
    seg = tr.segments
    # accelerate 0 -> 15 m/s at 2 m/s^2 plateau with 25 % ramps: 15 / (2 * 0.75) = 10 s
    assert seg[1]["type"] == "accelerate" and abs(seg[1]["duration"] - 10.0) < 1e-12
    # turn 90 deg at 12 deg/s: 10 s
    assert abs(seg[2]["duration"] - 10.0) < 1e-12
    # final heading = 30 + 90 - 120, final speed 0, height +10 - 5
    last = T.iloc[-1]
    assert abs(wrap_pi(last.heading - (30 + 90 - 120) * D)) < 1e-12
    assert np.all(T[["vel_e", "vel_n", "vel_u"]].to_numpy()[-100:] == 0.0)
    assert abs(last.height - (H + 5.0)) < 0.01
    # the static segments are flagged, motion is not
    st = T["stationary"].to_numpy() > 0.5
    t = T.index.to_numpy()
    assert np.all(st[t < 5.0]) and not np.any(st[(t > 5.5) & (t < seg[-1]["start"])])
    assert abs(T.index[-1] - seg[-1]["stop"]) < 0.01


def test_vehicle_attitude_models(trajs):
    # aircraft: bank = atan(v * turn rate / g)
    T = trajs["aircraft"].truth
    v = T[["vel_e", "vel_n", "vel_u"]].to_numpy()
    vh = np.hypot(v[:, 0], v[:, 1])
    psi = np.unwrap(T["heading"].to_numpy())
    psid = np.gradient(psi, T.index.to_numpy())
    g = normal_gravity(LAT, 1000.0)
    bank = np.arctan(vh * psid / g)
    assert np.abs(T["roll"].to_numpy() - bank)[5:-5].max() < 2e-4
    assert abs(np.degrees(T["roll"].max()) - 25.0) < 1e-6  # commanded bank on the plateau
    pitch = np.arctan2(v[:, 2], vh)
    assert np.abs(T["pitch"].to_numpy() - pitch).max() < 1e-12
    # land vehicle: body rolls outwards, -roll_gain * lateral acceleration; pitch = grade
    C = trajs["car"].truth
    v = C[["vel_e", "vel_n", "vel_u"]].to_numpy()
    vh = np.hypot(v[:, 0], v[:, 1])
    psid = np.gradient(np.unwrap(C["heading"].to_numpy()), C.index.to_numpy())
    assert np.abs(C["roll"].to_numpy() + 0.5 * D * vh * psid).max() < 1e-5
    assert C["roll"].min() < -1.5 * D and C["roll"].max() > 2.0 * D
    assert np.abs(C["pitch"].to_numpy() - np.arctan2(v[:, 2], vh)).max() < 1e-12


def test_pedestrian_stance_is_exactly_still(trajs):
    T = trajs["pedestrian"].truth
    st = T["stationary"].to_numpy() > 0.5
    v = T[["vel_e", "vel_n", "vel_u"]].to_numpy()
    assert np.all(v[st] == 0.0)  # truly zero, not merely small
    att = T[["roll", "pitch", "heading"]].to_numpy()
    # attitude constant within each stance run
    idx = np.flatnonzero(st[1:] & st[:-1]) + 1
    assert np.all(att[idx] == att[idx - 1])
    # 10 strides of 1.1 s with 60 % stance, plus 5 s standing
    assert abs(st.mean() - (5.0 + 10 * 0.66) / T.index[-1]) < 0.01
    # the foot swings: realistic pitch range and peak speed, lands 6*1.4 + 4*0.6 m away
    p = np.degrees(T["pitch"].to_numpy())
    assert -45 < p.min() < -30 and 15 < p.max() < 25
    r0, r1 = T.iloc[0], T.iloc[-1]
    e, n, u = geodetic_to_enu(r1.lat, r1.lon, r1.height, r0.lat, r0.lon, r0.height)
    assert abs(u - 1.2) < 1e-3
    assert abs(np.degrees(wrap_pi(r1.heading - r0.heading)) - 90.0) < 1e-9
    assert 9.0 < np.hypot(e, n) < 10.8
    # the ideal IMU sees only the Earth rate in stance
    imu = inverse_mechanize(T[NAV_COLS])
    w = imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy() / (1 / 200.0)
    both = np.flatnonzero(st[1:] & st[:-1]) + 1
    assert np.abs(np.linalg.norm(w[both], axis=1) - OMEGA_E).max() < 1e-9


@pytest.mark.parametrize("name", ["car", "aircraft", "pedestrian", "waypoints"])
def test_forward_of_inverse_reproduces_truth(trajs, name):
    T = trajs[name].truth[NAV_COLS]
    imu = inverse_mechanize(T)
    r = T.iloc[0]
    init = NavState.from_euler(r.lat, r.lon, r.height, [r.vel_e, r.vel_n, r.vel_u], r.roll,
                               r.pitch, r.heading, time=T.index[0])
    out = mechanize(imu, init)
    d = (out - T).abs()
    assert d[["lat", "lon"]].to_numpy().max() < 1e-12
    assert d["height"].max() < 1e-6
    assert d[["vel_e", "vel_n", "vel_u"]].to_numpy().max() < 1e-8
    assert d[["roll", "pitch"]].to_numpy().max() < 1e-10
    assert np.abs(wrap_pi(out["heading"] - T["heading"])).max() < 1e-10


def test_configuration_errors_name_the_key():
    kw = dict(rate=100.0, lat=LAT, lon=LON)
    with pytest.raises(ConfigError, match="speed"):
        generate(segments=[{"type": "accelerate", "sped": 3.0, "duration": 2.0}], **kw)
    with pytest.raises(ConfigError, match="static"):
        generate(speed=5.0, segments=[{"type": "static", "duration": 2.0}], **kw)
    with pytest.raises(ConfigError, match="duration"):
        generate(segments=[{"type": "turn", "angle": 1.0}], **kw)
    with pytest.raises(ConfigError, match="loop"):
        generate(segments=[{"type": "loop", "duration": 1.0}], **kw)
    with pytest.raises(ConfigError, match="climb"):
        generate(segments=[{"type": "climb", "height_change": 3.0, "duration": 5.0}], **kw)
    with pytest.raises(ConfigError, match="increase"):
        generate(waypoints=[{"time": 0.0}, {"time": 0.0, "east": 1.0}], **kw)
    with pytest.raises(ConfigError, match="walk"):
        generate(vehicle="pedestrian", segments=[{"type": "turn", "angle": 1.0, "rate": 0.1}],
                 **kw)


def test_duration_extends_and_truncates():
    segs = [{"type": "accelerate", "speed": 10.0, "duration": 4.0}]
    long = generate(rate=50.0, lat=LAT, lon=LON, segments=segs, duration=10.0).truth
    assert abs(long.index[-1] - 10.0) < 1e-9
    assert np.allclose(np.hypot(long.vel_e, long.vel_n).to_numpy()[-100:], 10.0)
    short = generate(rate=50.0, lat=LAT, lon=LON, segments=segs, duration=2.0, start_time=100.0)
    assert short.truth.index[0] == 100.0 and abs(short.truth.index[-1] - 102.0) < 1e-9
