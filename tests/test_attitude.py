"""Attitude representations: round trips, the seed convention, NED/FRD conversion."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from insgnss import attitude as att


def _random_euler(n, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-np.pi, np.pi, n), rng.uniform(-1.5, 1.5, n),
            rng.uniform(0, 2 * np.pi, n))


def test_seed_convention_product():
    r, p, a = 0.3, -0.2, 1.1
    C = att.Rz(-a) @ att.Rx(p) @ att.Ry(r)
    assert np.allclose(att.euler_to_dcm(r, p, a), C, atol=1e-15)


def test_axes_meaning():
    # heading 90 deg: body forward (y) points east; pitch up: forward gets an up component;
    # positive roll: right wing (x) goes down.
    assert np.allclose(att.euler_to_dcm(0, 0, np.pi / 2) @ [0, 1, 0], [1, 0, 0], atol=1e-15)
    assert att.euler_to_dcm(0, 0.1, 0)[2, 1] == pytest.approx(np.sin(0.1))
    assert (att.euler_to_dcm(0.1, 0, 0) @ [1, 0, 0])[2] < 0


def test_euler_roundtrip():
    r, p, a = _random_euler(500)
    r2, p2, a2 = att.dcm_to_euler(att.euler_to_dcm(r, p, a))
    assert np.allclose(r2, r, atol=1e-12)
    assert np.allclose(p2, p, atol=1e-12)
    assert np.allclose(a2, a, atol=1e-12)


def test_quaternion_roundtrip_and_scipy():
    C = att.euler_to_dcm(*_random_euler(300, 1))
    q = att.dcm_to_quat(C)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    assert np.allclose(att.quat_to_dcm(q), C, atol=1e-14)
    qs = Rotation.from_matrix(C).as_quat()  # scipy is scalar-last too
    qs *= np.sign(qs[:, 3:4])
    assert np.allclose(q, qs, atol=1e-12)


def test_rotvec_roundtrip_and_scipy():
    rng = np.random.default_rng(2)
    phi = rng.normal(size=(200, 3))
    phi *= (rng.uniform(0, 3.0, 200) / np.linalg.norm(phi, axis=1))[:, None]
    C = att.rotvec_to_dcm(phi)
    assert np.allclose(C, Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)
    assert np.allclose(att.dcm_to_rotvec(C), phi, atol=1e-12)
    tiny = np.array([1e-10, -2e-10, 3e-10])
    assert np.allclose(att.dcm_to_rotvec(att.rotvec_to_dcm(tiny)), tiny, atol=1e-20)
    out = np.empty((3, 3))
    att.rotvec_to_dcm_nb(phi[5], out)
    assert np.allclose(out, C[5], atol=1e-15)


def test_ned_frd_conversion_matches_yaw_pitch_roll():
    """C_frd^ned = P C_rfu^enu P equals the aerospace ZYX product with the same angles."""
    r, p, a = _random_euler(100, 3)
    C_ned = att.dcm_enu_rfu_to_ned_frd(att.euler_to_dcm(r, p, a))
    roll, pitch, yaw = att.euler_to_ned(r, p, a)
    C_ref = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll])).as_matrix()
    assert np.allclose(C_ned, C_ref, atol=1e-12)
    r2, p2, a2 = att.euler_from_ned(roll, pitch, yaw)
    assert np.allclose(a2, a) and np.allclose(r2, r) and np.allclose(p2, p)
    v = np.array([1.0, 2.0, 3.0])
    assert np.allclose(att.enu_to_ned(v), [2.0, 1.0, -3.0])
    assert np.allclose(att.ned_to_enu(att.enu_to_ned(v)), v)


def test_attitude_error_small_angle():
    C = att.euler_to_dcm(0.1, 0.2, 0.3)
    phi = np.array([1e-3, -2e-3, 5e-4])
    assert np.allclose(att.attitude_error(att.rotvec_to_dcm(phi) @ C, C), phi, atol=1e-12)


def test_orthonormalize():
    C = att.euler_to_dcm(0.1, 0.2, 0.3) + 1e-6
    O = att.orthonormalize(C)
    assert np.allclose(O @ O.T, np.eye(3), atol=1e-14)
