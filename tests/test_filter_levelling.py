"""The tilt / accelerometer-bias correlation of a levelled start (FilterConfig.levelling_correlation)
matches the errors that levelling actually makes."""

import numpy as np

from insgnss.align import level
from insgnss.attitude import attitude_error, euler_to_dcm
from insgnss.filter.engine import levelling_covariance
from insgnss.filter.models import StateLayout


def test_levelling_covariance_matches_sampled_levelling_errors():
    rng = np.random.default_rng(4)
    g = 9.8
    C_true = euler_to_dcm(0.05, -0.03, 2.0)
    sig_b = np.array([0.02, 0.03, 0.05])
    n = 4000
    samples = np.empty((n, 6))
    for k in range(n):
        b = rng.normal(0.0, sig_b)
        f = C_true.T @ np.array([0.0, 0.0, g]) + b
        r, p = level(f)
        # heading is not observed by levelling: keep the true one to isolate the tilt
        C_lev = euler_to_dcm(r, p, 2.0)
        phi = attitude_error(C_lev, C_true)  # C_lev = exp(phi) C_true
        samples[k, :3] = phi
        samples[k, 3:] = -b  # bias error: nominal (0) minus true
    emp = np.cov(samples.T)
    lay = StateLayout()
    P0 = np.diag(np.r_[np.ones(6), 1e-12 * np.ones(3), np.zeros(3), sig_b**2])
    P = levelling_covariance(P0, C_true, lay["att"], lay["accel_bias"], g)
    model = P[np.r_[6:9, 12:15]][:, np.r_[6:9, 12:15]]
    # the tilt block and the tilt-bias cross-covariance match the sampled ones (2 % of scale)
    scale = np.sqrt(np.outer(np.diag(model), np.diag(model))) + 1e-30
    assert np.max(np.abs(emp[:2, :2] - model[:2, :2]) / scale[:2, :2]) < 0.06
    assert np.max(np.abs(emp[:2, 3:] - model[:2, 3:]) / scale[:2, 3:]) < 0.06
    # and it is a valid covariance
    assert np.all(np.linalg.eigvalsh(P) > -1e-15)
