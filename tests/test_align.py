"""Coarse alignment on simulated static data: levelling, gyrocompassing, stated accuracy."""

import numpy as np
import pytest
from mech_helpers import LAT45, static_increments

from insgnss import align
from insgnss.attitude import Rx, Ry, euler_to_dcm
from insgnss.errors import AlignmentError
from insgnss.imu import grade


def _noisy_static(model, roll, pitch, heading, duration=120.0, rate=100.0, seed=0,
                  gyro_bias=None, accel_bias=None):
    imu, _ = static_increments(duration, rate, LAT45, roll=roll, pitch=pitch, heading=heading)
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    n = len(imu)
    bg = gyro_bias if gyro_bias is not None else rng.normal(0, model.gyro_bias, 3)
    ba = accel_bias if accel_bias is not None else rng.normal(0, model.accel_bias, 3)
    cols_w = ["dtheta_x", "dtheta_y", "dtheta_z"]
    cols_f = ["dv_x", "dv_y", "dv_z"]
    w = imu[cols_w].to_numpy() + bg * dt + rng.normal(0, model.gyro_arw * np.sqrt(dt), (n, 3))
    f = imu[cols_f].to_numpy() + ba * dt + rng.normal(0, model.accel_vrw * np.sqrt(dt), (n, 3))
    imu[cols_w], imu[cols_f] = w, f
    return imu.iloc[1:], bg, ba


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_navigation_grade_alignment(seed):
    model = grade("navigation")
    rng = np.random.default_rng(100 + seed)
    u = rng.normal(size=3)
    bg = np.radians(0.01) / 3600 * u / np.linalg.norm(u)  # 0.01 deg/h gyro bias
    r, p, a = 0.05, -0.03, np.radians(37.0 + 100 * seed)
    imu, _, _ = _noisy_static(model, r, p, a, seed=seed, gyro_bias=bg)
    res = align.coarse_align(imu, LAT45, 0.0, model=model)
    assert res.heading_source == "gyrocompass"
    assert abs(np.degrees(res.roll - r)) < 0.01
    assert abs(np.degrees(res.pitch - p)) < 0.01
    assert abs(np.degrees(np.angle(np.exp(1j * (res.heading - a))))) < 0.1


@pytest.mark.parametrize("seed", range(6))
def test_tactical_grade_alignment_within_reported_sigma(seed):
    model = grade("tactical")
    r, p, a = 0.02, 0.04, np.radians(60.0 * seed + 10)
    imu, bg, ba = _noisy_static(model, r, p, a, seed=seed)
    res = align.coarse_align(imu, LAT45, 0.0, model=model)
    assert res.heading_source == "gyrocompass"
    errs = [res.roll - r, res.pitch - p, np.angle(np.exp(1j * (res.heading - a)))]
    stds = [res.roll_std, res.pitch_std, res.heading_std]
    for e, s in zip(errs, stds, strict=True):
        assert abs(e) < 3 * s


def test_gyrocompass_heading_error_follows_east_gyro_bias():
    """Without white noise the heading error is -b_east / (Earth rate cos lat) (Groves 5.108)."""
    model = grade("tactical").scaled(gyro_arw=0.0, accel_vrw=0.0)
    for k, a in enumerate(np.radians([10.0, 130.0, 250.0])):
        r, p = 0.02, 0.04
        imu, bg, ba = _noisy_static(model, r, p, a, seed=k, accel_bias=np.zeros(3))
        res = align.coarse_align(imu, LAT45, 0.0, model=model)
        b_l = euler_to_dcm(r, p, a) @ bg
        predicted = -np.arctan2(b_l[0], 7.2921151467e-5 * np.cos(LAT45) + b_l[1])
        err = np.angle(np.exp(1j * (res.heading - a)))
        assert err == pytest.approx(predicted, rel=0.05, abs=1e-4)


def test_consumer_grade_needs_heading():
    model = grade("consumer")
    assert align.default_heading_source(model, LAT45) == "given"
    imu, _, _ = _noisy_static(model, 0.01, 0.02, 1.0, duration=20.0)
    with pytest.raises(AlignmentError, match="gyrocompassing is impossible"):
        align.coarse_align(imu, LAT45, model=model)
    res = align.coarse_align(imu, LAT45, model=model, heading=1.0)
    assert res.heading == pytest.approx(1.0) and np.isnan(res.heading_std)
    assert abs(res.roll - 0.01) < 3 * res.roll_std


def test_not_static_window_is_rejected():
    model = grade("tactical")
    imu, _, _ = _noisy_static(model, 0.0, 0.0, 0.0, duration=20.0)
    t = imu.index.to_numpy()
    imu = imu.copy()
    imu["dv_y"] += 2.0 * np.sin(2 * np.pi * t / 2.0) * 0.01  # 2 m/s^2 oscillating push
    with pytest.raises(AlignmentError, match="not static"):
        align.coarse_align(imu, LAT45, model=model)


def test_levelling_formulas_exact():
    for r, p in [(0.3, -0.2), (-1.0, 0.5), (2.5, 0.1)]:
        f = euler_to_dcm(r, p, 0.7).T @ np.array([0, 0, 9.8])
        rr, pp = align.level(f)
        assert (rr, pp) == pytest.approx((r, p), abs=1e-12)


def test_magnetometer_and_velocity_heading():
    r, p, a, decl = 0.1, -0.05, np.radians(250.0), np.radians(8.0)
    # magnetic field: north and down components in ENU, rotated by -declination
    # horizontal field along magnetic north, which lies `decl` east of true north
    b_l = np.array([20e-6 * np.sin(decl), 20e-6 * np.cos(decl), -45e-6])
    mag_b = euler_to_dcm(r, p, a).T @ b_l
    assert align.magnetic_heading(mag_b, r, p, declination=decl) == pytest.approx(a, abs=1e-12)
    assert np.allclose(Rx(p) @ Ry(r) @ mag_b, euler_to_dcm(0, 0, a).T @ b_l)
    h = align.heading_from_velocity([1.0, 10.0, -3.0], [0.0, 0.0, -3.0], min_speed=2.0)
    assert np.isnan(h[0]) and h[1] == pytest.approx(np.pi / 2) and h[2] == pytest.approx(
        np.radians(225.0))


def test_level_moving_removes_the_vehicle_acceleration():
    """f^b = C_l^b (a^l + (0, 0, g)): with the acceleration known (GNSS) the tilt is exact;
    levelling f^b alone tilts by about atan(a / g) (braking at 2.5 m/s^2: 14 deg)."""
    from insgnss.align import level, level_moving

    g = 9.80
    for r, p, h, acc in [(0.02, -0.03, 1.2, (1.5, -2.0, 0.1)), (-0.1, 0.05, 4.0, (0.0, 0.0, 0.0)),
                         (0.01, 0.2, 2.5, (-2.5, 0.3, -0.4))]:
        C = euler_to_dcm(r, p, h)
        f_b = C.T @ (np.asarray(acc) + np.array([0.0, 0.0, g]))
        r1, p1 = level_moving(f_b, acc, h, iterations=8)
        assert abs(r1 - r) < 1e-6 and abs(p1 - p) < 1e-6
        r0, p0 = level(f_b)
        tilt = np.hypot(r0 - r, p0 - p)
        if np.any(acc):
            assert tilt > 0.5 * np.arctan(np.hypot(acc[0], acc[1]) / g)
        else:
            assert tilt < 1e-12 and level_moving(f_b, acc, h) == (r0, p0)


def test_tactical_mems_preset_cannot_gyrocompass():
    """HG4930/ADIS16495 class: deg/h in-run stability, but ~100 deg/h turn-on bias."""
    model = grade("tactical_mems")
    assert np.degrees(model.gyro_bias) * 3600 == pytest.approx(100.0)
    assert np.degrees(model.gyro_bias_instability) * 3600 == pytest.approx(1.0)
    assert align.default_heading_source(model, LAT45) == "given"
    imu, _, _ = _noisy_static(model, 0.01, 0.02, 1.0, duration=30.0)
    _, _, w, _, _ = align.static_means(imu)
    chk = align.gyrocompass_check(model, LAT45, w, 0.01, 0.02)
    assert not chk.feasible and "gyro bias of the IMU model (100 deg/h" in chk.reason
    with pytest.raises(AlignmentError, match="gyro bias of the IMU model"):
        align.coarse_align(imu, LAT45, model=model)


def test_biased_gyros_refuse_gyrocompass_although_the_preset_allows_it():
    """A 'tactical' job on gyros that read 130 deg/h horizontally (12 x Earth rate at 45 deg):
    the data shows the bias; gyrocompassing would be tens of degrees off."""
    model = grade("tactical")
    bg = np.radians(np.array([120.0, 50.0, 0.0])) / 3600  # 130 deg/h horizontal
    imu, _, _ = _noisy_static(model, 0.01, 0.02, np.radians(250.0), gyro_bias=bg)
    _, _, w, _, _ = align.static_means(imu)
    chk = align.gyrocompass_check(model, LAT45, w, 0.01, 0.02)
    assert not chk.feasible and "parked gyros read" in chk.reason
    assert np.degrees(chk.measured_horizontal) * 3600 == pytest.approx(130.0, abs=12.0)
    with pytest.raises(AlignmentError, match="parked gyros read"):
        align.coarse_align(imu, LAT45, model=model)
    # the same gyros without the bias: feasible, and the heading within the claimed 3 sigma
    imu, _, _ = _noisy_static(model, 0.01, 0.02, np.radians(250.0), seed=3)
    _, _, w, _, _ = align.static_means(imu)
    chk = align.gyrocompass_check(model, LAT45, w, 0.01, 0.02)
    assert chk.feasible and chk.reason == ""
    res = align.coarse_align(imu, LAT45, model=model)
    err = np.angle(np.exp(1j * (res.heading - np.radians(250.0))))
    assert abs(err) < 3 * chk.heading_std


def test_vibration_noise_refuses_gyrocompass():
    """Engine vibration: 1 deg/s of measured rate noise per sample over 10 s at 100 Hz leaves
    0.01 deg/s = 36 deg/h on the mean, above 25 % of the horizontal Earth rate."""
    model = grade("tactical")
    imu, _, _ = _noisy_static(model, 0.01, 0.02, 1.0, duration=10.0, gyro_bias=np.zeros(3))
    rng = np.random.default_rng(5)
    cols = ["dtheta_x", "dtheta_y", "dtheta_z"]
    imu[cols] = imu[cols].to_numpy() + rng.normal(0, np.radians(1.0) * 0.01, (len(imu), 3))
    _, _, w, _, _ = align.static_means(imu)
    chk = align.gyrocompass_check(model, LAT45, w, 0.01, 0.02)
    assert not chk.feasible and "noise measured in the static window" in chk.reason
    assert np.degrees(chk.heading_std) > 14.0
