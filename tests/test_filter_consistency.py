"""Statistical must-shows of issue 4 on simulation with fixed seeds: NEES/NIS consistency
(Monte Carlo), aided accuracy, heading convergence, chi-square gating of GNSS jumps.

The full 50-run, 10-minute, 100 Hz consistency check is ``bench/bench_filter.py --mc 50``; the
test runs 20 runs of 5 minutes at 50 Hz.
"""

from __future__ import annotations

import numpy as np
from filter_sim import (
    DEG,
    car_truth,
    corrupt_imu,
    error_vector_at,
    gnss_from_truth,
    initial_with_error,
    nav_errors,
    perturbed_initial,
)
from scipy.stats import chi2

from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity, run_filter
from insgnss.imu import grade

P0, V0, A0 = 1.0, 0.1, (0.005, 0.005, 0.02)


def test_monte_carlo_nees_nis_inside_chi2_bounds():
    runs = 20
    model = grade("tactical")
    truth = car_truth(300.0, 50.0)
    nees = {"pos": [], "vel": [], "att": []}
    nis = {"gnss_pos": [], "gnss_vel": []}
    for r in range(runs):
        rng = np.random.default_rng(1000 + r)
        imu, _ = corrupt_imu(truth, model, rng)
        gnss = gnss_from_truth(truth, rng)
        init, _ = perturbed_initial(truth, rng, P0, V0, A0)
        cfg = FilterConfig(imu_model=model, initial_pos_std=P0, initial_vel_std=V0, initial_att_std=A0,
                           smoother=False, gate_probability=None)
        res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
        ev = error_vector_at(res.epoch_times[1:], nav_errors(res.forward, truth))
        P = res.P_filtered[1:]
        for name, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6)), ("att", slice(6, 9))):
            e = ev[:, sl]
            nees[name].append(np.einsum("ki,ki->k", e, np.linalg.solve(P[:, sl, sl], e[..., None])[..., 0]))
        inn = res.innovations
        for k in nis:
            nis[k].append(inn.loc[inn["type"] == k, "nis"].to_numpy()[1:])
    lo, hi = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    for name, arr in list(nees.items()) + list(nis.items()):
        avg = np.mean(np.array(arr), axis=0)
        inside = np.mean((avg >= lo) & (avg <= hi))
        print(f"{name}: mean {avg.mean():.2f}, inside [{lo:.2f}, {hi:.2f}] for {100 * inside:.1f} %")
        assert inside >= 0.90, (name, inside, avg.mean())
        assert 2.5 < avg.mean() < 3.5, (name, avg.mean())


def test_horizontal_rms_below_gnss_sigma():
    model = grade("tactical")
    truth = car_truth(300.0, 50.0)
    rng = np.random.default_rng(7)
    imu, _ = corrupt_imu(truth, model, rng)
    sigma = 1.0
    gnss = gnss_from_truth(truth, rng, horizontal_std=sigma, vertical_std=2 * sigma)
    init, _ = perturbed_initial(truth, rng, P0, V0, A0)
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)],
                     FilterConfig(imu_model=model, initial_att_std=A0))
    err = nav_errors(res.forward, truth)
    rms = np.sqrt(np.mean(err["east"] ** 2 + err["north"] ** 2))
    errs = nav_errors(res.smoothed, truth)
    rms_s = np.sqrt(np.mean(errs["east"] ** 2 + errs["north"] ** 2))
    print(f"horizontal RMS forward {rms:.3f} m, smoothed {rms_s:.3f} m (GNSS sigma {sigma} m)")
    assert rms < sigma and rms_s < rms
    # and the raw GNSS itself is worse
    g = nav_errors(gnss.assign(roll=0.0, pitch=0.0, heading=0.0), truth)
    assert np.sqrt(np.mean(g["east"] ** 2 + g["north"] ** 2)) > 2 * rms


def test_heading_converges_from_10_deg_tactical():
    model = grade("tactical")
    truth = car_truth(120.0, 50.0)
    rng = np.random.default_rng(17)
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng)
    init = initial_with_error(truth, np.r_[0.5, -0.5, 1.0, 0.05, -0.05, 0.02, 0.003, -0.003, 10 * DEG])
    cfg = FilterConfig(imu_model=model, initial_att_std=(0.005, 0.005, 12 * DEG))
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    err = nav_errors(res.forward, truth)
    h = np.abs(err["heading"].to_numpy()) / DEG
    t = err.index.to_numpy()
    assert h[0] > 9.9
    print(f"heading error < 0.2 deg from t = {t[np.nonzero(h >= 0.2)[0][-1] + 1]:.2f} s; "
          f"max after 60 s {h[t >= 60.0].max():.3f} deg")
    assert h[t >= 60.0].max() < 0.2
    # and consistently with the filter's own uncertainty
    assert np.all(h[t >= 60.0] < 3 * res.forward["heading_std"].to_numpy()[t >= 60.0] / DEG)


def test_gating_rejects_gnss_jumps():
    model = grade("tactical")
    truth = car_truth(300.0, 50.0)
    rng = np.random.default_rng(23)
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng)
    init, _ = perturbed_initial(truth, rng, P0, V0, A0)
    cfg = FilterConfig(imu_model=model, initial_att_std=A0)
    clean = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    bad = gnss.copy()
    n = len(bad)
    idx = rng.choice(np.arange(10, n), size=int(round(0.05 * n)), replace=False)
    mag = rng.uniform(30.0, 100.0, idx.size)
    az = rng.uniform(0, 2 * np.pi, idx.size)
    M = 6.37e6
    bad.iloc[idx, bad.columns.get_loc("lat")] += mag * np.cos(az) / M
    bad.iloc[idx, bad.columns.get_loc("lon")] += mag * np.sin(az) / (M * np.cos(bad["lat"].iloc[idx]))
    res = run_filter(imu, init, [GnssPosition(bad), GnssVelocity(bad)], cfg)
    rej = res.rejected
    assert set(np.round(rej.loc[rej["type"] == "gnss_pos", "time"], 6)) >= set(np.round(bad.index[idx], 6))
    assert len(rej) <= idx.size + 2  # (almost) nothing clean rejected
    assert (rej["nis"] > rej["threshold"]).all()
    e0 = nav_errors(clean.forward, truth)
    e1 = nav_errors(res.forward, truth)
    r0 = np.sqrt(np.mean(e0["east"] ** 2 + e0["north"] ** 2))
    r1 = np.sqrt(np.mean(e1["east"] ** 2 + e1["north"] ** 2))
    print(f"{idx.size} jumps, {len(rej)} rejected; RMS clean {r0:.3f} m, with jumps {r1:.3f} m")
    assert abs(r1 - r0) <= 0.1 * r0, (r0, r1)
    # without gating the jumps wreck the solution
    free = run_filter(imu, init, [GnssPosition(bad), GnssVelocity(bad)],
                      FilterConfig(imu_model=model, initial_att_std=A0, gate_probability=None))
    e2 = nav_errors(free.forward, truth)
    assert np.sqrt(np.mean(e2["east"] ** 2 + e2["north"] ** 2)) > 3 * r0
