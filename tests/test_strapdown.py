"""LLF strapdown mechanization: analytic cases, Schuler, bias error growth, duality, pyins."""

import numpy as np
import pandas as pd
import pytest
from mech_helpers import LAT45, dynamic_trajectory, enu_error, initial_state, static_increments

from insgnss.attitude import attitude_error, euler_to_dcm
from insgnss.earth import normal_gravity, radii, schuler_period
from insgnss.imu import increments_table
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import INSMechanization, NavState, mechanize


def _att_err(out, ref_C):
    C = euler_to_dcm(out["roll"].to_numpy(), out["pitch"].to_numpy(), out["heading"].to_numpy())
    return np.abs(attitude_error(C, ref_C)).max()


@pytest.mark.parametrize("update", ["exact", "first_order"])
def test_stationary_perfect_sensors_one_hour(update):
    imu, x0 = static_increments(3600.0, 100.0, LAT45, h=0.0, roll=0.02, pitch=-0.01, heading=1.0)
    out = mechanize(imu, x0, attitude_update=update)
    err = enu_error(out, pd.DataFrame({"lat": [x0.lat], "lon": [x0.lon],
                                       "height": [x0.height]}).iloc[np.zeros(len(out), int)])
    assert np.abs(err).max() < 1e-3
    assert np.abs(out[["vel_e", "vel_n", "vel_u"]].to_numpy()).max() < 1e-6
    assert _att_err(out, x0.C) < 1e-8


def _zero_crossings(t, x):
    s = np.sign(x)
    idx = np.nonzero(s[1:] * s[:-1] < 0)[0]
    return t[idx] - x[idx] * (t[idx + 1] - t[idx]) / (x[idx + 1] - x[idx])


def test_schuler_oscillation_period():
    """An initial 0.1 m/s east velocity error oscillates with the Schuler period."""
    imu, x0 = static_increments(3.0 * 3600, 10.0, LAT45)
    x0.vel = np.array([0.1, 0.0, 0.0])
    out = mechanize(imu, x0, fix_height=True)
    t = out.index.to_numpy()
    ve = out["vel_e"].to_numpy()
    zc = _zero_crossings(t, ve)
    period = 2.0 * np.mean(np.diff(zc))
    expected = schuler_period(LAT45)
    assert abs(period / expected - 1) < 0.005
    # the horizontal error stays bounded (oscillation, not drift): |dp| <= 0.1 / w_s + margin
    err = enu_error(out, out.iloc[np.zeros(len(out), int)])
    ws = 2 * np.pi / expected
    assert np.hypot(err[:, 0], err[:, 1]).max() < 1.1 * 2 * 0.1 / ws


@pytest.mark.parametrize("model", ["grs80_series", "inverse_square", "j2"])
def test_stationary_with_each_gravity_model(model):
    """The model reaches the step: sensors built with it keep the state at rest (and with a
    different model they do not)."""
    imu, x0 = static_increments(600.0, 100.0, LAT45, h=500.0, gravity_model=model)
    out = mechanize(imu, x0, gravity_model=model, fix_height=False)
    assert np.abs(out["vel_u"].to_numpy()).max() < 1e-9
    other = mechanize(imu, x0, gravity_model="somigliana")
    assert np.abs(other["vel_u"].to_numpy()).max() > 1e-7


def test_accelerometer_bias_error_growth():
    imu, x0 = static_increments(60.0, 100.0, LAT45)
    b = 1e-3  # m/s^2 on body x (= east at heading 0)
    imu.loc[imu.index[1:], "dv_x"] += b * 0.01
    out = mechanize(imu, x0)
    err = enu_error(out, out.iloc[np.zeros(len(out), int)])
    assert err[-1, 0] == pytest.approx(0.5 * b * 60.0**2, rel=0.02)


def test_gyro_bias_error_growth():
    imu, x0 = static_increments(60.0, 100.0, LAT45)
    eps = np.radians(10.0) / 3600  # 10 deg/h about body x (east): tilt -> north error
    imu.loc[imu.index[1:], "dtheta_x"] += eps * 0.01
    out = mechanize(imu, x0)
    err = enu_error(out, out.iloc[np.zeros(len(out), int)])
    g = normal_gravity(LAT45, 0.0)
    expected = g * eps * 60.0**3 / 6
    assert np.hypot(err[-1, 0], err[-1, 1]) == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("update", ["exact", "first_order"])
def test_duality_dynamic_trajectory(update):
    traj = dynamic_trajectory(600.0, 100.0)
    imu = inverse_mechanize(traj, attitude_update=update)
    out = mechanize(imu, initial_state(traj), attitude_update=update)
    assert np.abs(enu_error(out, traj)).max() < 1e-6
    ref_C = euler_to_dcm(traj["roll"].to_numpy(), traj["pitch"].to_numpy(),
                         traj["heading"].to_numpy())
    assert _att_err(out, ref_C) < 1e-9
    assert np.abs(out[["vel_e", "vel_n", "vel_u"]].to_numpy()
                  - traj[["vel_e", "vel_n", "vel_u"]].to_numpy()).max() < 1e-8


def test_first_order_update_differs_from_exact_for_large_steps():
    """The seed's first-order quaternion update under-rotates by 2 atan(a/2) vs a."""
    t = np.array([0.0, 1.0])
    rate = 0.5  # rad per step
    imu = increments_table(t, [[0, 0, 0], [0, 0, rate]], [[0, 0, 0], [0, 0, 9.8]])
    x0 = NavState(0.0, 0.0, 0.0)
    exact = mechanize(imu, x0, attitude_update="exact")["heading"].iloc[-1]
    first = mechanize(imu, x0, attitude_update="first_order")["heading"].iloc[-1]
    # rotation about body z (up) by +a turns heading by -a (counter-clockwise)
    w_ie_z = 7.2921151467e-5 * 0.0
    assert exact == pytest.approx(2 * np.pi - rate + w_ie_z, abs=1e-6)
    assert first == pytest.approx(2 * np.pi - 2 * np.arctan(rate / 2), abs=1e-6)


def test_rate_table_equals_increment_table_for_constant_rates():
    """Rates are integrated by the trapezoid rule: exact for constant rates."""
    inc, x0 = static_increments(600.0, 100.0, LAT45, roll=0.1, pitch=0.05, heading=2.0)
    x0.vel = np.array([3.0, -2.0, 0.0])
    rates = inc.to_numpy()[1:2] * 100.0
    rt = pd.DataFrame(np.repeat(rates, len(inc), axis=0), index=inc.index,
                      columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    a, b = mechanize(rt, x0), mechanize(inc, x0)
    assert np.abs(a.to_numpy() - b.to_numpy()).max() < 1e-9
    assert np.abs(enu_error(a, b)).max() < 1e-6


def test_seed_000_workflow():
    """The seed report's workflow: instantiate, feed 7-element samples, 120 s alignment."""
    lat0, lon0, h0 = np.radians(51.08), np.radians(-114.13), 1100.0
    imu, x0 = static_increments(180.0, 100.0, lat0, h0, roll=0.01, pitch=-0.02,
                                heading=np.radians(30.0), gravity_model="grs80_series")
    t = imu.index.to_numpy()
    w = imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy()[1:] * 100.0
    f = imu[["dv_x", "dv_y", "dv_z"]].to_numpy()[1:] * 100.0
    ins = INSMechanization(h0, lat0, lon0, accel_bias=0.0, gyro_bias=0.0, accel_sf=0.0,
                           gyro_sf=0.0, accel_no=np.zeros((3, 3)), gyro_no=np.zeros((3, 3)),
                           alignment_time=120.0)
    for k in range(len(w)):
        ins.process_measurement(np.concatenate([[t[k + 1]], w[k], f[k]]))
        if k == 100:
            assert not ins.get_params()["alignment_complete"]
    p = ins.get_params(degrees=True)
    assert p["alignment_complete"]
    assert p["roll"] == pytest.approx(np.degrees(0.01), abs=1e-6)
    assert p["pitch"] == pytest.approx(np.degrees(-0.02), abs=1e-6)
    assert p["azimuth"] == pytest.approx(30.0, abs=1e-4)
    assert p["lat"] == pytest.approx(np.degrees(lat0), abs=1e-9)
    assert abs(p["v_e"]) < 1e-6 and abs(p["v_u"]) < 1e-6
    # accessory methods
    N, M = INSMechanization.radii_of_curvature(lat0)
    assert (M, N) == pytest.approx(radii(lat0))
    R = INSMechanization.get_rotation_matrix(0.1, 0.2, 0.3)
    q = INSMechanization.matrix_to_normalized_quaternion(R)
    assert np.allclose(INSMechanization.quaternion_to_matrix(q), R)
    assert np.allclose(INSMechanization.vec_to_skew([1, 2, 3]) @ [4, 5, 6], np.cross([1, 2, 3],
                                                                                    [4, 5, 6]))
    assert np.allclose(R, INSMechanization.Rz(-0.3) @ INSMechanization.Rx(0.2)
                       @ INSMechanization.Ry(0.1))
    assert INSMechanization.gravity(lat0, h0) == pytest.approx(normal_gravity(lat0, h0), abs=2e-5)


def test_ins_mechanization_compensates_deterministic_errors():
    """Biases, scale factors and non-orthogonality given to the class are removed exactly."""
    lat0 = np.radians(45.0)
    imu, x0 = static_increments(130.0, 50.0, lat0, heading=0.7)
    t = imu.index.to_numpy()
    w = imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy()[1:] * 50.0
    f = imu[["dv_x", "dv_y", "dv_z"]].to_numpy()[1:] * 50.0
    bg, ba = np.array([1e-4, -2e-4, 5e-5]), np.array([0.02, -0.01, 0.03])
    S = np.diag([1e-3, -2e-3, 5e-4])
    N = np.array([[0, 1e-3, 0], [0, 0, -1e-3], [2e-3, 0, 0]])
    w_raw = w @ (np.eye(3) + S + N).T + bg
    f_raw = f @ (np.eye(3) + S + N).T + ba
    ins = INSMechanization(0.0, lat0, 0.0, ba, bg, S, S, N, N, alignment_time=120.0)
    for k in range(len(w)):
        ins.process_measurement(np.concatenate([[t[k + 1]], w_raw[k], f_raw[k]]))
    p = ins.get_params()
    assert p["azimuth"] == pytest.approx(0.7, abs=1e-5)
    assert np.hypot(p["v_e"], p["v_n"]) < 1e-5


def test_cross_check_with_pyins():
    """pyins integrating the same increments from the same state agrees within 1 cm."""
    pyins_strapdown = pytest.importorskip("pyins.strapdown")
    import numba
    import pyins._numba_integrate as pyins_kernel

    from insgnss.attitude import rfu_to_frd
    from insgnss.earth import gravity_somigliana

    # pyins' gravity has only the linear height term; give it our (separately tested) normal
    # gravity so that the comparison isolates the integration algorithms. Its integrate() is
    # compiled on first call (no cache), so replacing the global before that is effective.
    @numba.njit
    def _gravity_deg(lat_deg, alt):
        return gravity_somigliana(np.radians(lat_deg), alt)

    pyins_kernel.gravity = _gravity_deg
    pyins_kernel.integrate.recompile()

    traj = dynamic_trajectory(600.0, 100.0)
    imu = inverse_mechanize(traj)
    ours = mechanize(imu, initial_state(traj))
    t = imu.index.to_numpy()
    th = rfu_to_frd(imu[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy())[1:]
    dv = rfu_to_frd(imu[["dv_x", "dv_y", "dv_z"]].to_numpy())[1:]
    dv = dv + 0.5 * np.cross(th, dv)  # pyins expects the rotation-compensated increment
    inc = pd.DataFrame(np.column_stack([np.diff(t), th, dv]), index=t[1:],
                       columns=["dt", "theta_x", "theta_y", "theta_z", "dv_x", "dv_y", "dv_z"])
    r = traj.iloc[0]
    pva = pd.Series({"lat": np.degrees(r.lat), "lon": np.degrees(r.lon), "alt": r.height,
                     "VN": r.vel_n, "VE": r.vel_e, "VD": -r.vel_u, "roll": np.degrees(r.roll),
                     "pitch": np.degrees(r.pitch), "heading": np.degrees(r.heading)})
    integ = pyins_strapdown.Integrator(pva)
    theirs = integ.integrate(inc)
    th_df = pd.DataFrame({"lat": np.radians(theirs["lat"].to_numpy()),
                          "lon": np.radians(theirs["lon"].to_numpy()),
                          "height": theirs["alt"].to_numpy()})
    err = enu_error(th_df.iloc[-1:], ours.iloc[-1:])
    assert np.linalg.norm(err) < 0.01


@pytest.mark.parametrize("update", ["exact", "first_order"])
def test_seed_stage_methods_reproduce_strapdown_step(update):
    """v_and_r_integration, angular_velocity_compensation, attitude_integration (seed 000
    sections 2.4-2.6) called per interval reproduce the compiled step."""
    from insgnss.mechanization.strapdown import STEP_WORK_SHAPE, strapdown_step

    traj = dynamic_trajectory(20.0, 100.0)
    imu = inverse_mechanize(traj, attitude_update=update)
    x0 = initial_state(traj)
    ins = INSMechanization(x0.height, x0.lat, x0.lon, gravity_model="somigliana",
                           attitude_update=update)
    ins.vel, ins.C = x0.vel.copy(), x0.C.copy()
    pos, vel, C = np.array([x0.lat, x0.lon, x0.height]), x0.vel.copy(), x0.C.copy()
    work = np.empty(STEP_WORK_SHAPE)
    t = imu.index.to_numpy()
    inc = imu.to_numpy()
    for k in range(1, len(t)):
        dt = t[k] - t[k - 1]
        dth, dv = inc[k, :3], inc[k, 3:]
        strapdown_step(pos, vel, C, dth, dv, dt, 0, 0 if update == "exact" else 1, False, work)
        v1, p1 = ins.v_and_r_integration(dth, dv, dt)
        th_lb = ins.angular_velocity_compensation(dth, dt)
        r, p, a = ins.attitude_integration(th_lb)
    # the same compiled stages; exp(theta_lb) vs exp(-zeta) C exp(theta) differ by rounding
    assert np.abs(enu_error(pd.DataFrame([ins.pos], columns=["lat", "lon", "height"]),
                            pd.DataFrame([pos], columns=["lat", "lon", "height"]))).max() < 1e-9
    assert np.abs(ins.vel - vel).max() < 1e-11
    assert np.abs(ins.C - C).max() < 1e-13
    # theta_lb is the body rotation relative to the l-frame: about dtheta - C^T w_il dt
    assert np.abs(th_lb - dth).max() > 1e-9
    out = mechanize(imu, x0, attitude_update=update)
    assert (r, p, a) == pytest.approx(tuple(out[["roll", "pitch", "heading"]].iloc[-1]), abs=1e-12)


def test_seed_angular_velocity_compensation_alone_is_the_seed_eq16():
    """Without a preceding v_and_r_integration it uses the current state (seed eq. 15-16)."""
    lat = np.radians(50.0)
    ins = INSMechanization(0.0, lat, 0.0)
    ins.vel = np.array([20.0, 5.0, 0.0])
    ins.C = euler_to_dcm(0.1, 0.05, 1.0)
    dth = np.array([1e-4, -2e-4, 3e-4])
    th = ins.angular_velocity_compensation(dth, 0.01)
    M, N = radii(lat)
    w_il = np.array([-5.0 / M, 20.0 / N + 7.2921151467e-5 * np.cos(lat),
                     20.0 * np.tan(lat) / N + 7.2921151467e-5 * np.sin(lat)])
    # equal to second order (BCH term dtheta x C^T w_il dt / 2 ~ 1e-10)
    assert np.abs(th - (dth - ins.C.T @ w_il * 0.01)).max() < 3e-10


@pytest.mark.parametrize("call", [
    lambda: NavState.from_euler(45.07, 7.68, 240, heading=30),
    lambda: NavState(52.38, 0.17, 10.0),
    lambda: INSMechanization(60, 52.38, 9.72),
    lambda: INSMechanization.gravity(45.0, 0.0),
    lambda: INSMechanization.radii_of_curvature(-60.0),
])
def test_latitude_in_degrees_is_rejected(call):
    from insgnss.errors import InsgnssError

    with pytest.raises(InsgnssError, match="looks like degrees"):
        call()


def test_latitude_in_degrees_rejected_by_batch_entry_points():
    from insgnss.errors import InsgnssError
    from insgnss.mechanization.inverse import integrate_position

    traj = dynamic_trajectory(2.0, 10.0)
    bad = traj.copy()
    bad["lat"] = np.degrees(bad["lat"])
    with pytest.raises(InsgnssError, match="row 1.*looks like degrees|looks like degrees"):
        inverse_mechanize(bad)
    with pytest.raises(InsgnssError, match="looks like degrees"):
        integrate_position([0.0, 1.0], np.zeros((2, 3)), 45.0, 7.0, 0.0)
    x0 = initial_state(traj)
    x0.lat = 45.0  # mutated after construction
    with pytest.raises(InsgnssError, match="looks like degrees"):
        mechanize(inverse_mechanize(traj), x0)
    with pytest.raises(InsgnssError, match="not a latitude"):
        NavState(400.0, 0.0, 0.0)
    # the pole itself is a latitude
    assert NavState(np.pi / 2, 0.0, 0.0).lat == np.pi / 2
