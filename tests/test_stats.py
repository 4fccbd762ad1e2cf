"""Chi-square quantile and CDF without scipy.stats, against scipy.stats (the reference)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from insgnss.stats import chi2_cdf, chi2_ppf

P = np.array([1e-8, 1e-4, 0.025, 0.5, 0.9, 0.975, 0.999, 0.9999, 1 - 1e-9])
DOF = [1, 2, 3, 4, 6, 9, 15, 30, 100, 1000, 12000]


@pytest.mark.parametrize("dof", DOF)
def test_chi2_ppf_and_cdf_match_scipy_stats(dof):
    x = chi2_ppf(P, dof)
    np.testing.assert_allclose(x, stats.chi2.ppf(P, dof), rtol=1e-12)
    np.testing.assert_allclose(chi2_cdf(x, dof), P, rtol=1e-10)


def test_gates_of_the_filter_exact_where_wilson_hilferty_is_not():
    # the engine's default gate, 99.99 % with 1 dof: 15.1367 (Wilson-Hilferty: 16.21, 7 % off)
    assert chi2_ppf(0.9999, 1) == pytest.approx(15.136705226623606, rel=1e-14)
    assert chi2_ppf(0.9999, 2) == pytest.approx(-2.0 * np.log(1e-4), rel=1e-14)
    assert chi2_ppf(0.999, 3) == pytest.approx(16.266236196238129, rel=1e-13)
    # broadcasting, edges and the domain
    lo, hi = chi2_ppf([0.025, 0.975], 3 * 50)
    assert lo == pytest.approx(stats.chi2.ppf(0.025, 150)) and hi > lo
    assert chi2_ppf(1.0, 3) == np.inf and chi2_ppf(0.0, 3) == 0.0
    assert np.isnan(chi2_ppf(1.5, 3)) and np.isnan(chi2_ppf(0.5, 0))
    assert chi2_cdf(-1.0, 2) == 0.0 and np.isnan(chi2_cdf(1.0, -1))
    np.testing.assert_allclose(chi2_ppf(0.5, np.array([1, 2, 5])), stats.chi2.ppf(0.5, [1, 2, 5]),
                               rtol=1e-12)


def test_no_scipy_stats_import():
    """The filter's start-up does not pay for scipy.stats (about 1 s)."""
    import subprocess
    import sys

    code = ("import sys, insgnss.stats, insgnss.filter, insgnss.filter.engine, insgnss.foot; "
            "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_random_degrees_of_freedom_and_far_tails_match_scipy():
    """Non-integer degrees of freedom from 0.2 to 30,000 and probabilities down to 1e-12 in
    either tail (the Halley steps on Q above the median keep the upper tail's digits)."""
    rng = np.random.default_rng(7)
    n = 2000
    k = np.exp(rng.uniform(np.log(0.2), np.log(30000.0), n))
    tail = 10.0 ** rng.uniform(-12.0, -0.3, n)
    p = np.where(rng.random(n) < 0.5, tail, 1.0 - tail)
    x = chi2_ppf(p, k)
    np.testing.assert_allclose(x, stats.chi2.ppf(p, k), rtol=1e-12)
    np.testing.assert_allclose(chi2_cdf(x, k), stats.chi2.cdf(x, k), rtol=1e-11)
    assert chi2_cdf(np.inf, 3) == 1.0 and np.isnan(chi2_cdf(np.nan, 3))


def test_no_scipy_on_the_process_path():
    """No scipy subpackage is imported by the filter, the job run and the report's data
    (scipy.special and scipy.fft alone cost about 0.3 s of every start-up; numba imports the
    bare package, a few milliseconds)."""
    import subprocess
    import sys

    code = ("import sys, insgnss.cli, insgnss.pipeline, insgnss.report, insgnss.foot; "
            "heavy = ('special', 'fft', 'stats', 'linalg', 'signal', 'interpolate', 'integrate', "
            "'optimize', 'sparse'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy' and "
            "m.split('.')[1:2] and m.split('.')[1] in heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_scalar_series_and_fraction_are_the_vector_ones_bit_for_bit():
    """Arrays of a few elements are summed in Python floats (:data:`insgnss.stats._SCALAR`):
    the same operations in the same order as the vectorised loops, so the same bits."""
    from insgnss import stats

    rng = np.random.default_rng(1)
    a = np.concatenate([rng.uniform(0.1, 20000.0, 1500), rng.uniform(0.1, 5.0, 300)])
    x = a * rng.uniform(0.2, 3.0, a.size)
    low = x < a + 1.0
    for vec, one, sel in ((stats._converged_sum, stats._converged_sum_scalar, low),
                          (stats._continued_fraction, stats._continued_fraction_scalar, ~low)):
        got = np.array([one(float(p), float(q)) for p, q in zip(a[sel], x[sel], strict=True)])
        assert sel.sum() > 200
        np.testing.assert_array_equal(vec(a[sel], x[sel]), got)
    # and through the public functions: one element at a time equals the whole array
    k = rng.uniform(0.3, 30000.0, 40)
    np.testing.assert_array_equal(stats.chi2_ppf(0.9999, k),
                                  [stats.chi2_ppf(0.9999, v) for v in k])


def test_one_quantile_is_remembered_with_its_shape():
    """A single ``(p, dof)`` (a gate, a NIS bound of a figure) is solved once: the same value
    again, as a float for scalars and in the given shape for one-element arrays."""
    from insgnss import stats

    stats._chi2_ppf_one.cache_clear()
    first = chi2_ppf(0.995, 37)
    assert isinstance(first, float) and first == pytest.approx(stats_ref(0.995, 37), rel=1e-12)
    again = chi2_ppf(np.array([[0.995]]), np.array([37.0]))
    assert again.shape == (1, 1) and again[0, 0] == first
    assert stats._chi2_ppf_one.cache_info().hits == 1
    assert np.isnan(chi2_ppf(np.nan, 3)) and np.isnan(chi2_ppf(0.5, np.nan))


def stats_ref(p, dof):
    return float(stats.chi2.ppf(p, dof))
