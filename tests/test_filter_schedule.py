"""The engine's epoch schedule: the compiled high-rate event table against the array formula."""

import numpy as np
import pytest

from insgnss.filter.schedule import build_schedule


def _reference_events(t, ep, times, tol):
    """The high-rate part of the schedule by array operations (nearest sample, ties to the
    later one; row 0 never an event; ordered by sample, measurement, row)."""
    hj, hm, hr = [], [], []
    for k, tm in enumerate(times):
        rows = np.nonzero((tm > t[0] - tol) & (tm <= t[-1] + tol))[0]
        j = np.clip(np.searchsorted(t, tm[rows]), 1, t.size - 1)
        j = np.where(np.abs(t[j] - tm[rows]) <= np.abs(t[j - 1] - tm[rows]), j, j - 1)
        keep = j >= 1
        hj.append(j[keep])
        hm.append(np.full(int(keep.sum()), k))
        hr.append(rows[keep])
    hj_a = np.concatenate(hj).astype(np.int64)
    hm_a = np.concatenate(hm).astype(np.int64)
    hr_a = np.concatenate(hr).astype(np.int64)
    o = np.lexsort((hr_a, hm_a, hj_a))
    hj_a, hm_a, hr_a = hj_a[o], hm_a[o], hr_a[o]
    hr_ptr = np.searchsorted(hj_a, np.arange(t.size + 1))
    dense = np.zeros(ep.size, bool)
    seg = np.searchsorted(ep, t[hj_a], side="left")
    dense[np.unique(seg[(seg >= 1) & (seg < ep.size)])] = True
    lo = np.searchsorted(t, ep[:-1], side="right")
    hi = np.searchsorted(t, ep[1:], side="right")
    return hr_ptr, hm_a, hr_a, dense, int(np.sum((hi - lo)[dense[1:]]))


@pytest.mark.parametrize("seed", range(6))
def test_high_rate_events_equal_the_array_formula(seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.004, 0.006, 400))
    tol = 1e-6
    times = [
        t[rng.random(t.size) < 0.5] + 0.0,                        # on samples, sorted
        np.sort(rng.uniform(t[0] - 0.05, t[-1] + 0.05, 150)),     # between samples, some outside
        rng.uniform(t[0], t[-1], 80),                             # unsorted
        0.5 * (t[:-1] + t[1:])[::7],                              # exact midpoints: ties
        np.repeat(t[10:20], 2),                                   # duplicated times
    ]
    gen = [np.sort(rng.uniform(t[0], t[-1], 5))]
    s = build_schedule(t, gen, 0.3, tol, True, times)
    ref = _reference_events(t, s.epochs, times, tol)
    np.testing.assert_array_equal(s.hr_ptr, ref[0])
    np.testing.assert_array_equal(s.hr_m, ref[1])
    np.testing.assert_array_equal(s.hr_r, ref[2])
    np.testing.assert_array_equal(s.dense, ref[3])
    assert s.dense_samples == ref[4]


def test_no_high_rate_measurements():
    t = np.arange(0.0, 2.0, 0.01)
    s = build_schedule(t, [np.array([0.5, 1.0])], 1.0, 1e-6, True, [])
    assert s.hr_ptr.shape == (t.size + 1,) and not s.hr_ptr.any()
    assert s.hr_m.size == 0 and not s.dense.any() and s.dense_samples == 0
