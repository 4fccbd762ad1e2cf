"""jacobian (the filter's continuous error dynamics) against a numerical Jacobian of the exact
INS equations; vanloan against closed forms and series."""

import numpy as np
import pytest
from lin_helpers import numerical_F

from insgnss.attitude import euler_to_dcm
from insgnss.earth import gravity_gradient_somigliana, normal_gravity, radii
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

# F is exact (radius derivatives dM/dlat, dN/dlat in F_rr, F_vr, F_pr; the latitude gradient of
# gravity in F[vu, rn]; -dg/dh in F[vu, ru]): every entry to 1e-4 of itself. The floor is the
# numerical Jacobian's own rounding: ~1e-13 1/s in the attitude rows' velocity and attitude
# columns (central difference of a matrix logarithm), 1e-18 elsewhere. The former
# approximations were 5e-8 (F_rr), 7e-9 and 1e-8 1/s^2 (F[vu, rn], F[vu, ru]) and 2e-12..3e-14
# (dM/dlat in F_vr, F_pr): all far above these bounds.
FLOOR = np.full((15, 15), 1e-18)
FLOOR[6:9, 3:9] = 1e-12


@pytest.mark.parametrize("lat,h,v,rpy,f,w", STATES)
def test_jacobian_matches_numerical_jacobian(lat, h, v, rpy, f, w):
    C = euler_to_dcm(*rpy)
    Fa = jacobian(f, [lat, 0.2, h], v, C, w_ib=w)
    Fn = numerical_F(lat, 0.2, h, np.array(v), C, np.array(f), np.array(w))
    assert Fa.shape == (15, 15)
    D = np.abs(Fa - Fn)
    bad = np.argwhere(D > 1e-4 * np.abs(Fn) + FLOOR)
    assert bad.size == 0, [(i, j, Fa[i, j], Fn[i, j]) for i, j in bad]
    # the blocks that must be there are there (a test that can fail on a missing term)
    assert np.abs(Fn[3:6, 6:9]).max() > 9.0 and np.allclose(Fa[0:3, 3:6], np.eye(3))
    # the small terms are there and not zero (lat 60 and 20: moving vehicles)
    if np.any(v):
        for i, j in [(0, 0), (0, 1), (5, 1), (5, 2), (6, 1), (7, 1), (8, 1)]:
            assert abs(Fn[i, j]) > 1e-15 and D[i, j] < 1e-4 * abs(Fn[i, j]), (i, j)


def test_gravity_gradient_is_the_derivative_of_somigliana():
    for lat, h in [(0.3, 0.0), (1.2, 8000.0), (-0.7, 300.0), (np.pi / 2, 50.0)]:
        dlat, dh = gravity_gradient_somigliana(np.sin(lat), np.cos(lat), h)
        e = 1e-5
        n_lat = (normal_gravity(lat + e, h) - normal_gravity(lat - e, h)) / (2 * e)
        n_h = (normal_gravity(lat, h + 1.0) - normal_gravity(lat, h - 1.0)) / 2.0
        assert dlat == pytest.approx(n_lat, rel=1e-7, abs=1e-12)
        assert dh == pytest.approx(n_h, rel=1e-9)
    # the former F used 2 g / sqrt(M N): 0.34 % low
    g, R = normal_gravity(0.8, 0.0), np.sqrt(np.prod(radii(0.8)))
    assert -gravity_gradient_somigliana(np.sin(0.8), np.cos(0.8), 0.0)[1] / (2 * g / R) == \
        pytest.approx(1.0034, abs=5e-4)


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
