"""Stillness detectors: statistics against closed forms, decision logic, simulated gait."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from insgnss.detect import (
    DetectorConfig,
    amv_statistic,
    are_statistic,
    detect_arrays,
    detect_stillness,
    drop_short_runs,
    fill_short_runs,
    gait_adaptive_threshold,
    gait_period,
    hysteresis_decision,
    mag_statistic,
    quiet_runs,
    running_max,
    running_min,
    running_quantile,
    shoe_statistic,
    shrink_runs,
    stance_entry_rms,
    valley_level,
)
from insgnss.errors import ConfigError
from insgnss.imu import increments_table, rates_table, trapezoid_increments

G = 9.81
D = np.pi / 180.0


def _brute(x, half, fn):
    n = x.size
    return np.array([fn(x[max(0, k - half):min(n, k + half + 1)]) for k in range(n)])


# --- statistics ------------------------------------------------------------------------------
def test_statistics_closed_form_constant_input():
    n = 50
    w = np.tile([0.1, -0.2, 0.05], (n, 1))
    a = np.tile([0.3, -0.4, 9.7], (n, 1))
    sa, sw = 0.02, 0.003
    # constant specific force: a_j - g abar/|abar| = (1 - g/|a|) a
    na = np.linalg.norm(a[0])
    expect = (na - G) ** 2 / sa**2 + np.sum(w[0] ** 2) / sw**2
    np.testing.assert_allclose(shoe_statistic(a, w, 7, sa, sw, G), expect, rtol=1e-12)
    np.testing.assert_allclose(are_statistic(w, 7), np.linalg.norm(w[0]), rtol=1e-12)
    np.testing.assert_allclose(amv_statistic(a, 7), 0.0, atol=1e-12)
    np.testing.assert_allclose(mag_statistic(a, 7, G), abs(na - G), rtol=1e-12)


def test_statistics_against_brute_force_windows():
    rng = np.random.default_rng(3)
    a = rng.normal([0, 0, G], 0.5, (40, 3))
    w = rng.normal(0, 0.3, (40, 3))
    W = 5  # centred: k-2 .. k+2, truncated at the ends
    sa, sw = 0.1, 0.05

    def shoe(k):
        lo, hi = max(0, k - 2), min(40, k + 3)
        aa, ww = a[lo:hi], w[lo:hi]
        u = aa.mean(0) / np.linalg.norm(aa.mean(0))
        return np.mean(np.sum((aa - G * u) ** 2, 1) / sa**2 + np.sum(ww**2, 1) / sw**2)

    def amv(k):
        aa = a[max(0, k - 2):min(40, k + 3)]
        return np.sqrt(np.mean(np.sum((aa - aa.mean(0)) ** 2, 1)))

    np.testing.assert_allclose(shoe_statistic(a, w, W, sa, sw, G), [shoe(k) for k in range(40)],
                               rtol=1e-12)
    np.testing.assert_allclose(amv_statistic(a, W), [amv(k) for k in range(40)], rtol=1e-12)
    mags = np.linalg.norm(a, axis=1)
    np.testing.assert_allclose(mag_statistic(a, W, G),
                               _brute(mags, 2, lambda v: np.sqrt(np.mean((v - G) ** 2))),
                               rtol=1e-12)


def test_amv_statistic_sliding_sums_over_many_blocks():
    """The sliding sums of amv_statistic (refreshed every AMV_BLOCK samples) against the
    two-pass standard deviation of every window: a still stretch (gravity plus 0.01 m/s^2 of
    noise, where E[x^2] - E[x]^2 about zero would lose 8 digits) then motion of several
    m/s^2, over ten blocks and both truncated ends."""
    from numpy.lib.stride_tricks import sliding_window_view

    from insgnss.detect import AMV_BLOCK

    rng = np.random.default_rng(11)
    n, W = 10 * AMV_BLOCK + 37, 100
    a = rng.normal([0.2, -0.1, G], 0.01, (n, 3))
    a[n // 2:] += 3.0 * np.sin(np.arange(n - n // 2)[:, None] * [0.01, 0.02, 0.005])
    pad_lo, pad_hi = (W - 1) // 2, W - 1 - (W - 1) // 2
    full = sliding_window_view(a, W, axis=0)  # windows k - pad_lo .. k + pad_hi inside
    expect = np.empty(n)
    inner = np.sqrt(np.sum(full.var(axis=2), axis=1))
    expect[pad_lo:n - pad_hi] = inner
    for k in [*range(pad_lo), *range(n - pad_hi, n)]:
        aa = a[max(0, k - pad_lo):min(n, k + pad_hi + 1)]
        expect[k] = np.sqrt(np.mean(np.sum((aa - aa.mean(0)) ** 2, 1)))
    got = amv_statistic(a, W)
    np.testing.assert_allclose(got, expect, rtol=1e-10)
    assert 0.015 < np.median(got[: n // 2 - W]) < 0.02  # sqrt(3) * 0.01 in the still part


def test_running_max_min_match_brute_force():
    x = np.random.default_rng(0).normal(size=301)
    for half in (0, 1, 7, 40, 400):
        np.testing.assert_array_equal(running_max(x, half), _brute(x, half, np.max))
        np.testing.assert_array_equal(running_min(x, half), _brute(x, half, np.min))


# --- decision logic ------------------------------------------------------------------------
def test_hysteresis_enters_below_and_leaves_above_ratio():
    stat = np.array([5, 3, 0.5, 1.5, 1.9, 2.5, 1.5, 0.9, 3.0])
    thr = np.ones_like(stat)
    np.testing.assert_array_equal(hysteresis_decision(stat, thr, 1.0),
                                  [0, 0, 1, 0, 0, 0, 0, 1, 0])
    np.testing.assert_array_equal(hysteresis_decision(stat, thr, 2.0),
                                  [0, 0, 1, 1, 1, 0, 0, 1, 0])


def test_short_run_filters():
    f = np.array([0, 1, 1, 0, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1], bool)
    # still runs shorter than 3 dropped (the first, length 2); end runs count too
    np.testing.assert_array_equal(drop_short_runs(f, 3), [0, 0, 0, 0, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(drop_short_runs(f, 5), np.zeros(14, bool))
    # interior motion gaps shorter than 2 filled; the leading gap is not interior
    np.testing.assert_array_equal(fill_short_runs(f, False, 2),
                                  [0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1])


def test_shrink_runs_margin():
    f = np.array([1, 1, 1, 0, 0, 1, 1, 1, 1, 1, 0, 1, 1, 0, 1, 1, 1], bool)
    # interior runs lose 1 sample at both ends; runs touching the record ends keep that end
    np.testing.assert_array_equal(shrink_runs(f, 1),
                                  [1, 1, 0, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0, 1, 1])
    cfg = DetectorConfig(method="are", window=0.01, threshold=0.5, margin=0.02)
    t = np.arange(f.size) * 0.01
    w = np.where(f[:, None], 0.0, 2.0) * np.ones((1, 3))
    a = np.tile([0.0, 0.0, G], (f.size, 1))
    still, _, _ = detect_arrays(t, w, a, cfg)
    np.testing.assert_array_equal(still, shrink_runs(f, 2))


def test_quiet_runs_and_gait_adaptive_threshold():
    # standing (1e4), then a "walk" with valleys 1e6 and swings 1e10, then a "run" with valleys
    # 1e8 and swings 1e10.5, then a shuffle with no swing above the gait level (1e8 peaks)
    walk = np.tile(np.r_[np.full(40, 1e6), np.full(60, 1e10)], 6)
    run = np.tile(np.r_[np.full(20, 1e8), np.full(50, 10**10.5)], 8)
    shuffle = np.tile(np.r_[np.full(30, 3e6), np.full(30, 1e8)], 6)
    stat = np.r_[np.full(300, 1e4), walk, run, shuffle]
    q = quiet_runs(stat, 1e5, 100)
    assert q[:300].all() and not q[300:].any()
    thr = gait_adaptive_threshold(stat, 150, 1e5, 10.0, 100.0, 1e9, 100, np.inf)
    assert np.all(thr[:150] == 1e5)  # standing, far from any gait: the floor
    i_walk = 300 + 300  # middle of the walk
    assert thr[i_walk] == pytest.approx(1e7)  # 10 x valley level
    i_run = 300 + 600 + 280  # middle of the run
    assert thr[i_run] == pytest.approx(10**10.5 / 100)  # capped by peak / ratio
    i_sh = 300 + 600 + 560 + 180
    assert thr[i_sh] == 1e5  # no gait: floor only
    still = hysteresis_decision(stat, thr, 1.0)
    assert still[:300].all()
    assert still[i_walk:i_walk + 40].all() and not still[i_walk + 40:i_walk + 100].any()
    assert still[i_run:i_run + 20].all()  # running stance valleys are caught
    assert not still[i_run + 20:i_run + 70].any()
    assert not still[300 + 600 + 560 + 160:].any()  # shuffle valleys (3e6) are not


# --- front end -----------------------------------------------------------------------------
def _synthetic_gait(rate=200.0, seed=0):
    """Rates table: 2 s still, then strides of 0.6 s stance / 0.5 s swing, body z up."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    pattern = []
    pattern += [True] * int(2.0 * rate)
    for _ in range(8):
        pattern += [True] * int(0.6 * rate) + [False] * int(0.5 * rate)
    pattern += [True] * int(1.0 * rate)
    still = np.array(pattern)
    n = still.size
    t = np.arange(n) * dt
    w = rng.normal(0, 0.002, (n, 3))
    a = rng.normal(0, 0.01, (n, 3))
    a[:, 2] += G
    # swings: half-sine bursts of rotation (pitch) and acceleration
    idx = np.flatnonzero(~still)
    starts = idx[np.r_[True, np.diff(idx) > 1]]
    m = int(0.5 * rate)
    u = np.arange(m) / m
    for s in starts:
        w[s:s + m, 0] += 6.0 * np.sin(2 * np.pi * u)
        a[s:s + m, 1] += 15.0 * np.sin(2 * np.pi * u)
        a[s:s + m, 2] += 8.0 * np.sin(np.pi * u)
    return rates_table(t, w, a), still


@pytest.mark.parametrize("method,threshold", [
    ("shoe", 1e3), ("are", 0.3), ("amv", 0.2), ("mag", 0.5), ("adaptive", 1e3)])
def test_detectors_on_synthetic_gait(method, threshold):
    imu, truth = _synthetic_gait()
    cfg = DetectorConfig(method=method, window=0.025, threshold=threshold, sigma_a=0.01,
                         sigma_w=0.1 * D, gravity=G, adapt_gait_peak=1e5)
    res = detect_stillness(imu, cfg)
    assert isinstance(res.still, pd.Series) and res.still.dtype == bool
    np.testing.assert_array_equal(res.still.index.to_numpy(), imu.index.to_numpy())
    agree = np.mean(res.still.to_numpy() == truth)
    assert agree > 0.95, (method, agree)
    # every swing is seen as motion: the middle third of each swing has no still sample
    idx = np.flatnonzero(~truth)
    starts = idx[np.r_[True, np.diff(idx) > 1]]
    assert starts.size == 8
    for s in starts:
        assert not res.still.to_numpy()[s + 33:s + 67].any()
    assert res.intervals()[0][0] == imu.index[0]


def test_min_stance_removes_short_dips():
    imu, truth = _synthetic_gait()
    t = imu.index.to_numpy()
    w = imu[["gyro_x", "gyro_y", "gyro_z"]].to_numpy().copy()
    # a 20 ms "stillness" in the middle of the first swing
    s = np.flatnonzero(~truth)[0] + 50
    w[s:s + 4] = 0.0
    a = imu[["accel_x", "accel_y", "accel_z"]].to_numpy().copy()
    a[s:s + 4] = [0.0, 0.0, G]
    base = DetectorConfig(method="shoe", window=0.01, threshold=1e3, sigma_a=0.01,
                          sigma_w=0.1 * D, gravity=G)
    s1, _, _ = detect_arrays(t, w, a, base)
    assert s1[s:s + 4].any()
    s2, _, _ = detect_arrays(t, w, a, DetectorConfig(**{**base.to_dict(), "min_stance": 0.05}))
    assert not s2[s - 5:s + 10].any()
    assert np.mean(s2 == truth) > 0.95


def test_increment_table_gives_same_decisions():
    imu, _ = _synthetic_gait()
    t = imu.index.to_numpy()
    w = imu[["gyro_x", "gyro_y", "gyro_z"]].to_numpy()
    a = imu[["accel_x", "accel_y", "accel_z"]].to_numpy()
    inc = increments_table(t, trapezoid_increments(t, w), trapezoid_increments(t, a))
    cfg = DetectorConfig(method="are", window=0.05, threshold=0.3)
    r1 = detect_stillness(imu, cfg).still.to_numpy()
    r2 = detect_stillness(inc, cfg).still.to_numpy()
    assert np.mean(r1 == r2) > 0.99


def test_gravity_estimate_and_keyword_override():
    imu, truth = _synthetic_gait()
    r = detect_stillness(imu, method="mag", threshold=0.05, window=0.05)  # gravity estimated
    assert np.mean(r.still.to_numpy()[truth]) > 0.9
    assert r.method == "mag" and 0.5 < r.fraction < 0.8


def test_config_validation():
    with pytest.raises(ConfigError, match="unknown stillness detector"):
        DetectorConfig(method="magic")
    with pytest.raises(ConfigError, match="unknown detector settings"):
        DetectorConfig.from_dict({"method": "shoe", "treshold": 3})
    with pytest.raises(ConfigError):
        DetectorConfig(hysteresis=0.5)
    with pytest.raises(ConfigError):
        DetectorConfig(window=0.0)
    assert DetectorConfig.from_dict({"method": "are", "threshold": 0.2}).threshold == 0.2


# --- valley level, gait period, per-recording threshold selection ---------------------------
def test_running_quantile_matches_brute_force():
    rng = np.random.default_rng(5)
    x = rng.normal(size=400)
    x[50:60] = np.nan  # excluded samples
    x[300:400] = np.nan  # and a window that holds none at the end
    half, q = 12, 0.05

    def ref(k):
        v = x[max(0, k - half):k + half + 1]
        v = v[np.isfinite(v)]
        return np.quantile(v, q) if v.size else np.nan

    expect = np.array([ref(k) for k in range(x.size)])
    got = running_quantile(x, half, q, 1)
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-12)
    assert np.isnan(got[-1]) and np.isnan(got[320])
    # evaluated every 8th sample and interpolated: exact at the nodes, and between them within
    # the Lipschitz bound of the input (slope 1/200 per sample: 8/200 * 0.5)
    s = np.sin(np.arange(400) / 200.0)
    sparse = running_quantile(s, half, q, 8)
    dense = running_quantile(s, half, q, 1)
    np.testing.assert_allclose(sparse[::8], dense[::8], atol=1e-12)
    assert np.max(np.abs(sparse - dense)) <= 8 / 200 * 0.5 + 1e-12


@pytest.mark.parametrize("q", [0.0, 0.05, 0.5, 0.95, 1.0])
def test_running_quantile_selection_ties_infinities_trends(q):
    # a random walk (consecutive windows share their low values: the previous window's order
    # statistic bounds the heap), rounded for ties, with NaN and +-inf left out
    rng = np.random.default_rng(11)
    x = np.round(np.cumsum(rng.normal(size=600)), 1)
    x[rng.random(x.size) < 0.2] = np.nan
    x[rng.random(x.size) < 0.03] = np.inf
    x[rng.random(x.size) < 0.03] = -np.inf
    for half, step in ((20, 1), (37, 5), (3, 2)):
        nodes = np.append(np.arange(0, x.size, step), x.size - 1)
        got = running_quantile(x, half, q, step)[nodes]
        expect = []
        for k in nodes:
            v = x[max(0, k - half):k + half + 1]
            v = v[np.isfinite(v)]
            expect.append(np.quantile(v, q) if v.size else np.nan)
        np.testing.assert_allclose(got, expect, rtol=0, atol=1e-12)


@pytest.mark.parametrize("period", [0.72, 1.1, 1.6])
def test_gait_period_of_a_periodic_statistic(period):
    dt = 0.005
    t = np.arange(int(30 / dt)) * dt
    rng = np.random.default_rng(1)
    phase = (t % period) / period
    stat = np.where(phase < 0.35, 1e5, 1e9) * np.exp(rng.normal(0, 0.5, t.size))
    assert gait_period(stat, dt) == pytest.approx(period, abs=dt)
    # white noise has no gait
    assert np.isnan(gait_period(np.exp(rng.normal(0, 1, t.size)), dt))


def _walk_then_run():
    """SHOE-like statistic: 2 s standing (1e4), walking strides of 1.1 s (valleys 1e6, swings
    1e10), running strides of 0.7 s (valleys 1e8, swings 10^10.5), at 200 Hz."""
    walk = np.tile(np.r_[np.full(80, 1e6), np.full(140, 1e10)], 10)
    run = np.tile(np.r_[np.full(30, 1e8), np.full(110, 10**10.5)], 14)
    stat = np.r_[np.full(400, 1e4), walk, run]
    return np.arange(stat.size) * 0.005, stat


def test_valley_level_and_the_valley_method():
    t, stat = _walk_then_run()
    cfg = DetectorConfig(method="valley", threshold=1e5, adapt_factor=10.0, quiet_duration=0.5)
    v = valley_level(stat, 0.005, cfg)
    i_walk, i_run = 400 + 5 * 220 + 40, 400 + 2200 + 7 * 140 + 15
    assert v[i_walk] == pytest.approx(1e6, rel=1e-9)  # the stance depth of the walk
    assert v[i_run] == pytest.approx(1e8, rel=1e-9)  # ... and of the run, 2 decades higher
    assert np.isinf(v[:100]).all()  # only standing in the window: no valley
    thr = np.where(np.isfinite(v), cfg.adapt_factor * v, cfg.threshold)
    st = hysteresis_decision(stat, thr, 1.0)
    assert st[:400].all()
    assert st[i_walk - 40:i_walk + 40].all() and not st[i_walk + 40:i_walk + 180].any()
    assert st[i_run - 15:i_run + 15].all() and not st[i_run + 15:i_run + 125].any()
    # the method end to end on an IMU table (its 0.6 s stances are not standing: quiet 1 s)
    imu, truth = _synthetic_gait()
    res = detect_stillness(imu, DetectorConfig(method="valley", window=0.025, threshold=1e3,
                                               sigma_a=0.01, sigma_w=0.1 * D, gravity=G,
                                               quiet_duration=1.0))
    assert res.method == "valley" and np.mean(res.still.to_numpy() == truth) > 0.95


def test_stance_entry_rms():
    still = np.zeros(30, bool)
    still[0:3] = still[8:12] = still[18:22] = still[26:30] = True
    nu = np.full((30, 3), np.nan)
    nu[still] = 0.001
    nu[8] = [0.3, 0.0, 0.4]  # 0.5 m/s at the first stance after the start
    nu[18] = [0.0, 0.1, 0.0]
    nu[26] = [0.0, 0.0, -0.2]
    assert stance_entry_rms(nu, still) == pytest.approx(np.sqrt((0.25 + 0.01 + 0.04) / 3))
    assert stance_entry_rms(nu, still, min_stances=4) == np.inf
    assert stance_entry_rms(np.full((30, 3), np.nan), still) == np.inf  # no updates applied


# --- static windows found in the data ---------------------------------------------------------
def _still_then_hand_then_walk(rate=100.0, seed=4):
    """A device still on a table (0-5 s, sensor noise 0.01 m/s^2 and 0.002 rad/s), then held in
    a trembling hand (5-10 s: 0.4 m/s^2, 0.05 rad/s at 2-4 Hz), then carried walking."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 1.0 / rate)
    f = np.zeros((t.size, 3))
    f[:, 2] = 9.81
    w = np.zeros((t.size, 3))
    hand = (t >= 5.0) & (t < 10.0)
    walk = t >= 10.0
    f[hand, 0] += 0.4 * np.sin(2 * np.pi * 3.0 * t[hand])
    w[hand, 1] += 0.05 * np.sin(2 * np.pi * 2.0 * t[hand])
    f[walk, 2] += 2.0 * np.sin(2 * np.pi * 2.0 * t[walk])
    w[walk, 2] += 0.5 * np.sin(2 * np.pi * 1.0 * t[walk])
    f += 0.01 * rng.standard_normal(f.shape)
    w += 0.002 * rng.standard_normal(w.shape)
    return rates_table(t, w, f)


def test_static_windows_tell_still_from_stationary():
    from insgnss.detect import find_static_windows

    imu = _still_then_hand_then_walk()
    sw = find_static_windows(imu, max_accel_std=1.0, max_rate_std=np.radians(10.0))
    # the floor is the sensor noise (vector std of 3 axes of 0.01)
    assert sw.accel_floor == pytest.approx(0.01 * np.sqrt(3), rel=0.3)
    (a0, a1), = [s for s in sw.still if s[0] < 1.0]
    assert a0 == 0.0 and 4.4 <= a1 <= 5.0  # the table, minus the window overhang
    stationary = [s for s in sw.stationary if s[0] < 1.0][0]
    assert 9.4 <= stationary[1] <= 10.0  # the hand is stationary, not still
    assert all(b < 10.0 for _, b in sw.stationary)  # walking is neither
    a, _ = sw.motion(6.0, 9.0)
    assert a == pytest.approx(0.4 / np.sqrt(2), rel=0.2)  # the hand's motion is measured
    # an excluded interval (a bridged gap, GNSS showing motion) is never static
    sw2 = find_static_windows(imu, max_accel_std=1.0, max_rate_std=np.radians(10.0),
                              exclude=[(2.0, 2.1)])
    assert [s for s in sw2.still if s[0] < 1.0][0][1] < 2.0


def test_in_intervals_matches_the_interval_by_interval_mask():
    """One binary-search pass gives the closed-interval mask of every interval (padded,
    overlapping, empty, outside the samples) that testing each interval in turn gives."""
    from insgnss.detect import in_intervals

    rng = np.random.default_rng(11)
    t = np.sort(rng.uniform(0.0, 100.0, 4000))
    starts = rng.uniform(0.0, 100.0, 40)
    iv = [(a, a + d) for a, d in zip(starts, rng.uniform(0.0, 3.0, 40), strict=True)]
    iv += [(float(t[7]), float(t[7])), (-10.0, -5.0), (99.0, 200.0)]
    for pad in (0.0, 0.7):
        ref = np.zeros(t.size, bool)
        for a, b in iv:
            ref |= (t >= a - pad) & (t <= b + pad)
        assert np.array_equal(in_intervals(t, iv, pad), ref)
    assert ref.any() and not ref.all()
    assert not in_intervals(t, []).any()
