"""The compiled Kalman predict/update of the engine's general epochs against filterpy's."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from filterpy.kalman import predict as kf_predict
from filterpy.kalman import update as kf_update

from insgnss.errors import ConfigError, FilterHealthError
from insgnss.filter import kalman
from insgnss.filter.engine import FilterConfig


def _case(rng, n, m):
    A = rng.normal(size=(n, n))
    P = A @ A.T + 0.1 * np.eye(n)
    F = np.eye(n) + 0.05 * rng.normal(size=(n, n))
    Q = np.diag(rng.uniform(1e-6, 1e-2, n))
    H = rng.normal(size=(m, n))
    B = rng.normal(size=(m, m))
    R = B @ B.T + 0.01 * np.eye(m)
    return rng.normal(size=n), P, F, Q, rng.normal(size=m), R, H


def _close(a, b):
    scale = max(np.abs(b).max(), 1.0)
    assert np.abs(a - b).max() <= 1e-12 * scale


@pytest.mark.parametrize("n,m", [(15, 1), (15, 3), (18, 6), (21, 9), (24, 12)])
def test_compiled_equals_filterpy_functions_and_kalmanfilter(n, m):
    rng = np.random.default_rng(100 * n + m)
    for _ in range(20):
        x, P, F, Q, z, R, H = _case(rng, n, m)
        xc, Pc = kalman.predict(x, P, F, Q)
        xf, Pf = kf_predict(x, P, F, Q)
        _close(xc, xf)
        _close(Pc, Pf)
        xu, Pu = kalman.update(xc, Pc, z, R, H)
        xg, Pg = kf_update(xf, Pf, z, R, H)
        _close(xu, xg)
        _close(Pu, Pg)
        # the KalmanFilter object (its update is the Joseph form too)
        kf = KalmanFilter(dim_x=n, dim_z=m)
        kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = x.copy(), P.copy(), F, Q, H, R
        kf.predict()
        _close(xc, kf.x)
        _close(Pc, kf.P)
        kf.update(z)
        _close(xu, kf.x)
        _close(Pu, kf.P)


def test_update_is_the_joseph_form_and_reduces_the_observed_variance():
    rng = np.random.default_rng(7)
    x, P, _, _, z, R, H = _case(rng, 15, 3)
    x1, P1 = kalman.update(x, P, z, R, H)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(15) - K @ H
    np.testing.assert_allclose(P1, I_KH @ P @ I_KH.T + K @ R @ K.T, rtol=0, atol=1e-12)
    np.testing.assert_allclose(x1, x + K @ (z - H @ x), rtol=0, atol=1e-12)
    # optimal gain: equals the short form (I - K H) P, and H P1 H^T < H P H^T
    np.testing.assert_allclose(P1, I_KH @ P, rtol=0, atol=1e-10)
    assert np.all(np.linalg.eigvalsh(H @ P @ H.T - H @ P1 @ H.T) > 0)
    # inputs untouched, non-contiguous inputs accepted
    x2, P2 = kalman.update(x, np.asfortranarray(P), z, R, np.asfortranarray(H))
    np.testing.assert_array_equal(x2, x1)
    _close(P2, P1)


def test_backend_choice_and_validation():
    assert kalman.backend("compiled") == (kalman.predict, kalman.update)
    p, u = kalman.backend("filterpy")
    assert p is kf_predict and u is kf_update
    with pytest.raises(ValueError):
        kalman.backend("sparse")
    with pytest.raises(ConfigError):
        FilterConfig(kalman="sparse").validate()


@pytest.mark.parametrize("n,m", [(15, 3), (15, 6), (21, 9)])
def test_smoother_record_equals_the_numpy_solve(n, m):
    """K = Pp H^T S^-1, G = S^-1 H, s = S^-1 z of the compiled record against the numpy form
    the engine used (stack [H z], one solve)."""
    rng = np.random.default_rng(11 * n + m)
    for _ in range(10):
        _, P, _, _, z, R, H = _case(rng, n, m)
        K, G, s = kalman.smoother_record(P, H, R, z)
        S = H @ P @ H.T + R
        Gs = np.linalg.solve(S, np.column_stack([H, z]))
        _close(G, Gs[:, :-1])
        _close(s, Gs[:, -1])
        _close(K, P @ Gs[:, :-1].T)
        # the definitions: S G = H, S s = z, K S = Pp H^T
        np.testing.assert_allclose(S @ G, H, rtol=0, atol=1e-9 * np.abs(H).max())
        np.testing.assert_allclose(K @ S, P @ H.T, rtol=0, atol=1e-9 * np.abs(P @ H.T).max())
        assert K.shape == (n, m) and G.shape == (m, n) and s.shape == (m,)


def test_smoother_record_stops_on_an_indefinite_innovation_covariance():
    """A broken predicted covariance (S = H Pp H^T + R not positive definite) stops the
    filter with the epoch named, instead of recording a meaningless solve."""
    rng = np.random.default_rng(3)
    _, P, _, _, z, R, H = _case(rng, 15, 3)
    P = P - 1e3 * np.eye(15)  # indefinite: H Pp H^T dominates R with negative eigenvalues
    with pytest.raises(FilterHealthError, match=r"t = 12\.500000 s \(smoother record\)"):
        kalman.smoother_record(P, H, R, z, 12.5)
    # and a valid one from a non-contiguous Pp is the same as from a contiguous one
    _, P, _, _, z, R, H = _case(rng, 15, 3)
    a = kalman.smoother_record(P, H, R, z)
    b = kalman.smoother_record(np.asfortranarray(P), np.asfortranarray(H), R, z)
    for u, v in zip(a, b, strict=True):
        np.testing.assert_array_equal(u, v)


def test_loop_products_and_inverse_equal_numpys():
    """The compiled products and inverse the kernels use instead of BLAS / LAPACK
    (filter/linalg.py) equal numpy's to rounding, propagate a NaN as BLAS does, and stop on an
    exactly singular matrix as ``np.linalg.inv``."""
    from insgnss.filter.linalg import inverse, matmul, matmul_bt, matvec

    rng = np.random.default_rng(7)
    for n, m, p in ((1, 1, 1), (3, 3, 3), (6, 21, 21), (21, 21, 4), (5, 2, 9)):
        A, B, C = rng.normal(size=(n, m)), rng.normal(size=(m, p)), rng.normal(size=(p, m))
        x = rng.normal(size=m)
        np.testing.assert_allclose(matmul(A, B), A @ B, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(matmul_bt(A, C), A @ C.T, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(matvec(A, x), A @ x, rtol=1e-13, atol=1e-13)
    for n in (1, 2, 6, 21):
        S = rng.normal(size=(n, n)) + n * np.eye(n)
        np.testing.assert_allclose(inverse(S) @ S, np.eye(n), atol=1e-12)
        np.testing.assert_allclose(inverse(S), np.linalg.inv(S), rtol=1e-11, atol=1e-13)
    # a zero leading pivot: the row exchange of partial pivoting
    np.testing.assert_allclose(inverse(np.array([[0.0, 2.0], [4.0, 1.0]])),
                               np.linalg.inv(np.array([[0.0, 2.0], [4.0, 1.0]])), rtol=1e-15)
    B = np.eye(3)
    B[1, 1] = np.nan
    assert np.isnan(matmul(np.zeros((3, 3)), B)[:, 1]).all()  # 0 * NaN as in BLAS
    with pytest.raises(np.linalg.LinAlgError):
        inverse(np.array([[1.0, 2.0], [2.0, 4.0]]))


def _sparse_case(rng, n, m):
    """A transition matrix and measurement rows shaped like the strapdown model's: a dense
    navigation block, couplings to a few bias states, identity elsewhere; H sees position
    and attitude (a GNSS fix with a lever arm)."""
    F = np.eye(n)
    F[:9, :9] += 0.01 * rng.normal(size=(9, 9))
    F[3:9, 9:15] += 0.01 * rng.normal(size=(6, 6))
    F[9, 9] = 0.0  # a zero on the diagonal too
    H = np.zeros((m, n))
    H[:, :3] = rng.normal(size=(m, 3))
    H[:, 6:9] = rng.normal(size=(m, 3))
    return F, H


@pytest.mark.parametrize("n,m", [(15, 3), (21, 2), (25, 3)])
def test_sparse_products_are_the_dense_ones_bit_for_bit(n, m):
    """Skipping the zeros of the sparse factor and forming the congruences transposed
    (filter/linalg.py ``congruence_transposed``) leaves every element the same sum in the
    same order: predict and update return exactly what the dense loop products followed by
    ``0.5 (P + P^T)`` gave (the engine's form before), and an exactly symmetric P."""
    from insgnss.filter.linalg import congruence_transposed, inverse, matmul, matmul_bt, matvec

    rng = np.random.default_rng(10 * n + m)
    for _ in range(10):
        x, P, _, Q, z, R, _ = _case(rng, n, m)
        F, H = _sparse_case(rng, n, m)
        np.testing.assert_array_equal(congruence_transposed(F, P),
                                      matmul_bt(matmul(F, P), F).T)
        # predict: the dense products, then numpy's symmetrization
        X = matmul_bt(matmul(F, P), F) + Q
        xp, Pp = kalman.predict(x, P, F, Q)
        np.testing.assert_array_equal(xp, matvec(F, x))
        np.testing.assert_array_equal(Pp, 0.5 * (X + X.T))
        assert (Pp == Pp.T).all()
        # update: Joseph form from the same dense products
        y = z - matvec(H, xp)
        S = matmul_bt(matmul(H, Pp), H) + R
        K = matmul(matmul_bt(Pp, H), inverse(S))
        I_KH = np.eye(n) - matmul(K, H)
        X = matmul_bt(matmul(I_KH, Pp), I_KH) + matmul_bt(matmul(K, R), K)
        xu, Pu = kalman.update(xp, Pp, z, R, H)
        np.testing.assert_array_equal(xu, xp + matvec(K, y))
        np.testing.assert_array_equal(Pu, 0.5 * (X + X.T))
        assert (Pu == Pu.T).all()


def test_covariance_fault_and_the_innovation_kernel():
    """The compiled health check (finite, positive definite) and the gate's ``S``, NIS."""
    from insgnss.filter import gating, health

    rng = np.random.default_rng(3)
    x, P, _, _, z, R, H = _case(rng, 15, 3)
    assert health.covariance_fault(x, P, True) == 0
    bad = P.copy()
    bad[4, 7] = np.inf
    assert health.covariance_fault(x, bad, False) == 1
    xn = x.copy()
    xn[2] = np.nan
    assert health.covariance_fault(xn, P, False) == 1
    indefinite = P.copy()
    indefinite[0, 0] = -1.0
    assert health.covariance_fault(x, indefinite, False) == 0  # finite; no Cholesky asked
    assert health.covariance_fault(x, indefinite, True) == 2
    with pytest.raises(FilterHealthError, match="not positive definite at t = 2.500000"):
        health.check_covariance(x, indefinite, 2.5, "update")
    with pytest.raises(FilterHealthError, match="non-finite at t = 1.000000"):
        health.check_covariance(x, bad, 1.0, "prediction", full=False)
    assert health.finite_navigation(np.ones(3), np.ones(3), np.eye(3))
    C = np.eye(3)
    C[2, 1] = np.nan
    assert not health.finite_navigation(np.ones(3), np.ones(3), C)
    S, nis = gating.innovation_nis(H, P, R, z)
    S_ref = H @ P @ H.T + R
    np.testing.assert_allclose(S, S_ref, rtol=1e-13)
    assert (S == S.T).all()
    assert nis == pytest.approx(z @ np.linalg.solve(S_ref, z), rel=1e-12)
    _, nis = gating.innovation_nis(H, P, -10.0 * R - S_ref, z)
    assert np.isnan(nis)  # S not positive definite


def test_the_epoch_kernels_import_no_scipy():
    """The Kalman steps and the GNSS measurement kernels run without importing scipy.linalg
    (numba compiles ``@`` and ``np.linalg`` on arrays to BLAS / LAPACK calls through scipy;
    its import is 0.12-0.15 s of a run). On the ahead-of-time exports: numba's own compiler
    imports scipy when it compiles anything."""
    import os
    import subprocess
    import sys

    from insgnss import aot

    if os.environ.get(aot.ENV_SWITCH, "1") == "0" or not aot.status().startswith("used"):
        pytest.skip(f"insgnss._aot: {aot.status()}")

    code = """
import sys
import numpy as np
from insgnss.filter import kalman, measurements as M
n = 21
x, P, F = np.zeros(n), np.eye(n), np.eye(n)
kalman.predict(x, P, F, 1e-3 * P)
H = np.zeros((3, n)); H[0, 0] = H[1, 1] = H[2, 2] = 1.0
kalman.update(x, P, np.ones(3), np.eye(3), H)
kalman.smoother_record(P, H, np.eye(3), np.ones(3))
std, arm, C = np.ones(3), np.array([0.1, 0.2, 0.3]), np.eye(3)
M._gnss_position(np.array([0.5, 0.1, 10.0]), std, arm, C, 0.5, 0.1, 10.0, 6.4e6, 6.4e6, n)
M._gnss_velocity(np.zeros(3), std, arm, True, np.ones(3), C, np.ones(3) * 1e-3, 0.5, 10.0,
                 6.4e6, 6.4e6, n)
print(sorted(m for m in sys.modules if m.startswith("scipy.linalg")))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip() == "[]", r.stdout
