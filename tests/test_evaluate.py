"""Outage schedules and evaluation against a reference."""

import numpy as np
import pandas as pd
import pytest

from insgnss.earth import enu_to_geodetic
from insgnss.evaluate import move_point, outage_metrics, position_errors
from insgnss.outages import in_windows, periodic_windows, window_index

LAT0, LON0, H0 = np.radians(40.1), np.radians(-105.15), 1600.0


def test_drive_schedule_matches_benchmark():
    t0 = 1436038458.499
    w = periodic_windows(t0, t0 + 549.0, 40.0, 15.0, 30.0, 30.0)
    assert len(w) == 11
    assert w[0] == pytest.approx((1436038498.499, 1436038513.499), abs=1e-6)
    assert all(b - a == pytest.approx(15.0) for a, b in w)
    t = t0 + np.arange(0, 549.0, 0.25)
    assert in_windows(t, w).sum() == 660  # 11 x 60 epochs withheld
    idx = window_index(t, w)
    assert idx.max() == 10 and (idx == 0).sum() == 60
    # boundaries: start inside, end outside
    assert in_windows([w[0][0], w[0][1]], w).tolist() == [True, False]


def _track(t, e, n, u):
    lat, lon, h = enu_to_geodetic(e, n, u, LAT0, LON0, H0)
    return pd.DataFrame({"lat": lat, "lon": lon, "height": h, "roll": 0.0 * t, "pitch": 0.0 * t,
                         "heading": 0.0 * t}, index=pd.Index(t, name="time"))


def test_position_errors_interpolates_and_measures():
    t_ref = np.arange(0, 100.0, 0.25)
    ref = _track(t_ref, 10 * t_ref, 0 * t_ref, 0 * t_ref)
    t_sol = np.arange(0, 100.0, 0.01)
    # (errors are in the local ENU of each reference point; 1 km from the origin the frames
    # differ by 0.16 mrad, hence the 1 mm tolerance)
    sol = _track(t_sol, 10 * t_sol + 0.3, 0 * t_sol - 0.4, 0 * t_sol + 0.1)
    err = position_errors(sol, ref)
    assert err["east"].dropna().to_numpy() == pytest.approx(0.3, abs=1e-3)
    assert err["north"].dropna().to_numpy() == pytest.approx(-0.4, abs=1e-3)
    assert err["horizontal"].dropna().to_numpy() == pytest.approx(0.5, abs=1e-3)
    # a gap in the solution leaves NaN
    sol_gap = sol[(sol.index < 40) | (sol.index > 41)]
    err2 = position_errors(sol_gap, ref)
    assert err2.loc[40.25:40.75, "east"].isna().all()



def _errors_by_arrays(sol, ref, max_gap):
    """The array formula of position_errors (bracketing samples to ECEF, interpolation, the
    difference in the ENU axes of the reference point; a sample within 1e-4 s taken as it
    is): what the compiled kernel must give."""
    from insgnss.earth import ecef_to_enu_vectors, geodetic_to_ecef

    ts, tr = sol.index.to_numpy(float), ref.index.to_numpy(float)
    s = [sol[c].to_numpy(float) for c in ("lat", "lon", "height")]
    r = [ref[c].to_numpy(float) for c in ("lat", "lon", "height")]
    j = np.searchsorted(ts, tr, side="right")
    ok = (j > 0) & (j < ts.size)
    jj = np.clip(j, 1, ts.size - 1)
    t0, t1 = ts[jj - 1], ts[jj]
    ok &= (t1 - t0) <= max_gap
    jprev = np.clip(j - 1, 0, ts.size - 1)
    exact = np.abs(ts[jprev] - tr) <= 1e-4
    w = np.where(t1 > t0, (tr - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)
    x0 = np.column_stack(geodetic_to_ecef(*(c[jj - 1] for c in s)))
    x1 = np.column_stack(geodetic_to_ecef(*(c[jj] for c in s)))
    xi = x0 + w[:, None] * (x1 - x0)
    snap = ~ok & exact
    xi[snap] = np.column_stack(geodetic_to_ecef(*(c[jprev[snap]] for c in s)))
    enu = ecef_to_enu_vectors(xi - np.column_stack(geodetic_to_ecef(*r)), r[0], r[1])
    enu[~(ok | exact)] = np.nan
    return enu


@pytest.mark.parametrize("dt_sol", [0.25, 0.01, 0.7])
def test_position_errors_kernel_equals_the_array_formula(dt_sol):
    """The compiled kernel against the array formula: the solution at the reference rate
    (each sample the end of one bracket and the start of the next), faster and slower; a gap
    wider than max_gap (NaN), reference epochs before and after the solution (NaN); at the
    rate of the reference the samples lie 3e-5 s after its epochs."""
    rng = np.random.default_rng(5)
    t_ref = np.arange(-2.0, 102.0, 0.25)
    ref = _track(t_ref, 12 * t_ref, 3 * np.sin(t_ref / 7), 0.5 * t_ref)
    t_sol = np.arange(0.0, 100.0, dt_sol) + (3e-5 if dt_sol == 0.25 else 0.0)
    t_sol = t_sol[(t_sol < 40.0) | (t_sol > 43.0)]
    sol = _track(t_sol, 12 * t_sol + rng.normal(0, 0.5, t_sol.size),
                 3 * np.sin(t_sol / 7) + rng.normal(0, 0.5, t_sol.size),
                 0.5 * t_sol + rng.normal(0, 0.2, t_sol.size))
    got = position_errors(sol, ref, max_gap=1.0)[["east", "north", "up"]].to_numpy()
    want = _errors_by_arrays(sol, ref, 1.0)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got[~np.isnan(got)], want[~np.isnan(want)], rtol=0, atol=1e-9)
    assert np.isnan(got[t_ref < 0.0]).all() and np.isnan(got[t_ref > 100.0]).all()
    covered = ~np.isnan(got[:, 0])
    inside = (t_ref >= t_sol[0]) & (t_ref <= t_sol[-1])
    before, after = t_sol[t_sol < 40.0][-1], t_sol[t_sol > 40.0][0]
    gap = (t_ref > before + 1e-4) & (t_ref < after)  # a bracket wider than max_gap
    assert gap.sum() >= 12 and not covered[gap].any()
    assert covered[inside & ~gap].all()


def test_lever_arm_moves_point():
    t = np.arange(3.0)
    tr = _track(t, 0 * t, 0 * t, 0 * t)
    tr["heading"] = np.pi / 2  # forward = east
    moved = move_point(tr, [0.0, 2.0, 0.0])
    err = position_errors(moved, tr, max_gap=2.0)
    assert err["east"].to_numpy() == pytest.approx(2.0, abs=1e-6)


def test_outage_metrics():
    t = np.arange(0, 100.0, 0.25)
    hz = np.where((t >= 40) & (t < 55), (t - 40) * 0.1, 0.02)
    err = pd.DataFrame({"east": hz, "north": 0 * t, "up": 0 * t + 0.5, "horizontal": hz},
                       index=t)
    table, summary = outage_metrics(err, [(40.0, 55.0)], settle_time=10.0)
    assert table["end_h_err_m"].iloc[0] == pytest.approx(14.75 * 0.1)
    assert table["max_h_err_m"].iloc[0] == pytest.approx(14.75 * 0.1)
    assert summary["non_outage_rms_h_m"] == pytest.approx(0.02)
    assert summary["n_outages"] == 1 and table["complete"].iloc[0]


def test_outage_end_consistency_against_the_filter_sigma():
    """Ratio |e_h| / hypot(s_E, s_N) and the two-axis 3-sigma test (chi2 2 dof 99.73 % =
    11.83) at the last epoch of each outage (issue 22)."""
    t = np.arange(0, 100.0, 0.25)
    err = pd.DataFrame({"east": 0 * t, "north": 0 * t, "up": 0 * t, "horizontal": 0 * t},
                       index=t)
    err["east_std"], err["north_std"] = 0.6, 0.8
    end = [40.0 + 14.75, 70.0 + 14.75]
    err.loc[end[0], ["east", "north"]] = (1.8, 2.4)   # 3 sigma on each axis: d2 = 18 > 11.83
    err.loc[end[1], ["east", "north"]] = (0.6, 0.8)   # 1 sigma on each axis: d2 = 2
    err["horizontal"] = np.hypot(err["east"], err["north"])
    table, summary = outage_metrics(err, [(40.0, 55.0), (70.0, 85.0)])
    assert table["end_h_sigma_m"].to_numpy() == pytest.approx([1.0, 1.0])
    assert table["end_h_err_sigma_ratio"].to_numpy() == pytest.approx([3.0, 1.0])
    assert list(table["end_within_3sigma"]) == [False, True]
    assert summary["end_within_3sigma_fraction"] == pytest.approx(0.5)
    assert summary["end_h_err_sigma_ratio_max"] == pytest.approx(3.0)


def test_stored_errors_keep_the_output_rate_epochs_and_the_aiding_epochs():
    """A 200 Hz error table is kept at the 10 Hz output epochs plus the samples around each
    GNSS epoch (not on the 10 Hz grid), the rows the report and the files have."""
    from types import SimpleNamespace

    from insgnss.job.evaluation import stored_errors

    t = 100.0 + np.arange(2000) / 200.0  # 10 s at 200 Hz
    err = pd.DataFrame({"east": np.sin(t), "north": np.cos(t), "up": t * 0.0}, index=t)
    err["horizontal"] = np.hypot(err["east"], err["north"])
    tg = np.array([101.2525, 105.5125])  # GNSS epochs between IMU samples and off the grid
    inputs = SimpleNamespace(gnss=pd.DataFrame(index=tg), control_points=None)
    job = {"outputs": {"rate_hz": "auto"}, "process": {"preset": "standard"}}
    kept = stored_errors(err, inputs, job)
    tk = kept.index.to_numpy(float)
    grid = np.round(np.arange(100.0, 110.0, 0.1), 6)
    assert np.isin(grid, np.round(tk, 6)).all()  # every 10 Hz epoch
    for x in tg:  # the samples either side of each GNSS epoch
        assert np.isin([t[t < x][-1], t[t > x][0]], tk).all()
    assert len(kept) == len(grid) + 2 * len(tg) + 1  # and the last sample
    assert np.array_equal(kept.to_numpy(), err.loc[tk].to_numpy())  # rows, not resampled
    every = stored_errors(err, inputs, {"outputs": {"rate_hz": "imu"},
                                        "process": {"preset": "standard"}})
    assert len(every) == len(err)


def test_reference_errors_in_blocks_equal_the_whole_table():
    """Errors formed block by block of reference epochs from the bracketing solution rows
    (a store Table, blocks of 7 epochs) are bit-identical to those of the whole solution, at
    the antenna (attitude used) and with reference epochs outside the solution and in a gap."""
    from types import SimpleNamespace

    from insgnss.filter.store import Table
    from insgnss.job.evaluation import reference_errors

    rng = np.random.default_rng(3)
    ts = np.arange(0.0, 20.0, 0.01)
    ts = np.delete(ts, np.arange(800, 900))  # a 1 s gap: not covered
    n = ts.size
    sol = pd.DataFrame({"lat": np.radians(48.0) + 1e-7 * np.cumsum(rng.normal(size=n)),
                        "lon": np.radians(11.0) + 1e-7 * np.cumsum(rng.normal(size=n)),
                        "height": 500 + np.cumsum(rng.normal(size=n)) * 0.01,
                        "roll": 0.01 * rng.normal(size=n), "pitch": 0.01 * rng.normal(size=n),
                        "heading": np.linspace(0, 3, n),
                        "east_std": 1 + ts * 0.01, "north_std": 2 + ts * 0.01,
                        "up_std": 3 + ts * 0.01}, index=ts)
    tr = np.concatenate([[-1.0], np.arange(0.0, 21.0, 0.037)])  # before, inside, after
    ref = pd.DataFrame({"lat": np.full(tr.size, np.radians(48.0)),
                        "lon": np.full(tr.size, np.radians(11.0)),
                        "height": np.full(tr.size, 500.0)}, index=tr)
    inputs = SimpleNamespace(reference=ref, reference_point="antenna",
                             lever_arm=np.array([0.2, 1.0, 1.5]))
    pt = move_point(sol, inputs.lever_arm)
    whole = position_errors(pt, ref)
    for c in ("east_std", "north_std", "up_std"):
        whole[c] = np.interp(tr, ts, sol[c].to_numpy())
    table = Table(ts, sol.to_numpy(), list(sol.columns))
    blocks = reference_errors(table, inputs, block=7)
    assert list(blocks.columns) == list(whole.columns)
    np.testing.assert_array_equal(blocks.to_numpy(), whole.to_numpy())
    assert np.isnan(blocks["east"].iloc[0]) and np.isnan(blocks["east"].iloc[-1])
    gap = (tr > 8.0) & (tr < 8.99)
    assert gap.any() and np.isnan(blocks.loc[gap, "east"]).all()
    assert np.isfinite(blocks["east"]).sum() > 400
