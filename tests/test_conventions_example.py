"""The worked example of docs/conventions.md holds numerically."""

import numpy as np
import pytest

from insgnss.attitude import euler_from_ned, euler_to_dcm, frd_to_rfu
from insgnss.earth import OMEGA_E, normal_gravity


def test_frd_ned_worked_example():
    dth_frd = np.array([1.823e-7, -1.823e-7, -2.578e-7])
    dv_frd = np.array([0.0, 0.0, -0.04903])
    dth = frd_to_rfu(dth_frd)
    dv = frd_to_rfu(dv_frd)
    assert np.allclose(dth, [-1.823e-7, 1.823e-7, 2.578e-7])
    assert dv[2] / 0.005 == pytest.approx(normal_gravity(np.radians(45), 0.0), abs=1e-3)
    roll, pitch, heading = euler_from_ned(*np.radians([0.0, 0.0, 45.0]))
    C = euler_to_dcm(roll, pitch, heading)
    assert np.allclose(C @ [0, 1, 0], [np.sqrt(0.5), np.sqrt(0.5), 0])
    lat = np.radians(45.0)
    w_ie = np.array([0.0, OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)])
    assert np.allclose(w_ie, [0, 5.157e-5, 5.157e-5], atol=1e-8)
    expected = C.T @ w_ie * 0.005
    assert np.allclose(expected, [-1.823e-7, 1.823e-7, 2.578e-7], atol=1e-10)
    assert np.allclose(expected, dth, atol=1e-10)
    assert np.allclose(frd_to_rfu(np.array([1.0, 2.0, 3.0])), [2.0, 1.0, -3.0])
