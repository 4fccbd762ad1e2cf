"""IMU compensation, increments, coning/sculling and grade presets."""

import numpy as np
import pytest

from insgnss import imu


def test_compensation_inverts_error_model():
    rng = np.random.default_rng(0)
    true = rng.normal(size=(100, 3))
    b = np.array([0.1, -0.2, 0.05])
    S = np.array([1e-3, -2e-3, 5e-4])
    N = np.array([[0, 1e-3, -2e-3], [5e-4, 0, 1e-3], [-1e-3, 2e-3, 0]])
    raw = true @ (np.eye(3) + np.diag(S) + N).T + b
    assert np.allclose(imu.compensate(raw, b, S, N), true, atol=1e-14)
    # scalar and full-matrix forms
    raw2 = true * (1 + 2e-3) + 0.3
    assert np.allclose(imu.compensate(raw2, 0.3, 2e-3), true, atol=1e-14)
    with pytest.raises(ValueError):
        imu.compensate(raw, np.ones(4))


def test_trapezoid_increments_exact_for_linear_rate():
    t = np.linspace(0, 1, 11)
    w = np.column_stack([2 * t, 3 + 0 * t, -t])
    tab = imu.rates_table(t, w, w)
    tt, dth, dv = imu.increments(tab)
    assert np.allclose(dth[1:].sum(0), [1.0, 3.0, -0.5])
    assert np.all(dth[0] == 0)
    inc = imu.increments_table(t, dth, dv)
    assert imu.is_increment_table(inc) and not imu.is_increment_table(tab)
    assert np.array_equal(imu.increments(inc)[1], dth)


def test_coning_correction_for_coning_motion():
    """Classical coning: the two-sample algorithm recovers the true rotation much better than
    the plain sum of increments (Savage 1998)."""
    from insgnss.attitude import dcm_to_rotvec, rotvec_to_dcm

    a, w, dt, n = 0.02, 2 * np.pi * 5, 0.005, 200
    t = np.arange(n + 1) * dt
    # body rate of a coning motion with half angle a (analytic increments)
    dth = np.column_stack([
        np.zeros(n),
        a * (np.sin(w * t[1:]) - np.sin(w * t[:-1])),
        -a * (np.cos(w * t[1:]) - np.cos(w * t[:-1])),
    ])
    dth[:, 0] = -0.5 * a * a * w * dt  # first-order drift rate along the cone axis
    ref = np.eye(3)
    for k in range(n):  # fine reference integration (this is a test, not a hot path)
        sub = 50
        for j in range(sub):
            tt = t[k] + (j + 0.5) * dt / sub
            wb = np.array([-0.5 * a * a * w, a * w * np.cos(w * tt), a * w * np.sin(w * tt)])
            ref = ref @ rotvec_to_dcm(wb * dt / sub)
    phi, _ = imu.coning_sculling(dth, np.zeros_like(dth))
    C_plain, C_con = np.eye(3), np.eye(3)
    for k in range(n):
        C_plain = C_plain @ rotvec_to_dcm(dth[k])
        C_con = C_con @ rotvec_to_dcm(phi[k])
    err_plain = np.linalg.norm(dcm_to_rotvec(C_plain.T @ ref))
    err_con = np.linalg.norm(dcm_to_rotvec(C_con.T @ ref))
    assert err_con < 0.2 * err_plain


def test_grades_units():
    g = imu.grade("tactical")
    assert g.gyro_bias == pytest.approx(np.radians(1.0) / 3600)
    assert g.accel_bias == pytest.approx(1e-3 * 9.80665)
    assert g.gyro_arw == pytest.approx(np.radians(0.125) / 60)
    assert g.accel_vrw == pytest.approx(0.03 / 60)
    assert imu.grade("mems") is imu.grade("consumer")
    assert imu.grade("navigation").gyro_bias < g.gyro_bias < imu.grade("consumer").gyro_bias
    with pytest.raises(ValueError):
        imu.grade("toy")
