"""Measurement models: H against numerical derivatives of h(nominal), and scenarios for ZUPT,
ZARU, CUPT, heading, odometer/NHC and lever arms."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from filter_sim import (
    DEG,
    car_outage_setup,
    car_truth,
    corrupt_imu,
    gnss_from_truth,
    initial_with_error,
    nav_errors,
    outage_end_error,
    outage_rms,
    perturbed_initial,
    static_truth,
    stop_windows,
)

from insgnss.attitude import dcm_to_euler, euler_to_dcm, rotvec_to_dcm
from insgnss.earth import enu_displacement_to_geodetic, radii
from insgnss.errors import InputFormatError, InvalidValueError
from insgnss.filter import (
    BodyVelocity,
    Cupt,
    FilterConfig,
    GnssPosition,
    GnssVelocity,
    Heading,
    NominalState,
    StateLayout,
    Zaru,
    Zupt,
    run_filter,
)
from insgnss.imu import grade


def _nav(layout, lat=0.8, lon=0.2, h=120.0, vel=(3.0, -8.0, 0.4), rpy=(0.1, -0.2, 2.0),
         omega=(0.02, -0.05, 0.3), params=None):
    nav = NominalState()
    nav.layout = layout
    nav.time = 10.0
    nav.lat, nav.lon, nav.height = lat, lon, h
    nav.vel = np.array(vel, float)
    nav.C = euler_to_dcm(*rpy)
    nav.omega_ib = np.array(omega, float)
    nav.omega_ib_mean = nav.omega_ib.copy()
    nav.f_ib = np.array([0.1, 0.2, 9.8])
    nav.f_ib_mean = nav.f_ib.copy()
    nav.segment_duration = 0.5
    nav.params = np.zeros(layout.n - 9) if params is None else np.array(params, float)
    nav.M, nav.N = radii(lat)
    nav.gyro_psd = np.full(3, 1e-8)
    return nav


def _perturbed(nav, d):
    """The nominal moved by the error-state vector d (nominal minus true convention)."""
    out = _nav(nav.layout, params=nav.params + d[9:])
    M, N = radii(nav.lat)
    out.lat = nav.lat + d[1] / (M + nav.height)
    out.lon = nav.lon + d[0] / ((N + nav.height) * np.cos(nav.lat))
    out.height = nav.height + d[2]
    out.M, out.N = radii(out.lat)
    out.vel = nav.vel + d[3:6]
    out.C = rotvec_to_dcm(d[6:9]) @ nav.C
    # a larger gyro-bias estimate means a smaller compensated rate
    out.omega_ib = nav.omega_ib - d[9:12]
    out.omega_ib_mean = nav.omega_ib_mean - d[9:12]
    out.f_ib = nav.f_ib - d[12:15]  # and of the accelerometer bias, a smaller specific force
    out.f_ib_mean = nav.f_ib_mean - d[12:15]
    out.segment_duration = nav.segment_duration
    return out


def _check_jacobian(meas, nav, i=0, eps=None):
    z0, H, R = meas.evaluate(i, nav)
    n = nav.layout.n
    if eps is None:  # large enough for float64 lat/lon, small enough for the curvature
        eps = np.full(n, 1e-6)
        eps[0:3] = 1e-2
        eps[3:6] = 1e-4
    num = np.zeros_like(H)
    for k in range(n):
        d = np.zeros(n)
        d[k] = eps[k]
        zp = meas.evaluate(i, _perturbed(nav, d))[0]
        zm = meas.evaluate(i, _perturbed(nav, -d))[0]
        num[:, k] = (zp - zm) / (2 * eps[k])
    bad = ~np.isclose(H, num, atol=1e-6, rtol=1e-5)
    assert not bad.any(), (np.argwhere(bad), H[bad], num[bad])
    assert R.shape == (z0.size, z0.size) and np.all(np.linalg.eigvalsh(R) > 0)
    return z0, H


def _gnss_table(nav, lever=(0, 0, 0)):
    return pd.DataFrame({"lat": [nav.lat + 1e-7], "lon": [nav.lon - 2e-7], "height": [nav.height + 0.7],
                         "east_std": [0.5], "north_std": [0.6], "up_std": [1.0],
                         "vel_e": [3.1], "vel_n": [-7.9], "vel_u": [0.3],
                         "vel_e_std": [0.05], "vel_n_std": [0.05], "vel_u_std": [0.1]},
                        index=pd.Index([10.0], name="time"))


def test_gnss_position_jacobian_and_value():
    lay = StateLayout()
    nav = _nav(lay)
    g = _gnss_table(nav)
    m = GnssPosition(g, lever_arm=(0.3, 1.2, 0.8))
    z, H = _check_jacobian(m, nav)
    la = nav.C @ np.array([0.3, 1.2, 0.8])
    M, N = radii(nav.lat)
    expect = np.array([2e-7 * (N + nav.height) * np.cos(nav.lat), -1e-7 * (M + nav.height), -0.7]) + la
    assert np.allclose(z, expect, atol=1e-6)


def test_gnss_position_across_the_antimeridian_is_metres():
    """The compiled GNSS position model wraps the longitude difference (as
    NominalState.enu_offset): a fix 2e-7 rad east of the nominal across +-pi gives metres."""
    lay = StateLayout()
    lon = np.pi - 1e-7
    nav = _nav(lay, lon=lon)
    g = _gnss_table(nav)
    g["lon"] = -np.pi + 1e-7  # 2e-7 rad east of the nominal, across the antimeridian
    z, H, R = GnssPosition(g).evaluate(0, nav)
    _, N = radii(nav.lat)
    assert z[0] == pytest.approx(-2e-7 * (N + nav.height) * np.cos(nav.lat), abs=1e-6)
    np.testing.assert_allclose(z, nav.enu_offset(*g[["lat", "lon", "height"]].iloc[0]),
                               rtol=0, atol=1e-9)
    np.testing.assert_array_equal(np.diag(R), [0.25, 0.36, 1.0])
    assert H.shape == (3, lay.n) and np.array_equal(H[:, 0:3], np.eye(3))


def test_gnss_velocity_jacobian_with_lever_arm():
    lay = StateLayout()
    nav = _nav(lay)
    m = GnssVelocity(_gnss_table(nav), lever_arm=(0.3, 1.2, 0.8))
    _, H = _check_jacobian(m, nav)
    assert np.any(H[:, 9:12] != 0) and np.any(H[:, 6:9] != 0)


def test_zupt_zaru_cupt_heading_jacobians():
    lay = StateLayout(True)
    nav = _nav(lay)
    _check_jacobian(Zupt([10.0], std=0.01), nav)
    zaru_nav = _nav(lay, vel=(0, 0, 0), omega=(1e-5, 3e-5, 4e-5))
    z, H = _check_jacobian(Zaru([10.0], std=1e-4), zaru_nav)
    assert np.allclose(H[:, 9:12], -np.eye(3))
    _check_jacobian(Cupt([10.0], nav.lat, nav.lon, nav.height, std=0.05, lever_arm=(0, 0.5, -1)), nav)
    z, H = _check_jacobian(Heading([10.0], [2.01], std=0.01), nav)
    assert z[0] == pytest.approx(-0.01, abs=1e-9)
    # heading wraps across north
    zw = Heading([10.0], [2 * np.pi - 0.01], std=0.01).evaluate(0, _nav(lay, rpy=(0, 0, 0.02)))[0]
    assert zw[0] == pytest.approx(0.03, abs=1e-9)


def test_body_velocity_jacobian_with_scale_and_misalignment():
    m = BodyVelocity([10.0], values=[[0.05, 8.2, -0.02]], axes=(0, 1, 2), std=0.1,
                     lever_arm=(0.2, -1.5, -0.4), scale_state="odo_scale", scale_axis=1,
                     misalignment_state="mis")
    lay = StateLayout(False, m.extra_states())
    assert lay.n == 19
    nav = _nav(lay, params=np.r_[np.zeros(6), 0.02, 0.01, -0.005, 0.03])
    _, H = _check_jacobian(m, nav)
    assert H[1, lay["odo_scale"]][0] != 0 and np.any(H[:, lay["mis"]] != 0)
    nhc = BodyVelocity(np.arange(3.0), values=0.0, axes=(0, 2), std=[0.1, 0.2])
    assert nhc.values.shape == (3, 2) and np.allclose(nhc.std[:, 1], 0.2)


def test_nhc_pitch_compliance_value_and_jacobian():
    """The vertical NHC with a suspension pitch-compliance state: a body pitched up by
    kappa a_f from its velocity (squat) satisfies it exactly; H (velocity, attitude, forward
    accelerometer bias, kappa) matches the numerical derivatives."""
    m = BodyVelocity([10.0], values=0.0, axes=(0, 2), std=0.1, misalignment_state="mis",
                     pitch_compliance_state="kappa")
    lay = StateLayout(False, m.extra_states())
    kappa, speed, pitch_road = 0.006, 12.0, 0.03
    a_f = 1.5  # forward acceleration [m/s^2]: the body is pitched up by kappa a_f
    pitch = pitch_road + kappa * a_f
    vel = speed * np.array([np.cos(pitch_road) * np.sin(0.4), np.cos(pitch_road) * np.cos(0.4),
                            np.sin(pitch_road)])
    nav = _nav(lay, vel=vel, rpy=(0.0, pitch, 0.4), omega=(0.0, 0.0, 0.0),
               params=np.r_[np.zeros(6), 0.0, 0.0, 0.0, kappa])
    from insgnss.earth import normal_gravity
    g = normal_gravity(nav.lat, nav.height)
    # specific force of that forward acceleration: a_f = f_y - g C[2, 1]
    nav.f_ib = nav.f_ib_mean = np.array([0.0, a_f + g * nav.C[2, 1], g * nav.C[2, 2]])
    z = m.evaluate(0, nav)[0]
    # exactly up to the small-angle term v ((kappa a_f)^3 / 3 - ...): 3e-6 m/s here
    assert abs(z[1]) < 1e-5 and abs(z[0]) < 1e-9
    # without the term the NHC reads the squat as a vertical velocity -v sin(kappa a_f)
    z0 = BodyVelocity([10.0], values=0.0, axes=(0, 2), std=0.1).evaluate(0, _nav(
        StateLayout(), vel=vel, rpy=(0.0, pitch, 0.4), omega=(0.0, 0.0, 0.0)))[0]
    assert z0[1] == pytest.approx(-speed * np.sin(kappa * a_f), rel=1e-9)
    # the Jacobian at a general nominal (rates, misalignment, lever arm-free)
    nav2 = _nav(lay, params=np.r_[np.zeros(6), 0.01, -0.02, 0.005, 0.008])
    nav2.f_ib = nav2.f_ib_mean = np.array([0.3, 1.1, 9.7])
    _, H = _check_jacobian(m, nav2)
    assert H[1, lay.index("kappa")] != 0 and H[1, 13] != 0 and H[0, lay.index("kappa")] == 0
    with pytest.raises(ValueError, match="vertical axis"):
        BodyVelocity([1.0], axes=(0,), pitch_compliance_state="kappa")


def test_gnss_quality_weighting_and_missing_columns():
    idx = pd.Index([0.0, 1.0, 2.0], name="time")
    g = pd.DataFrame({"lat": 0.8, "lon": 0.1, "height": 10.0, "east_std": 0.02, "north_std": 0.02,
                      "up_std": 0.04, "q": [1, 2, 5]}, index=idx)
    m = GnssPosition(g, std_scale={1: 1.0, 2: 5.0, 5: 50.0}, min_std=0.05)
    assert np.allclose(m.std[:, 0], [0.05, 0.1, 1.0])
    m2 = GnssPosition(g, use_q=[1, 2])
    assert list(m2.valid) == [True, True, False]
    assert m2.evaluate(2, _nav(StateLayout())) is None
    with pytest.raises(InputFormatError):
        GnssPosition(g.drop(columns=["east_std"]))
    assert GnssPosition(g.drop(columns=["east_std", "north_std", "up_std"]), std=2.0).std[0, 2] == 2.0
    with pytest.raises(InputFormatError):
        GnssVelocity(g)


# --- scenarios ----------------------------------------------------------------------------------
def _stop_indices(truth, guard=0.5):
    t = truth.index.to_numpy()
    m = np.zeros(t.size, bool)
    for a, b in stop_windows(truth):
        m |= (t >= a + guard) & (t <= b)
    return m


def test_zupt_bounds_velocity_error_at_stops_mems():
    truth = car_truth(200.0, 100.0, stops_after=(0, 1))
    assert len(stop_windows(truth)) == 2
    model = grade("mems")
    rng = np.random.default_rng(11)
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng, horizontal_std=1.5, vertical_std=3.0)
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.01, 0.01, 0.05))
    t = truth.index.to_numpy()
    in_stop = _stop_indices(truth, guard=0.0)
    zupt = Zupt(t[in_stop][::10], std=0.005)  # 10 Hz during the stops
    cfg = FilterConfig(imu_model=model, initial_att_std=(0.01, 0.01, 0.05))
    res = run_filter(imu, init, [GnssPosition(gnss), zupt], cfg)
    err = nav_errors(res.forward, truth)
    vel_err = np.linalg.norm(err[["vel_e", "vel_n", "vel_u"]].to_numpy(), axis=1)
    stop = _stop_indices(truth, guard=0.5)
    print(f"max velocity error in stops: ZUPT {vel_err[stop].max():.4f} m/s")
    assert vel_err[stop].max() < 0.01
    # without ZUPT the velocity error in the stops is much larger
    res0 = run_filter(imu, init, [GnssPosition(gnss)], cfg)
    err0 = nav_errors(res0.forward, truth)
    v0 = np.linalg.norm(err0[["vel_e", "vel_n", "vel_u"]].to_numpy(), axis=1)
    assert v0[stop].max() > 3 * vel_err[stop].max()


def test_zaru_estimates_vertical_gyro_bias_mems():
    truth = static_truth(60.0, 100.0, heading=1.0)
    model = grade("mems")
    rng = np.random.default_rng(5)
    bias0 = np.r_[0.05, -0.08, 0.1, 0.1, -0.1, 0.15] * np.r_[DEG, DEG, DEG, 1, 1, 1]
    imu, errs = corrupt_imu(truth, model, rng, bias="constant", bias0=bias0)
    init = initial_with_error(truth, np.r_[0, 0, 0, 0, 0, 0, 0.002, -0.002, 0.02])
    t = truth.index.to_numpy()
    ms = [Zupt(t[10::10], std=0.005), Zaru(t[10::10])]
    res = run_filter(imu, init, ms, FilterConfig(imu_model=model, initial_att_std=(0.01, 0.01, 0.05)))
    bz_true = errs["gyro_bias"][-1, 2]
    bz_est = res.forward["gyro_bias_z"].iloc[-1]
    print(f"vertical gyro bias: true {bz_true:.3e}, ZARU estimate {bz_est:.3e} rad/s "
          f"({100 * abs(bz_est - bz_true) / abs(bz_true):.2f} % error)")
    assert abs(bz_est - bz_true) < 0.2 * abs(bz_true)
    # the horizontal gyro biases too, and much better than 20 %
    assert np.allclose(res.forward[["gyro_bias_x", "gyro_bias_y"]].iloc[-1], errs["gyro_bias"][-1, :2],
                       rtol=0.05)
    # ZUPT alone cannot see the vertical gyro bias
    res0 = run_filter(imu, init, ms[:1], FilterConfig(imu_model=model, initial_att_std=(0.01, 0.01, 0.05)))
    assert abs(res0.forward["gyro_bias_z"].iloc[-1] - bz_true) > 0.5 * abs(bz_true)


def test_cupt_removes_accumulated_error():
    truth = car_truth(280.0, 50.0, stops_after=(4,))
    (s0, s1), = stop_windows(truth)
    assert s0 > 200.0 and s1 < 280.0
    model = grade("tactical")
    rng = np.random.default_rng(21)
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng)
    gnss = gnss[gnss.index < 100.0]  # GNSS lost after 100 s
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    t_cp = float(np.round(0.5 * (s0 + s1)))
    cp = truth.loc[t_cp]
    sigma = 0.05
    cp_err = rng.standard_normal(3) * sigma  # the surveyed coordinates have their own error
    dlat, dlon, dh = enu_displacement_to_geodetic(cp["lat"], cp["height"], *cp_err)
    cupt = Cupt([t_cp], cp["lat"] + dlat, cp["lon"] + dlon, cp["height"] + dh, std=sigma)
    t = truth.index.to_numpy()
    zupt = Zupt(t[(t >= s0 + 0.5) & (t <= s1)][::5], std=0.005)
    cfg = FilterConfig(imu_model=model, initial_att_std=(0.005, 0.005, 0.02))
    before = nav_errors(run_filter(imu, init, [GnssPosition(gnss), zupt], cfg).forward, truth)
    res = run_filter(imu, init, [GnssPosition(gnss), zupt, cupt], cfg)
    err = nav_errors(res.forward, truth)
    e_before = np.hypot(before.loc[t_cp, "east"], before.loc[t_cp, "north"])
    assert e_before > 20 * sigma  # the coast accumulated a real error
    e_after = err.loc[t_cp, ["east", "north", "up"]].to_numpy()
    print(f"CUPT: horizontal error before {e_before:.2f} m, after {np.hypot(*e_after[:2]):.3f} m "
          f"(control point error {np.hypot(*cp_err[:2]):.3f} m, sigma {sigma} m)")
    # the solution moves onto the control point: what is left is the point's own error
    assert np.all(np.abs(e_after - cp_err) < 0.2 * sigma)
    assert np.all(res.forward.loc[t_cp, ["east_std", "north_std", "up_std"]] <= sigma)
    # and stays there for the rest of the stop (ZUPT)
    rest = (t > t_cp) & (t <= s1)
    assert np.all(np.abs(err[["east", "north"]].to_numpy()[rest] - cp_err[:2]) < 0.5 * sigma)


def test_heading_measurement_aligns_static_heading():
    truth = static_truth(60.0, 100.0, heading=0.3)
    model = grade("tactical")
    rng = np.random.default_rng(8)
    imu, _ = corrupt_imu(truth, model, rng)
    init = initial_with_error(truth, np.r_[0, 0, 0, 0, 0, 0, 0, 0, 5 * DEG])
    t = truth.index.to_numpy()
    meas_t = t[100::100]
    sig = 0.5 * DEG
    hd = Heading(meas_t, 0.3 + rng.standard_normal(meas_t.size) * sig, std=sig)
    cfg = FilterConfig(imu_model=model, initial_att_std=(0.002, 0.002, 10 * DEG))
    res = run_filter(imu, init, [Zupt(meas_t, std=0.01), hd], cfg)
    err = nav_errors(res.forward, truth)
    assert abs(err["heading"].iloc[-1]) < 3 * res.forward["heading_std"].iloc[-1]
    assert res.forward["heading_std"].iloc[-1] < sig / np.sqrt(30)


def test_odometer_scale_and_nhc_estimated():
    truth = car_truth(300.0, 50.0)
    model = grade("tactical")
    rng = np.random.default_rng(4)
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng)
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    C = euler_to_dcm(truth["roll"].to_numpy(), truth["pitch"].to_numpy(), truth["heading"].to_numpy())
    vb = np.einsum("kji,kj->ki", C, truth[["vel_e", "vel_n", "vel_u"]].to_numpy())
    t = truth.index.to_numpy()
    rows = np.arange(0, t.size, 5)  # 10 Hz
    k_true = 0.03
    speed = (1 + k_true) * vb[rows, 1] + rng.standard_normal(rows.size) * 0.02
    odo = BodyVelocity(t[rows], speed, axes=(1,), std=0.02, scale_state="odometer_scale",
                       scale_std=0.05, name="odometer")
    nhc = BodyVelocity(t[rows], 0.0, axes=(0, 2), std=0.05, name="nhc")
    cfg = FilterConfig(imu_model=model, initial_att_std=(0.005, 0.005, 0.02))
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss), odo, nhc], cfg)
    k_est = res.forward["odometer_scale"].iloc[-1]
    k_std = res.forward["odometer_scale_std"].iloc[-1]
    assert abs(k_est - k_true) < max(3 * k_std, 1e-3) and k_std < 2e-3
    assert set(res.innovations["type"]) == {"gnss_pos", "gnss_vel", "odometer", "nhc"}


def test_lever_arm_is_needed_and_used():
    truth = car_truth(200.0, 50.0)
    model = grade("tactical")
    rng = np.random.default_rng(9)
    imu, _ = corrupt_imu(truth, model, rng)
    arm = np.array([0.6, 1.8, 1.2])
    gnss = gnss_from_truth(truth, rng, horizontal_std=0.05, vertical_std=0.1, velocity_std=0.01,
                           vertical_velocity_std=0.02, lever_arm=arm)
    init, _ = perturbed_initial(truth, rng, 0.05, 0.01, (0.005, 0.005, 0.02))
    cfg = FilterConfig(imu_model=model, initial_pos_std=0.1, initial_vel_std=0.05,
                       initial_att_std=(0.005, 0.005, 0.02), gate_probability=None)
    good = run_filter(imu, init, [GnssPosition(gnss, lever_arm=arm), GnssVelocity(gnss, lever_arm=arm)], cfg)
    bad = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    nis_good = good.innovations.groupby("type")["nis"].mean()
    nis_bad = bad.innovations.groupby("type")["nis"].mean()
    assert nis_good["gnss_pos"] < 4.5 and nis_good["gnss_vel"] < 4.5
    assert nis_bad["gnss_pos"] > 3 * nis_good["gnss_pos"]
    assert nis_bad["gnss_vel"] > 3 * nis_good["gnss_vel"]
    eg = nav_errors(good.forward, truth)
    eb = nav_errors(bad.forward, truth)
    rms_good = np.sqrt(np.mean(eg["east"] ** 2 + eg["north"] ** 2))
    rms_bad = np.sqrt(np.mean(eb["east"] ** 2 + eb["north"] ** 2))
    print(nis_good.to_dict(), nis_bad.to_dict(), rms_good, rms_bad)
    assert rms_good < 0.1 and rms_bad > 10 * rms_good


KAPPA_SQUAT = np.radians(3.0) / 9.80665


def _squatting_car(kappa, duration, rate=50.0):
    """car_truth whose body pitches up by ``kappa a_f`` from its path (suspension squat/dive;
    ``a_f`` the forward acceleration, low-passed over 0.5 s like a suspension)."""
    truth = car_truth(duration, rate)
    t = truth.index.to_numpy()
    C = euler_to_dcm(truth["roll"].to_numpy(), truth["pitch"].to_numpy(), truth["heading"].to_numpy())
    a = np.gradient(truth[["vel_e", "vel_n", "vel_u"]].to_numpy(), t, axis=0)
    n = int(0.5 * rate)
    a_f = np.convolve(np.einsum("ki,ki->k", a, C[:, :, 1]), np.ones(n) / n, mode="same")
    out = truth.copy()
    out["pitch"] = truth["pitch"] + kappa * a_f
    return out


def test_nhc_pitch_compliance_estimated_and_removes_outage_drift():
    """A car squats 3 deg/g. Its vertical NHC without the compliance state reads the squat as a
    pitch error; with the gyros loosely trusted (a noise model at the level of a running
    engine's vibration, 20 times the white noise, as a static window measures it) that tilts
    gravity into the forward channel and the 15 s outages drift. The compliance state is
    recovered (within 3 sigma, sigma < 15 %) and halves the end-of-outage error."""
    kappa = np.radians(3.0) / 9.80665
    truth = _squatting_car(kappa, 240.0)
    outages = [(100.0 + 45 * k, 115.0 + 45 * k) for k in range(3)]
    imu, init, gnss, tn, cfg = car_outage_setup(truth, np.random.default_rng(7), outages)
    ends = {}
    for state in (None, "kappa"):
        nhc = BodyVelocity(tn, 0.0, axes=(0, 2), std=0.1, name="nhc", pitch_compliance_state=state)
        res = run_filter(imu, init, [*gnss, nhc], cfg)
        ends[state] = outage_end_error(res.forward, truth, outages)
        if state:
            k_est, k_std = res.forward["kappa"].iloc[-1], res.forward["kappa_std"].iloc[-1]
            assert abs(k_est - kappa) < 3 * k_std and k_std < 0.15 * kappa, (k_est, k_std)
    assert ends["kappa"] < 0.6 * ends[None], ends


def test_nhc_misalignment_states_remove_the_drift_of_a_residual_mounting():
    """The squatting car with its IMU turned from the vehicle axes by a residual mounting of
    0.6 deg pitch and -1.0 deg yaw (a lateral IMU velocity of 0.26 m/s at 15 m/s): the NHC
    without misalignment states reads it as velocity and heading errors and the 15 s outages
    drift; with them the pitch and yaw residuals are recovered (within 3 sigma, sigma below
    0.1 deg) and the drift falls to that of a car without a residual mounting (within 10 %)."""
    mu = np.radians([0.6, 0.0, -1.0])
    ends = {}
    for case, m, state in (("mounted", mu, None), ("mounted", mu, "mis"),
                           ("aligned", np.zeros(3), None)):
        truth = _squatting_car(KAPPA_SQUAT, 240.0)
        C = euler_to_dcm(truth["roll"].to_numpy(), truth["pitch"].to_numpy(),
                         truth["heading"].to_numpy()) @ rotvec_to_dcm(m)
        truth["roll"], truth["pitch"], truth["heading"] = dcm_to_euler(C)
        outages = [(55.0 + 45 * k, 70.0 + 45 * k) for k in range(4)]
        imu, init, gnss, tn, cfg = car_outage_setup(truth, np.random.default_rng(7), outages)
        nhc = BodyVelocity(tn, 0.0, axes=(0, 2), std=0.1, name="nhc",
                           pitch_compliance_state="kappa", misalignment_state=state)
        res = run_filter(imu, init, [*gnss, nhc], cfg)
        ends[case, state] = outage_end_error(res.forward, truth, outages)
        if state:
            # C_b = C_v exp([mu x]): the vehicle velocity is (I + [mu x]) v_b, the state -mu
            last = res.forward.iloc[-1]
            for ax in ("x", "z"):
                est, std = last[f"mis_{ax}"], last[f"mis_{ax}_std"]
                true = -m["xyz".index(ax)]
                assert abs(est - true) < 3 * std and std < np.radians(0.1), (ax, est, true, std)
    assert ends["mounted", "mis"] < 0.6 * ends["mounted", None], ends
    assert ends["mounted", "mis"] < 1.1 * ends["aligned", None], ends


def test_nhc_violation_states_value_jacobian_and_process():
    """The Gauss-Markov violation states add to the constrained components (z = v_v + s),
    H matches the numerical derivatives, and the block is a first-order Gauss-Markov process
    of the given sigma and correlation time (driving PSD 2 sigma^2 / tau)."""
    m = BodyVelocity([10.0], values=0.0, axes=(0, 2), std=0.02, misalignment_state="mis",
                     pitch_compliance_state="kappa", violation_state="slip",
                     violation_std=[0.1, 0.05], violation_tau=1.5)
    ex = {e.name: e for e in m.extra_states()}["slip"]
    assert ex.size == 2 and ex.tau == 1.5 and ex.labels == ("slip_x", "slip_z")
    assert ex.initial_std == pytest.approx((0.1, 0.05))
    assert ex.psd == pytest.approx((2 * 0.01 / 1.5, 2 * 0.0025 / 1.5))
    lay = StateLayout(False, m.extra_states())
    base = np.r_[np.zeros(6), 0.01, 0.0, -0.02, 0.004]
    z0 = m.evaluate(0, _nav(lay, params=np.r_[base, 0.0, 0.0]))[0]
    nav = _nav(lay, params=np.r_[base, 0.07, -0.03])
    z, H = _check_jacobian(m, nav)
    assert z - z0 == pytest.approx([0.07, -0.03], abs=1e-12)
    assert np.allclose(H[:, lay["slip"]], np.eye(2))
    with pytest.raises(InvalidValueError):
        BodyVelocity([10.0], violation_state="slip", violation_tau=0.0)
    with pytest.raises(ValueError):
        BodyVelocity([10.0], violation_state="slip", high_rate=True)


def test_nhc_violation_states_on_a_slipping_car():
    """A car whose body slips sideways by a Gauss-Markov 0.1 m/s (0.05 m/s heave, 2 s): the
    white NHC at that sigma lets the constraint steer the outages; Gauss-Markov violation
    states of the same sigma and a 1 s correlation time (not the true 2 s) cut the forward
    end-of-outage error by 10 % and the smoothed in-outage RMS by a third."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
    from bench_nhc_sigma import slipping_car

    rng = np.random.default_rng(300)
    truth = slipping_car(rng, 0.1, 2.0, duration=200.0)
    outages = [(40.0 + 45 * k, 55.0 + 45 * k) for k in range(4)]
    imu, init, gnss, tn, cfg = car_outage_setup(truth, rng, outages, smoother=True)
    out = {}
    for case, kw in (("white", {"std": 0.1}),
                     ("violation", {"std": 0.02, "violation_state": "slip",
                                    "violation_std": 0.1, "violation_tau": 1.0})):
        nhc = BodyVelocity(tn, 0.0, axes=(0, 2), name="nhc", pitch_compliance_state="kappa",
                           misalignment_state="mis", **kw)
        res = run_filter(imu, init, [*gnss, nhc], cfg)
        out[case] = (outage_end_error(res.forward, truth, outages),
                     outage_rms(res.smoothed, truth, outages))
    assert out["violation"][0] < 0.9 * out["white"][0], out
    assert out["violation"][1] < 0.67 * out["white"][1], out


def test_nhc_lateral_sigma_grows_with_yaw_rate_times_speed_squared():
    """sigma_lat^2 = std^2 + (k |w_z| v^2)^2 with v the forward velocity of the point: 15 m/s
    forward at 0.2 rad/s and k = 0.01 give 0.45 m/s of slip sigma; the vertical axis and a
    straight run keep their sigma; the lever arm to the rear axle adds w x l (issue 22)."""
    lay = StateLayout()
    # heading 0, level: body forward = north
    straight = _nav(lay, vel=(0.0, 15.0, 0.0), rpy=(0.0, 0.0, 0.0), omega=(0.0, 0.0, 0.0))
    turning = _nav(lay, vel=(0.0, 15.0, 0.0), rpy=(0.0, 0.0, 0.0), omega=(0.0, 0.0, 0.2))
    nhc = BodyVelocity([10.0], 0.0, axes=(0, 2), std=[0.1, 0.05], slip_gradient=0.01)
    _, _, R = nhc.evaluate(0, straight)
    assert np.sqrt(np.diag(R)) == pytest.approx([0.1, 0.05])
    _, _, R = nhc.evaluate(0, turning)
    assert np.sqrt(R[0, 0]) == pytest.approx(np.hypot(0.1, 0.01 * 0.2 * 15.0**2), rel=1e-12)
    assert np.sqrt(R[1, 1]) == pytest.approx(0.05)
    _, _, R0 = BodyVelocity([10.0], 0.0, axes=(0, 2), std=[0.1, 0.05]).evaluate(0, turning)
    assert np.sqrt(R0[0, 0]) == pytest.approx(0.1)
    # rear axle 1.5 m behind the IMU: turning left (w_z > 0) moves it to the right at 0.3 m/s
    rear = BodyVelocity([10.0], 0.0, axes=(0, 2), std=0.1, lever_arm=(0.0, -1.5, 0.0))
    z, _, _ = rear.evaluate(0, turning)
    assert z[0] == pytest.approx(0.3, abs=1e-9)
    _check_jacobian(BodyVelocity([10.0], 0.0, axes=(0, 2), std=0.1, slip_gradient=0.01,
                                 lever_arm=(0.1, -1.5, -0.6)), _nav(lay))
    with pytest.raises(InvalidValueError):
        BodyVelocity([10.0], slip_gradient=-1.0)


@pytest.mark.parametrize("aiding,key", [
    ({"nhc_correlation_time": -1.0}, "aiding.nhc_correlation_time"),
    ({"nhc_correlation_time": 1.0, "nhc_white_std": [0.02, 0.0]}, "aiding.nhc_white_std"),
])
def test_nhc_violation_job_keys_are_range_checked(aiding, key):
    from insgnss.config import load_job_dict
    from insgnss.errors import ConfigError

    with pytest.raises(ConfigError) as exc:
        load_job_dict({"job": {"platform": "car"}, "aiding": aiding}, "job.toml")
    assert exc.value.column == key and "job.toml" in str(exc.value)


def test_nhc_violation_job_keys_reach_the_constraint():
    """aiding.nhc_correlation_time > 0: the job's NHC carries Gauss-Markov violation states of
    sigma aiding.nhc_std and white sigma aiding.nhc_white_std; 0 (the default) keeps the
    white constraint of sigma aiding.nhc_std."""
    from insgnss.config import load_job_dict
    from insgnss.job.aiding import build_aiding

    truth = car_truth(20.0, 50.0)
    imu, _ = corrupt_imu(truth, grade("consumer"), np.random.default_rng(1))
    for tau in (0.0, 1.5):
        job = load_job_dict({"job": {"platform": "car"},
                             "aiding": {"zupt": False, "zaru": False, "nhc_std": [0.1, 0.05],
                                        "nhc_correlation_time": tau,
                                        "nhc_white_std": [0.03, 0.01]}})
        nhc = next(m for m in build_aiding(job, _NoInputs(), [], imu).models if m.name == "nhc")
        if tau:
            assert nhc.violation_state and nhc.violation_tau == 1.5
            assert nhc.violation_std == pytest.approx([0.1, 0.05])
            assert nhc.std[0] == pytest.approx([0.03, 0.01])
        else:
            assert nhc.violation_state is None and nhc.std[0] == pytest.approx([0.1, 0.05])


class _NoInputs:
    gnss = None
    control_points = None
    odometer = None
    lever_arm = None
