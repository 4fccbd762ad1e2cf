"""Engine: propagation equals the strapdown, IMU splitting at epochs between samples, outputs,
configuration checks, health failures that keep the partial result, discretisation options."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from filter_sim import (
    car_truth,
    corrupt_imu,
    gnss_from_truth,
    initial_with_error,
    nav_errors,
    perturbed_initial,
)

from insgnss.errors import ConfigError, FilterHealthError
from insgnss.filter import (
    BIAS_COLS,
    STD_COLS,
    FilterConfig,
    GnssPosition,
    GnssVelocity,
    Measurement,
    run_filter,
)
from insgnss.filter.store import dense_rows
from insgnss.imu import grade, increments
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS, mechanize


class _Never(Measurement):
    """Epochs without data: forces filter epochs (and IMU splits) at arbitrary times."""

    name = "never"

    def evaluate(self, i, nav):
        return None


class _Bad(Measurement):
    """A measurement with a negative noise variance: the update destroys P."""

    name = "bad"

    def evaluate(self, i, nav):
        H = np.zeros((1, nav.layout.n))
        H[0, 0] = 1.0
        return np.array([0.0]), H, np.array([[-1e-4]])


@pytest.fixture(scope="module")
def case():
    truth = car_truth(120.0, 50.0)
    rng = np.random.default_rng(2)
    imu, errs = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(truth, rng)
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    return truth, imu, gnss, init


def test_without_measurements_forward_is_the_strapdown(case):
    truth, imu, _, init = case
    res = run_filter(imu, init, [], FilterConfig(imu_model="tactical"))
    mech = mechanize(imu, init)
    assert res.complete and res.error is None
    assert np.allclose(res.forward[NAV_COLS].to_numpy(), mech.to_numpy(), rtol=0, atol=1e-10)
    # covariance only grows; the smoother has nothing to add
    assert np.all(np.diff(res.forward["north_std"].to_numpy()) >= -1e-12)
    assert np.allclose(res.smoothed[NAV_COLS].to_numpy(), mech.to_numpy(), atol=1e-10)
    assert np.allclose(res.smoothed["north_std"], res.forward["north_std"], rtol=1e-9)
    assert len(res.innovations) == 0 and len(res.rejected) == 0
    assert res.epoch_times.size == 121  # the 1 s epoch grid


def test_epochs_between_samples_split_the_increments(case):
    truth, imu, _, init = case
    t = imu.index.to_numpy()
    odd = np.sort(np.r_[t[:-1] + 0.0037, t[5:-1:7] + 0.0191])  # many splits
    res = run_filter(imu, init, [_Never(odd)], FilterConfig(imu_model="tactical", smoother=False))
    mech = mechanize(imu, init)
    d = nav_errors(res.forward, mech)
    # splitting every interval (~7000 splits in 120 s of manoeuvres) changes only the
    # second-order integration terms (~1e-9 m/s, 1e-12 rad per split): far below any sensor
    # error, while a wrong share of one increment would cost ~1e-2 m/s at once
    assert d[["east", "north", "up"]].abs().to_numpy().max() < 5e-3
    assert d[["vel_e", "vel_n", "vel_u"]].abs().to_numpy().max() < 5e-5
    assert d[["phi_e", "phi_n", "phi_u"]].abs().to_numpy().max() < 5e-8
    assert res.epoch_times.size > 5000


def test_gnss_between_samples(case):
    """GNSS at times between IMU samples: truth at 100 Hz, IMU at 50 Hz, GNSS on odd rows."""
    fine = car_truth(120.0, 100.0)
    truth = fine.iloc[::2]
    rng = np.random.default_rng(3)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(fine.iloc[1:], rng)  # t = k + 0.01
    assert not np.any(np.isin(gnss.index, imu.index))
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], FilterConfig(imu_model="tactical"))
    err = nav_errors(res.forward, truth)
    assert np.sqrt(np.mean(err["east"] ** 2 + err["north"] ** 2)) < 0.6
    nis = res.innovations.groupby("type")["nis"].mean()
    assert 2.3 < nis["gnss_pos"] < 3.8 and 2.3 < nis["gnss_vel"] < 3.8
    assert res.innovations["time"].isin(gnss.index).all()


def test_outputs_and_logs(case):
    truth, imu, gnss, init = case
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], FilterConfig(imu_model="tactical"))
    for df in (res.forward, res.smoothed):
        assert list(df.columns[:18]) == NAV_COLS + STD_COLS
        for c in BIAS_COLS:
            assert c in df.columns and f"{c}_std" in df.columns
        assert df.index.equals(imu.index) and np.isfinite(df.to_numpy()).all()
    inn = res.innovations
    expected = {"time", "type", "dof", "nis", "threshold", "accepted", "innov_0", "innov_std_2"}
    assert expected <= set(inn.columns)
    assert len(inn) == 2 * len(gnss) and inn["accepted"].all() and len(res.rejected) == 0
    assert res.layout.n == 15 and res.P_filtered.shape == (res.epoch_times.size, 15, 15)
    assert set(res.timing) >= {"mechanization", "covariance", "updates", "smoother", "total"}
    # smoothing never increases the uncertainty
    for c in ("east_std", "vel_n_std", "heading_std", "accel_bias_z_std"):
        assert np.all(res.smoothed[c].to_numpy() <= res.forward[c].to_numpy() * (1 + 1e-9) + 1e-15)
    # and at the end they coincide
    assert np.allclose(res.smoothed.iloc[-1], res.forward.iloc[-1], rtol=1e-9, atol=1e-12)


def test_forward_only_run_keeps_innovations_and_forward(case):
    """A forward-only run (``smoother=False``, the self-tuning's): the same innovations,
    forward table and feedback as a run with the smoother, no record of the updates and no
    transitions (only the smoother reads them); a run that destroys P still stops."""
    truth, imu, gnss, init = case
    models = [GnssPosition(gnss), GnssVelocity(gnss)]
    full = run_filter(imu, init, models, FilterConfig(imu_model="tactical"))
    fwd = run_filter(imu, init, models, FilterConfig(imu_model="tactical", smoother=False))
    pd.testing.assert_frame_equal(fwd.innovations, full.innovations)
    pd.testing.assert_frame_equal(fwd.forward, full.forward)
    assert np.array_equal(fwd.feedback, full.feedback) and np.abs(fwd.feedback).sum() > 0
    # nor the transitions (the smoother reads them alone): the same covariances without them
    assert fwd.Phi is None and full.Phi.shape == full.P_filtered.shape
    assert np.array_equal(fwd.P_filtered, full.P_filtered)
    assert np.array_equal(fwd.P_predicted, full.P_predicted)
    assert full.updates["s"].shape[0] == 6 * len(gnss)
    assert full.updates["H_ptr"].shape[0] == 6 * len(gnss) + 1
    # H kept by its non-zeros: the dense rows hold exactly the stored entries, none zero
    H = dense_rows(full.updates["H_ptr"], full.updates["H_col"], full.updates["H_val"], 0, 6,
                   full.layout.n)
    assert np.count_nonzero(H) == full.updates["H_ptr"][6] > 0
    assert np.all(full.updates["H_val"] != 0.0)
    assert fwd.updates["s"].shape[0] == 0 and fwd.smoothed is None and fwd.complete
    bad = run_filter(imu, init, [GnssPosition(gnss), _Bad([30.0])],
                     FilterConfig(imu_model="tactical", gate_probability=None, smoother=False))
    assert not bad.complete and "30.0" in str(bad.error)


def test_config_validation():
    with pytest.raises(ConfigError):
        FilterConfig(discretization="euler").validate()
    with pytest.raises(ConfigError):
        FilterConfig(bias_model="flicker").validate()
    with pytest.raises(ConfigError):
        FilterConfig(propagation_interval=0.0).validate()
    with pytest.raises(ConfigError):
        FilterConfig(gate_probability=1.5).validate()


def test_nonfinite_imu_stops_with_partial_result(case):
    truth, imu, gnss, init = case
    bad = imu.copy()
    bad.iloc[3000:3005, 0] = np.nan  # t = 60.0 .. 60.08 s
    res = run_filter(bad, init, [GnssPosition(gnss), GnssVelocity(gnss)], FilterConfig(imu_model="tactical"))
    assert not res.complete
    assert isinstance(res.error, FilterHealthError) and "60." in str(res.error)
    assert res.forward.index[-1] <= 60.0 and len(res.forward) > 2900
    assert np.isfinite(res.forward.to_numpy()).all()
    assert res.smoothed is not None and len(res.smoothed) == len(res.forward)
    good = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], FilterConfig(imu_model="tactical"))
    n = len(res.forward)
    assert np.allclose(res.forward.to_numpy(), good.forward.iloc[:n].to_numpy())


def test_non_positive_definite_covariance_stops(case):
    truth, imu, gnss, init = case
    res = run_filter(imu, init, [GnssPosition(gnss), _Bad([30.0])],
                     FilterConfig(imu_model="tactical", gate_probability=None))
    assert not res.complete and "30.0" in str(res.error)
    assert res.forward.index[-1] == pytest.approx(29.0)


def test_vanloan_and_second_order_agree(case):
    truth, imu, gnss, init = case
    ms = [GnssPosition(gnss), GnssVelocity(gnss)]
    a = run_filter(imu, init, ms, FilterConfig(imu_model="tactical", discretization="second_order"))
    b = run_filter(imu, init, ms, FilterConfig(imu_model="tactical", discretization="vanloan",
                                                propagation_interval=0.05))
    d = nav_errors(a.forward, b.forward)
    assert d[["east", "north", "up"]].abs().to_numpy().max() < 5e-3
    assert np.allclose(a.forward["east_std"], b.forward["east_std"], rtol=2e-3)


def test_scale_factor_states_estimated():
    truth = car_truth(300.0, 50.0)
    model = grade("mems")
    rng = np.random.default_rng(12)
    imu, errs = corrupt_imu(truth, model, rng, scale=True)
    gnss = gnss_from_truth(truth, rng, horizontal_std=0.3, vertical_std=0.6, velocity_std=0.02,
                           vertical_velocity_std=0.04)
    init = initial_with_error(truth, np.r_[0, 0, 0, 0, 0, 0, 0.002, -0.002, 0.01])
    cfg = FilterConfig(imu_model=model, scale_factors=True, initial_att_std=(0.01, 0.01, 0.03))
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    assert res.layout.n == 21
    est = res.forward["gyro_scale_z"].iloc[-1]
    std = res.forward["gyro_scale_z_std"].iloc[-1]
    true = errs["gyro_scale"][2]
    assert abs(est - true) < 3 * std and std < 0.3 * model.gyro_scale


def test_progress_bar_runs(case, capsys):
    truth, imu, gnss, init = case
    res = run_filter(imu.iloc[:500], init, [GnssPosition(gnss)], FilterConfig(smoother=False), progress=True)
    assert res.complete and len(res.forward) == 500


def test_rates_input_table(case):
    """A rate table (gyro/accel columns) is accepted like increments."""
    truth, _, _, init = case
    t, dth, dv = increments(inverse_mechanize(truth))
    dt = np.diff(t)
    w = np.vstack([dth[1:2] / dt[0], dth[1:] / dt[:, None]])
    f = np.vstack([dv[1:2] / dt[0], dv[1:] / dt[:, None]])
    rates = pd.DataFrame(np.column_stack([w, f]), index=pd.Index(t, name="time"),
                         columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    res = run_filter(rates, initial_with_error(truth, np.zeros(9)), [], FilterConfig(smoother=False))
    assert res.complete and len(res.forward) == len(truth)


def test_compiled_and_filterpy_kalman_backends_agree(case):
    """The engine through filterpy's predict/update (``kalman="filterpy"``, the reference)
    and through the compiled ones: the same gating decisions, innovations, forward and
    smoothed solution to rounding."""
    truth, imu, gnss, init = case
    ms = [GnssPosition(gnss), GnssVelocity(gnss)]
    a = run_filter(imu, init, ms, FilterConfig(imu_model="tactical"))
    b = run_filter(imu, init, ms, FilterConfig(imu_model="tactical", kalman="filterpy"))
    assert a.complete and b.complete
    assert (a.innovations["accepted"].to_numpy() == b.innovations["accepted"].to_numpy()).all()
    np.testing.assert_allclose(a.innovations["nis"], b.innovations["nis"], rtol=1e-8, atol=1e-10)
    for fa, fb in ((a.forward, b.forward), (a.smoothed, b.smoothed)):
        np.testing.assert_allclose(fa.to_numpy(), fb.to_numpy(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(a.P_filtered, b.P_filtered, rtol=1e-8, atol=1e-15)
    # the filter did work: the GNSS updates cut the position std far below the prior growth
    assert a.forward["east_std"].iloc[-1] < 1.0
