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


def test_grid_epochs_only_fill_gaps_longer_than_the_interval():
    """Measurements every 0.25 s need no 1 s grid; a 3 s outage gets grid epochs inside it,
    none more than the interval from the next node; both ends are always epochs."""
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.01), 10)
    meas = np.round(np.arange(0.13, 10.0, 0.25), 10)
    meas = meas[(meas < 4.0) | (meas > 7.0)]  # an outage 4.0 .. 7.0 s
    for split in (True, False):  # between samples (strapdown) or at them (RISS)
        s = build_schedule(t, [meas], 1.0, 1e-6, split, [])
        grid = s.epochs[np.diff(s.ptr) == 0]  # the epochs without a measurement
        assert grid[0] == t[0] and grid[-1] == t[-1]
        inner = grid[1:-1]
        assert inner.size == 4 and np.all((inner > 3.87) & (inner < 7.13))  # in the outage
        assert np.max(np.diff(s.epochs)) <= 1.0 + 1e-9


def test_gap_grid_keeps_ends_and_long_gaps():
    from insgnss.filter.schedule import gap_grid

    grid = np.arange(0.0, 6.0 + 1e-9, 1.0)
    keep = gap_grid(grid, np.array([0.5, 1.2, 1.9, 4.9]), 1.0, 1e-6)
    # gaps: 0..0.5, 0.5..1.2, 1.2..1.9, 1.9..4.9 (3 s: 2, 3, 4 kept), 4.9..6.0 (1.1 s: 5)
    np.testing.assert_array_equal(keep, [True, False, True, True, True, True, True])
    assert gap_grid(grid, np.empty(0), 1.0, 1e-6).all()


def test_epoch_grid_always_keeps_every_grid_time():
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.01), 10)
    meas = np.round(np.arange(0.13, 10.0, 0.25), 10)
    s = build_schedule(t, [meas], 1.0, 1e-6, True, [], grid_in_gaps=False)
    np.testing.assert_allclose(s.epochs[np.diff(s.ptr) == 0], np.arange(0.0, 10.5, 1.0))
    from insgnss.errors import ConfigError
    from insgnss.filter.engine import FilterConfig

    with pytest.raises(ConfigError, match="epoch_grid"):
        FilterConfig(epoch_grid="sometimes").validate()
