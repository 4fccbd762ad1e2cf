"""The wander-azimuth filter over the pole: accuracy, consistency, speed.

    python bench/bench_wander_filter.py            # one polar run, wander and ENU filters
    python bench/bench_wander_filter.py --mc 20    # + 20-seed position NEES of the wander filter

Polar route: :func:`filter_sim.polar_flight` (250 m/s, 1 km, 89.5 N lon 0 -> pole -> lon 180,
450 s, 100 Hz, tactical IMU, GNSS positions 1 Hz 1 m / 2 m). Prints the position errors
(forward, smoothed; ENU at the true point, from ECEF differences), the attitude errors after
60 s (misalignment in ECEF, shown in ENU axes), the mean NIS per dof, and the same for the ENU
filter on the same data. With ``--mc`` also the mean position NEES (3 dof) over the seeds,
averaged over time, and the share of epochs whose seed-mean NEES lies inside the 95 %
chi-square band. Then the throughput of both models on a 600 s car run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from filter_sim import (  # noqa: E402
    car_truth,
    corrupt_imu,
    gnss_from_truth,
    perturbed_initial,
    polar_flight,
)

from insgnss.attitude import attitude_error, euler_to_dcm  # noqa: E402
from insgnss.earth import enu_to_ecef_dcm, geodetic_to_ecef  # noqa: E402
from insgnss.filter import (  # noqa: E402
    FilterConfig,
    GnssPosition,
    GnssVelocity,
    run_filter,
    run_wander_filter,
)
from insgnss.imu import grade  # noqa: E402
from insgnss.stats import chi2_ppf  # noqa: E402


def _ecef(df):
    return np.column_stack(geodetic_to_ecef(df["lat"].to_numpy(), df["lon"].to_numpy(),
                                            df["height"].to_numpy()))


def errors(est, truth):
    """ENU position error (N, 3) at the true point, misalignment (N, 3) in ENU axes."""
    tr = truth.loc[est.index]
    Cl = enu_to_ecef_dcm(tr["lat"].to_numpy(), tr["lon"].to_numpy())
    de = np.einsum("kji,kj->ki", Cl, _ecef(est) - _ecef(tr))
    Ce = enu_to_ecef_dcm(est["lat"].to_numpy(), est["lon"].to_numpy()) @ euler_to_dcm(
        est["roll"].to_numpy(), est["pitch"].to_numpy(), est["heading"].to_numpy())
    Ct = Cl @ euler_to_dcm(tr["roll"].to_numpy(), tr["pitch"].to_numpy(),
                           tr["heading"].to_numpy())
    return de, np.einsum("kji,kj->ki", Cl, attitude_error(Ce, Ct))


def report(name, res, truth):
    print(f"{name}: complete={res.complete}")
    for kind in ("forward", "smoothed"):
        est = getattr(res, kind)
        de, phi = errors(est, truth)
        late = est.index.to_numpy() > 60.0
        n3 = np.linalg.norm(de, axis=1)
        print(f"  {kind:8s} pos max {n3.max():8.2f} m  rms hor {np.sqrt((de[:, :2] ** 2).sum(1).mean()):6.2f}"
              f"  up {np.sqrt((de[:, 2] ** 2).mean()):6.2f}  att max after 60 s [deg] "
              f"{np.array2string(np.degrees(np.abs(phi[late]).max(0)), precision=3)}")
    inn = res.innovations
    print(f"  NIS/dof {inn['nis'].mean() / 3:.2f}, rejected {int((~inn['accepted']).sum())}")


def monte_carlo(n):
    """Mean position NEES (forward filter, 3 dof) over ``n`` seeds at the GNSS epochs."""
    nees = []
    for seed in range(n):
        truth, imu, gnss, x0, cfg = polar_flight(np.random.default_rng(100 + seed))
        res = run_wander_filter(imu, x0, [GnssPosition(gnss)], cfg)
        est = res.forward.iloc[::100]
        de, _ = errors(est, truth)
        # the position block of P(e|e) rotated into ENU at the nominal of each node
        t = res.epoch_times
        k = np.searchsorted(t, est.index.to_numpy())
        k = np.minimum(k, len(t) - 1)
        Cel = np.swapaxes(enu_to_ecef_dcm(est["lat"].to_numpy(), est["lon"].to_numpy()), 1, 2)
        P = Cel @ res.P_filtered[k, 0:3, 0:3] @ np.swapaxes(Cel, 1, 2)
        nees.append(np.einsum("ki,kij,kj->k", de, np.linalg.inv(P), de))
    m = np.mean(nees, axis=0)
    lo, hi = chi2_ppf(0.025, 3 * n) / n, chi2_ppf(0.975, 3 * n) / n
    print(f"Monte Carlo ({n} seeds): mean position NEES {m.mean():.2f} (3 dof); "
          f"{np.mean((m > lo) & (m < hi)) * 100:.0f} % of epochs inside [{lo:.2f}, {hi:.2f}]")


def throughput():
    rng = np.random.default_rng(1)
    truth = car_truth(600.0, rate=100.0)
    imu, _ = corrupt_imu(truth, grade("tactical"), rng)
    gnss = gnss_from_truth(truth, rng)
    x0, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    cfg = FilterConfig(imu_model="tactical", initial_att_std=(0.005, 0.005, 0.02))
    ms = [GnssPosition(gnss), GnssVelocity(gnss)]
    for name, run in (("LLF", run_filter), ("wander", run_wander_filter)):
        run(imu, x0, ms, cfg)  # compile
        best = min(run(imu, x0, ms, cfg).timing["total"] for _ in range(3))
        print(f"{name:7s} car 600 s at 100 Hz, forward + smoother: {best:.2f} s, "
              f"{len(imu) / best:,.0f} IMU samples/s")


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--mc", type=int, default=0, help="Monte Carlo seeds (0: none)")
    a = ap.parse_args()
    truth, imu, gnss, x0, cfg = polar_flight(np.random.default_rng(7))
    c0 = time.perf_counter()
    res = run_wander_filter(imu, x0, [GnssPosition(gnss)], cfg)
    print(f"polar route, {len(imu)} IMU samples; first wander run {time.perf_counter() - c0:.1f} s")
    report("wander filter", res, truth)
    report("ENU filter", run_filter(imu, x0, [GnssPosition(gnss)], cfg), truth)
    if a.mc:
        monte_carlo(a.mc)
    throughput()


if __name__ == "__main__":
    main()
