"""Wander-azimuth mechanization: over the pole, duality, agreement with the ENU frame,
stationary at the pole, the wander condition."""

import numpy as np
import pytest
from mech_helpers import LAT45, dynamic_trajectory, initial_state, static_increments

from insgnss.attitude import euler_to_dcm, wrap_pi
from insgnss.earth import OMEGA_E, enu_to_ecef_dcm, geodetic_to_ecef, normal_gravity
from insgnss.imu import increments_table
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import INSMechanization, NavState, mechanize
from insgnss.mechanization.wander import wander_angles
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0
VEL = ["vel_e", "vel_n", "vel_u"]


def _ecef(df):
    return np.column_stack(geodetic_to_ecef(df["lat"].to_numpy(), df["lon"].to_numpy(),
                                            df["height"].to_numpy()))


def _x0(T):
    x0 = initial_state(T)
    x0.wander_angle = float(T["wander_angle"].iloc[0]) if "wander_angle" in T else 0.0
    return x0


def _att(df):
    return euler_to_dcm(df["roll"].to_numpy(), df["pitch"].to_numpy(), df["heading"].to_numpy())


def _att_err(a, b):
    from insgnss.attitude import attitude_error

    return np.abs(attitude_error(_att(a), _att(b))).max()


@pytest.fixture(scope="module")
def polar():
    """250 m/s, 1 km, from 89.5 N on lon 0 over the pole to lon 180 (450 s, 100 Hz)."""
    return generate(rate=100.0, lat=89.5 * D, lon=0.0, height=1000.0, heading=0.0, speed=250.0,
                    vehicle="aircraft", segments=[{"type": "hold", "duration": 450.0}],
                    frame="wander").truth


def test_polar_route_passes_over_the_pole(polar):
    lat = polar["lat"].to_numpy()
    assert np.degrees(lat[0]) == pytest.approx(89.5)
    assert np.degrees(lat[-1]) == pytest.approx(89.49, abs=0.01)
    assert polar["lon"].iloc[0] == 0.0 and abs(polar["lon"].iloc[-1]) == pytest.approx(np.pi)
    # closest sample within 2 m of the pole, none exactly on it
    d = (np.pi / 2 - lat) * 6.4e6
    assert 0.0 < d.min() < 2.0
    # the ENU heading flips from north to south while the wander heading stays
    assert polar["heading"].iloc[0] == pytest.approx(0.0)
    assert polar["heading"].iloc[-1] == pytest.approx(np.pi)
    a = polar["wander_angle"].to_numpy()
    assert abs(abs(a[-1]) - np.pi) < 1e-6


def test_over_the_pole_inverse_then_forward_within_1m(polar):
    imu = inverse_mechanize(polar, frame="wander")
    out = mechanize(imu, _x0(polar), frame="wander")
    assert np.linalg.norm(_ecef(out) - _ecef(polar), axis=1).max() < 1.0
    # in fact at rounding level of the ENU columns near the pole
    assert np.linalg.norm(_ecef(out) - _ecef(polar), axis=1).max() < 1e-4
    ecef_v = np.einsum("kij,kj->ki", enu_to_ecef_dcm(polar["lat"], polar["lon"]),
                       polar[VEL].to_numpy())
    ecef_o = np.einsum("kij,kj->ki", enu_to_ecef_dcm(out["lat"], out["lon"]), out[VEL].to_numpy())
    assert np.abs(ecef_o - ecef_v).max() < 1e-5
    assert np.abs(wrap_pi(out["wander_angle"].to_numpy() - polar["wander_angle"].to_numpy())).max() < 1e-6


def test_enu_frame_cannot_fly_over_the_pole(polar):
    out = mechanize(inverse_mechanize(polar), _x0(polar))
    err = np.linalg.norm(_ecef(out) - _ecef(polar), axis=1)
    assert not np.all(np.isfinite(err)) or np.nanmax(err) > 1e3


PLANE = [
    {"type": "hold", "duration": 5.0},
    {"type": "coordinated_turn", "angle": 180 * D, "bank": 25 * D},
    {"type": "climb", "height_change": 100.0, "rate": 5.0},
    {"type": "coordinated_turn", "angle": -90 * D, "duration": 20.0},
    {"type": "accelerate", "speed": 80.0, "duration": 10.0},
    {"type": "hold", "duration": 200.0},
]


@pytest.mark.parametrize("update", ["exact", "first_order"])
def test_duality_at_rounding_level_off_the_pole(update):
    T = generate(rate=100.0, lat=60 * D, lon=7 * D, height=1000.0, heading=250 * D, speed=60.0,
                 vehicle="aircraft", segments=PLANE, frame="wander", wander_angle=0.3).truth
    imu = inverse_mechanize(T, frame="wander", attitude_update=update)
    out = mechanize(imu, _x0(T), frame="wander", attitude_update=update)
    assert np.linalg.norm(_ecef(out) - _ecef(T), axis=1).max() < 1e-6
    assert np.abs(out[VEL].to_numpy() - T[VEL].to_numpy()).max() < 1e-8
    assert _att_err(out, T) < 1e-10
    assert np.abs(wrap_pi(out["wander_angle"].to_numpy() - T["wander_angle"].to_numpy())).max() < 1e-10


def test_wander_and_enu_agree_on_the_same_imu_data():
    """Both second-order steps on one trajectory: 10 minutes, within 0.1 mm."""
    traj = dynamic_trajectory(600.0, 100.0)
    imu = inverse_mechanize(traj)
    enu = mechanize(imu, initial_state(traj))
    x0 = initial_state(traj)
    x0.wander_angle = 1.0
    wan = mechanize(imu, x0, frame="wander")
    assert np.linalg.norm(_ecef(wan) - _ecef(enu), axis=1).max() < 1e-4
    assert np.abs(wan[VEL].to_numpy() - enu[VEL].to_numpy()).max() < 1e-6
    assert _att_err(wan, enu) < 1e-9


def test_wander_condition():
    """alpha follows d alpha/dt = -d lon/dt sin(lat) (seed 004 eq. 15)."""
    traj = dynamic_trajectory(600.0, 100.0, lat0=np.radians(70.0))
    x0 = initial_state(traj)
    out = mechanize(inverse_mechanize(traj), x0, frame="wander")
    a = out["wander_angle"].to_numpy()
    lat, lon = out["lat"].to_numpy(), out["lon"].to_numpy()
    expected = -np.concatenate([[0.0], np.cumsum(np.diff(lon) * np.sin(0.5 * (lat[1:] + lat[:-1])))])
    assert a[-1] != pytest.approx(0.0, abs=1e-3)  # the test moves the angle
    assert np.abs(a - expected).max() < 1e-7
    assert np.abs(wander_angles(lat, lon) - a).max() < 1e-10


@pytest.mark.parametrize("lat", [LAT45, np.pi / 2, -np.pi / 2 + 1e-9])
def test_stationary_including_the_pole(lat):
    """Perfect static sensors for 30 minutes: the wander frame stays put also exactly at a pole
    (where the ENU transport rate has tan(lat) = inf)."""
    imu, x0 = static_increments(1800.0, 100.0, lat, h=100.0, roll=0.01, pitch=-0.02, heading=1.0)
    x0.wander_angle = 0.4
    out = mechanize(imu, x0, frame="wander")
    p0 = np.array(geodetic_to_ecef(x0.lat, x0.lon, x0.height))
    assert np.linalg.norm(_ecef(out) - p0, axis=1).max() < 1e-3
    assert np.abs(out[VEL].to_numpy()).max() < 1e-6


def test_schuler_period_near_the_pole():
    """A 0.1 m/s velocity error at 89.9 N oscillates with the Schuler period."""
    from insgnss.earth import schuler_period

    lat = np.radians(89.9)
    imu, x0 = static_increments(3 * 3600.0, 10.0, lat)
    x0.vel = np.array([0.1, 0.0, 0.0])
    out = mechanize(imu, x0, frame="wander", fix_height=True)
    v = np.einsum("kij,kj->ki", enu_to_ecef_dcm(out["lat"], out["lon"]), out[VEL].to_numpy())
    v0 = v[0] / np.linalg.norm(v[0])
    s = v @ v0
    t = out.index.to_numpy()
    idx = np.nonzero(np.sign(s[1:]) * np.sign(s[:-1]) < 0)[0]
    zc = t[idx] - s[idx] * (t[idx + 1] - t[idx]) / (s[idx + 1] - s[idx])
    assert 2 * np.mean(np.diff(zc)) == pytest.approx(schuler_period(lat), rel=0.01)


def test_streaming_class_in_the_wander_frame_at_the_pole():
    """INSMechanization(frame="wander") aligned at the pole: it stays put (the ENU frame
    cannot even take a step there)."""
    lat = np.pi / 2
    imu, x0 = static_increments(200.0, 100.0, lat, h=50.0, heading=0.3)
    t = imu.index.to_numpy()
    w = imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy()[1:] * 100.0
    f = imu[["dv_x", "dv_y", "dv_z"]].to_numpy()[1:] * 100.0
    ins = INSMechanization(50.0, lat, 0.0, alignment_time=60.0, frame="wander",
                           gravity_model="somigliana", wander_angle=0.2)
    for k in range(len(w)):
        ins.process_measurement(np.concatenate([[t[k + 1]], w[k], f[k]]))
    p = ins.get_params()
    assert p["alignment_complete"]
    assert np.hypot(p["v_e"], p["v_n"]) < 1e-6
    assert p["h"] == pytest.approx(50.0, abs=1e-4)
    assert np.pi / 2 - p["lat"] < 1e-10
    assert "wander_angle" in p


def test_wander_gravity_and_earth_rate_at_the_pole():
    """One step from rest at the pole: specific force (0, 0, g) and Earth rate along up keep
    the state at rest (the step's Earth terms are right at the pole)."""
    g = normal_gravity(np.pi / 2, 0.0)
    imu = increments_table([0.0, 0.01], [[0, 0, 0], [0, 0, OMEGA_E * 0.01]],
                           [[0, 0, 0], [0, 0, g * 0.01]])
    out = mechanize(imu, NavState(np.pi / 2, 0.0, 0.0), frame="wander")
    assert np.abs(out[VEL].to_numpy()).max() < 1e-12
