"""Chi-square distribution functions without scipy.

The filter needs the chi-square quantile (innovation gates, NEES/NIS bounds) and CDF; importing
``scipy.stats`` costs 0.6-1 s and even ``scipy.special`` about 0.2 s of every run's start-up,
so both are computed here from the regularized incomplete gamma functions
``P(a, x) = gamma(a, x) / Gamma(a)`` and ``Q = 1 - P``::

    F(x; k)    = P(k / 2, x / 2)
    F^-1(p; k) = 2 P^-1(k / 2, p)

``P`` and ``Q`` (Press et al., Numerical Recipes, 3rd ed., 6.2): the series
``P = e^-x x^a / Gamma(a + 1) (1 + x / (a + 1) + x^2 / ((a + 1)(a + 2)) + ...)`` for
``x < a + 1``, the continued fraction of ``Q`` (modified Lentz) beyond; ``a = 1/2`` (one degree
of freedom) exactly as ``P = erf(sqrt(x))``, ``Q = erfc(sqrt(x))``. The factor
``e^-x x^a / Gamma(a)`` is formed for ``a >= 10`` as
``a (ln(1 + t) - t) + ln(a) / 2 - ln(2 pi) / 2 - s(a)`` with ``t = (x - a) / a`` and Stirling's
series ``s(a)`` of ``ln Gamma``, which keeps it accurate to a few ulp at 12,000 degrees of
freedom (``a ln x - x - ln Gamma(a)`` loses six digits there).

The inverse: the initial guess of Numerical Recipes (``invgammp``: Wilson-Hilferty for
``a > 1``) refined by Halley steps on ``P - p`` below the median and on ``(1 - p) - Q`` above it,
where ``1 - p`` is exact and ``Q`` keeps its relative accuracy in the upper tail (the gates sit
at 0.9999 and beyond). Two degrees of freedom use the closed form ``x = -2 ln(1 - p)``.
Wilson-Hilferty alone is not used: at ``p = 0.9999`` with 1 dof it is 7 % off. Equal to
``scipy.stats.chi2`` to 1e-12 (tests/test_stats.py).
"""

from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["chi2_cdf", "chi2_ppf"]

_EPS = 1e-16
_TINY = 1e-300
_MAX_TERMS = 100_000
_lgamma = np.vectorize(math.lgamma, otypes=[float])
_erf = np.vectorize(math.erf, otypes=[float])
_erfc = np.vectorize(math.erfc, otypes=[float])
_HALF_LN_2PI = 0.5 * math.log(2.0 * math.pi)


def _log_density_factor(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``ln(e^-x x^a / Gamma(a))`` (module docstring), ``x > 0``."""
    out = a * np.log(x) - x - _lgamma(a)
    big = a >= 10.0
    if np.any(big):
        ab, xb = a[big], x[big]
        t = (xb - ab) / ab
        r = 1.0 / (ab * ab)
        stirling = (1.0 / 12.0 - r * (1.0 / 360.0 - r * (1.0 / 1260.0 - r / 1680.0))) / ab
        out[big] = ab * (np.log1p(t) - t) + 0.5 * np.log(ab) - _HALF_LN_2PI - stirling
    return out


#: arrays up to this size are summed element by element in Python floats: the same operations
#: in the same order (the same bits), without numpy's per-term call overhead on 1-element
#: arrays (a window's chi-square point at 30,000 dof: thousands of terms, 3 ms -> 0.2 ms)
_SCALAR = 4


def _converged_sum(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``sum_n x^n / ((a + 1) ... (a + n)) / a`` (the series of ``P``), each element to its own
    convergence."""
    if a.size <= _SCALAR:
        return np.array([_converged_sum_scalar(float(ai), float(xi))
                         for ai, xi in zip(a, x, strict=True)])
    ap, term = a.copy(), 1.0 / a
    total = term.copy()
    live = np.arange(a.size)
    for _ in range(_MAX_TERMS):
        ap[live] += 1.0
        term[live] *= x[live] / ap[live]
        total[live] += term[live]
        live = live[np.abs(term[live]) >= np.abs(total[live]) * _EPS]
        if not live.size:
            break
    return total


def _converged_sum_scalar(a: float, x: float) -> float:
    """:func:`_converged_sum` of one element (the same operations in the same order)."""
    ap, term = a, 1.0 / a
    total = term
    for _ in range(_MAX_TERMS):
        ap += 1.0
        term *= x / ap
        total += term
        if abs(term) < abs(total) * _EPS:
            break
    return total


def _continued_fraction(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The continued fraction of ``Q e^x x^-a Gamma(a)`` (modified Lentz), each element to its
    own convergence."""
    if a.size <= _SCALAR:
        return np.array([_continued_fraction_scalar(float(ai), float(xi))
                         for ai, xi in zip(a, x, strict=True)])
    b = x + 1.0 - a
    c = np.full(b.shape, 1.0 / _TINY)
    d = 1.0 / b
    h = d.copy()
    live = np.arange(a.size)
    for i in range(1, _MAX_TERMS):
        an = -i * (i - a[live])
        b[live] += 2.0
        dl = an * d[live] + b[live]
        dl[np.abs(dl) < _TINY] = _TINY
        cl = b[live] + an / c[live]
        cl[np.abs(cl) < _TINY] = _TINY
        d[live] = 1.0 / dl
        c[live] = cl
        step = d[live] * cl
        h[live] *= step
        live = live[np.abs(step - 1.0) >= _EPS]
        if not live.size:
            break
    return h


def _continued_fraction_scalar(a: float, x: float) -> float:
    """:func:`_continued_fraction` of one element (the same operations in the same order)."""
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, _MAX_TERMS):
        an = -i * (i - a)
        b += 2.0
        dl = an * d + b
        if abs(dl) < _TINY:
            dl = _TINY
        cl = b + an / c
        if abs(cl) < _TINY:
            cl = _TINY
        d = 1.0 / dl
        c = cl
        step = d * cl
        h *= step
        if abs(step - 1.0) < _EPS:
            break
    return h


def _gamma_pq(a: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``P(a, x)`` and ``Q(a, x)`` for ``a > 0``, ``x >= 0`` (1-d arrays of one size)."""
    p, q = np.zeros(x.shape), np.ones(x.shape)
    half = (a == 0.5) & (x > 0.0)
    if np.any(half):
        r = np.sqrt(x[half])
        p[half], q[half] = _erf(r), _erfc(r)
    series = np.flatnonzero((x > 0.0) & (x < a + 1.0) & ~half)
    if series.size:
        aa, xx = a[series], x[series]
        total = _converged_sum(aa, xx)
        p[series] = total * np.exp(_log_density_factor(aa, xx))
        q[series] = 1.0 - p[series]
    frac = np.flatnonzero((x >= a + 1.0) & ~half & np.isfinite(x))
    if frac.size:
        aa, xx = a[frac], x[frac]
        q[frac] = _continued_fraction(aa, xx) * np.exp(_log_density_factor(aa, xx))
        p[frac] = 1.0 - q[frac]
    endless = np.isposinf(x)
    p[endless], q[endless] = 1.0, 0.0
    return p, q


def _gamma_p_inverse(a: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``x`` with ``P(a, x) = p`` for ``a > 0``, ``0 < p < 1`` (1-d arrays of one size)."""
    upper = p >= 0.5
    q = 1.0 - p  # exact for p >= 0.5
    x = np.empty(p.shape)
    big = a > 1.0
    if np.any(big):  # Wilson-Hilferty from a rational approximation of the normal quantile
        ab, pb = a[big], p[big]
        tail = np.where(pb < 0.5, pb, q[big])
        t = np.sqrt(-2.0 * np.log(tail))
        z = (2.30753 + t * 0.27061) / (1.0 + t * (0.99229 + t * 0.04481)) - t
        z = np.where(pb < 0.5, z, -z)
        x[big] = np.maximum(1e-3, ab * (1.0 - 1.0 / (9.0 * ab) - z / (3.0 * np.sqrt(ab))) ** 3)
    small = ~big
    if np.any(small):
        aa, ps = a[small], p[small]
        t = 1.0 - aa * (0.253 + aa * 0.12)
        lo = ps < t
        x[small] = np.where(lo, (ps / t) ** (1.0 / aa),
                            1.0 - np.log1p(-(ps - t) / (1.0 - t)))
    a1 = a - 1.0
    live = np.arange(p.size)
    for _ in range(100):
        al, xl = a[live], x[live]
        P, Q = _gamma_pq(al, xl)
        err = np.where(upper[live], q[live] - Q, P - p[live])  # > 0: x too large
        dens = np.exp(_log_density_factor(al, xl)) / xl
        u = err / dens
        step = u / (1.0 - 0.5 * np.minimum(1.0, u * (a1[live] / xl - 1.0)))  # Halley
        new = xl - step
        # far out in a tail the density underflows: halve or double x until it is near
        lost = ~np.isfinite(new) | (new <= 0.0)
        new[lost] = np.where(err[lost] > 0.0, 0.5, 2.0) * xl[lost]
        x[live] = new
        live = live[lost | (np.abs(step) > 4.0 * _EPS * np.abs(new))]
        if not live.size:
            break
    return x


def chi2_ppf(p, dof):
    """Quantile of the chi-square distribution (``scipy.stats.chi2.ppf``).

    Parameters
    ----------
    p : float or array_like
        Probability in [0, 1].
    dof : float or array_like
        Degrees of freedom (> 0; broadcast against ``p``).

    Returns
    -------
    float or ndarray
        ``x`` with ``P(X <= x) = p``; ``inf`` at ``p = 1``, NaN outside the domain.
    """
    if type(p) in _SCALARS and type(dof) in _SCALARS:  # a gate, per epoch: no arrays
        return _chi2_ppf_one(float(p), float(dof))
    p, k = np.broadcast_arrays(np.asarray(p, float), np.asarray(dof, float))
    if p.size == 1:  # a gate or a bound: the same few (p, dof) over and over
        x = _chi2_ppf_one(float(p.flat[0]), float(k.flat[0]))
        return x if p.ndim == 0 else np.full(p.shape, x)
    return _chi2_ppf(p, k)


#: Python number types :func:`chi2_ppf` takes without making arrays
_SCALARS = (float, int)


@functools.lru_cache(maxsize=1024)
def _chi2_ppf_one(p: float, k: float) -> float:
    """:func:`chi2_ppf` of one ``(p, dof)``, remembered (a solve costs about 1 ms)."""
    return float(_chi2_ppf(np.array([p]), np.array([k]))[0])


def _chi2_ppf(p: np.ndarray, k: np.ndarray) -> np.ndarray:
    """:func:`chi2_ppf` of broadcast arrays."""
    shape = p.shape
    p, k = p.ravel(), k.ravel()
    x = np.full(p.shape, np.nan)
    ok = (p >= 0.0) & (p <= 1.0) & (k > 0.0)
    x[ok & (p == 0.0)] = 0.0
    x[ok & (p == 1.0)] = np.inf
    inner = ok & (p > 0.0) & (p < 1.0)
    two = inner & (k == 2.0)
    x[two] = -2.0 * np.log1p(-p[two])
    rest = inner & ~two
    if np.any(rest):
        x[rest] = 2.0 * _gamma_p_inverse(0.5 * k[rest], p[rest])
    return x.reshape(shape)


def chi2_cdf(x, dof):
    """Cumulative distribution function of the chi-square distribution
    (``scipy.stats.chi2.cdf``); 0 for ``x <= 0``, NaN for ``dof <= 0``."""
    x, k = np.broadcast_arrays(np.asarray(x, float), np.asarray(dof, float))
    shape = x.shape
    x, k = x.ravel(), k.ravel()
    out = np.full(x.shape, np.nan)
    ok = (k > 0.0) & ~np.isnan(x)
    out[ok] = _gamma_pq(0.5 * k[ok], np.maximum(0.5 * x[ok], 0.0))[0]
    out = out.reshape(shape)
    return float(out) if out.ndim == 0 else out
