"""jacobian (the filter's continuous error dynamics) against a numerical Jacobian of the exact
INS equations; vanloan against closed forms and series."""

import numpy as np
import pytest
from lin_helpers import numerical_F

from insgnss.attitude import euler_to_dcm
from insgnss.errors import InsgnssError
from insgnss.filter.models import StateLayout
from insgnss.linearization import jacobian, vanloan

STATES = [
    (np.radians(60.0), 3000.0, [150.0, -120.0, 8.0], (0.3, 0.1, 2.0), [0.5, 1.0, 10.5],
     [0.01, -0.02, 0.05]),
    (np.radians(20.0), 100.0, [-15.0, 20.0, -1.0], (-0.05, 0.02, 4.0), [-2.0, 0.3, 9.7],
     [0.2, 0.0, -0.3]),
    (np.radians(-45.0), 0.0, [0.0, 0.0, 0.0], (0.0, 0.0, 0.0), [0.0, 0.0, 9.806], [0, 0, 0]),
]

# entries where F keeps a documented approximation (models.py: dM/dlat, dN/dlat neglected,
# no latitude gradient of gravity, vertical gradient 2 g / R): (row, col) -> bound on |error|
KNOWN = {(0, 0): 1e-7, (0, 1): 1e-7, (1, 1): 1e-9, (1, 2): 1e-9,  # F_rr: dN/dlat, dM/dlat
         (3, 1): 1e-11, (4, 1): 1e-11, (6, 1): 1e-13, (7, 1): 1e-13, (8, 1): 1e-13,  # dM/dlat
         (5, 1): 1e-8,   # F[vu, rn]: dg/dlat / (M + h), at most 8.2e-9 1/s^2 (45 deg)
         (5, 2): 1.2e-8}  # F[vu, ru]: 2 g / R is 0.34 % below -dg/dh


@pytest.mark.parametrize("lat,h,v,rpy,f,w", STATES)
def test_jacobian_matches_numerical_jacobian(lat, h, v, rpy, f, w):
    C = euler_to_dcm(*rpy)
    Fa = jacobian(f, [lat, 0.2, h], v, C, w_ib=w)
    Fn = numerical_F(lat, 0.2, h, np.array(v), C, np.array(f), np.array(w))
    assert Fa.shape == (15, 15)
    D = np.abs(Fa - Fn)
    tol = np.broadcast_to(1e-6 * np.abs(Fn).max(axis=1, keepdims=True) + 1e-15, D.shape).copy()
    for (i, j), bound in KNOWN.items():
        assert D[i, j] < bound, (i, j, Fa[i, j], Fn[i, j])
        tol[i, j] = np.inf
    bad = np.argwhere(D > tol)
    assert bad.size == 0, [(i, j, Fa[i, j], Fn[i, j]) for i, j in bad]
    # the blocks that must be there are there (a test that can fail on a missing term)
    assert np.abs(Fn[3:6, 6:9]).max() > 9.0 and np.allclose(Fa[0:3, 3:6], np.eye(3))


def test_jacobian_with_scale_factors_and_decay():
    layout = StateLayout(scale_factors=True)
    C = euler_to_dcm(0.1, 0.2, 0.3)
    f, w = np.array([0.1, 0.2, 9.8]), np.array([0.01, 0.02, 0.03])
    decay = np.zeros(layout.n)
    decay[layout["gyro_bias"]] = 1 / 300.0
    F = jacobian(f, [0.7, 0.0, 0.0], [1.0, 2.0, 0.0], C, w_ib=w, layout=layout, decay=decay)
    assert F.shape == (21, 21)
    assert np.allclose(F[layout["vel"], layout["accel_scale"]], -C * f)  # -C diag(f)
    assert np.allclose(F[layout["att"], layout["gyro_scale"]], -C * w)
    assert np.allclose(np.diag(F)[layout["gyro_bias"]], -1 / 300.0)
    with pytest.raises(InsgnssError, match="degrees"):
        jacobian(f, [45.0, 7.0, 0.0], [0, 0, 0], C)


def test_vanloan_double_integrator_closed_form():
    F = np.array([[0.0, 1.0], [0.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    q, T = 0.3, 0.7
    Phi, Bd, Qd = vanloan(F, B, np.diag([0.0, q]), T)
    assert np.allclose(Phi, [[1, T], [0, 1]], atol=1e-14)
    assert np.allclose(Bd, [[T * T / 2], [T]], atol=1e-14)
    assert np.allclose(Qd, q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]]), atol=1e-14)


def test_vanloan_matches_series_on_a_damped_oscillator():
    rng = np.random.default_rng(3)
    F = np.array([[0.0, 1.0, 0.0], [-4.0, -0.3, 0.5], [0.0, 0.0, -0.1]])
    B = rng.normal(size=(3, 2))
    L = rng.normal(size=(3, 3))
    Q = L @ L.T
    T = 0.05
    Phi, Bd, Qd = vanloan(F, B, Q, T)
    # series: Phi = sum (FT)^k/k!, Bd = sum F^k T^(k+1)/(k+1)! B,
    # Qd = sum_k T^(k+1)/(k+1)! sum_j C(k, j) F^j Q (F^T)^(k-j)
    Ps, Bs, Qs = np.zeros((3, 3)), np.zeros((3, 2)), np.zeros((3, 3))
    Fk = [np.linalg.matrix_power(F, k) for k in range(25)]
    from math import comb, factorial

    for k in range(24):
        Ps += Fk[k] * T**k / factorial(k)
        Bs += Fk[k] @ B * T ** (k + 1) / factorial(k + 1)
        Qs += T ** (k + 1) / factorial(k + 1) * sum(comb(k, j) * Fk[j] @ Q @ Fk[k - j].T
                                                    for j in range(k + 1))
    assert np.allclose(Phi, Ps, rtol=1e-12, atol=1e-15)
    assert np.allclose(Bd, Bs, rtol=1e-12, atol=1e-15)
    assert np.allclose(Qd, Qs, rtol=1e-12, atol=1e-15)
    # without B and Q
    Phi2, Bd2, Qd2 = vanloan(F, T=T)
    assert np.allclose(Phi2, Phi) and Bd2 is None and Qd2 is None
    with pytest.raises(InsgnssError):
        vanloan(F)
