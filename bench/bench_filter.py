"""Benchmark of the error-state filter + RTS smoother and its full Monte Carlo check.

    python bench/bench_filter.py                 # 1 h, 200 Hz IMU + 1 Hz GNSS pos/vel
    python bench/bench_filter.py --hours 0.25    # shorter
    python bench/bench_filter.py --mc 50         # 50-run NEES/NIS consistency (10 min car)

Prints the cold first-run time (fresh numba cache in a child process, compilation included),
the warm wall time of forward filter + smoother, IMU samples/s and the split
(mechanization / covariance / updates / smoother / output). Data generation is not timed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from filter_sim import (  # noqa: E402
    car_truth,
    corrupt_imu,
    gnss_from_truth,
    nav_errors,
    perturbed_initial,
)

from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity, run_filter  # noqa: E402
from insgnss.imu import grade  # noqa: E402
from insgnss.stats import chi2_ppf  # noqa: E402


def make_case(hours: float, rate: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    truth = car_truth(3600.0 * hours, rate)
    model = grade("tactical")
    imu, _ = corrupt_imu(truth, model, rng)
    gnss = gnss_from_truth(truth, rng)
    init, _ = perturbed_initial(truth, rng, 1.0, 0.1, (0.005, 0.005, 0.02))
    cfg = FilterConfig(imu_model=model, initial_pos_std=1.0, initial_vel_std=0.1,
                       initial_att_std=(0.005, 0.005, 0.02))
    return truth, imu, gnss, init, cfg


def run_once(imu, gnss, init, cfg, cpu=False):
    t0 = time.perf_counter()
    c0 = time.process_time()
    res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
    if cpu:
        return time.perf_counter() - t0, time.process_time() - c0, res
    return time.perf_counter() - t0, res


def child(hours, rate):
    truth, imu, gnss, init, cfg = make_case(hours, rate)
    wall, res = run_once(imu, gnss, init, cfg)
    print(json.dumps({"wall": wall, "timing": res.timing}))


def mc(runs: int, duration: float, rate: float):
    """NEES (pos, vel, att) and NIS averaged over runs vs two-sided 95 % chi-square bounds."""
    from filter_sim import error_vector_at

    model = grade("tactical")
    truth = car_truth(duration, rate)
    nees = {"pos": [], "vel": [], "att": []}
    nis = {"gnss_pos": [], "gnss_vel": []}
    t_start = time.perf_counter()
    for r in range(runs):
        rng = np.random.default_rng(1000 + r)
        imu, _ = corrupt_imu(truth, model, rng)
        gnss = gnss_from_truth(truth, rng)
        p0, v0, a0 = 1.0, 0.1, (0.005, 0.005, 0.02)
        init, _ = perturbed_initial(truth, rng, p0, v0, a0)
        cfg = FilterConfig(imu_model=model, initial_pos_std=p0, initial_vel_std=v0,
                           initial_att_std=a0, smoother=False, gate_probability=None)
        res = run_filter(imu, init, [GnssPosition(gnss), GnssVelocity(gnss)], cfg)
        err = nav_errors(res.forward, truth)
        te = res.epoch_times[1:]
        ev = error_vector_at(te, err)
        P = res.P_filtered[1:]
        for name, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6)), ("att", slice(6, 9))):
            e = ev[:, sl]
            nees[name].append(np.einsum("ki,ki->k", e, np.linalg.solve(P[:, sl, sl], e[..., None])[..., 0]))
        inn = res.innovations
        for k in nis:
            nis[k].append(inn.loc[inn["type"] == k, "nis"].to_numpy())
    elapsed = time.perf_counter() - t_start
    print(f"Monte Carlo: {runs} runs of {duration:.0f} s at {rate:.0f} Hz, tactical IMU, 1 Hz GNSS "
          f"pos+vel ({elapsed:.1f} s)")
    for name, arr in list(nees.items()) + list(nis.items()):
        a = np.mean(np.array(arr), axis=0)
        lo, hi = chi2_ppf([0.025, 0.975], 3 * runs) / runs
        inside = np.mean((a >= lo) & (a <= hi))
        kind = "NEES" if name in nees else "NIS "
        print(f"  {kind} {name:9s}: mean {a.mean():5.2f} (dof 3), bounds [{lo:.2f}, {hi:.2f}], "
              f"inside {100 * inside:5.1f} % of {a.size} epochs")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--no-cold", action="store_true", help="skip the cold-cache child run")
    ap.add_argument("--mc", type=int, default=0, help="run the Monte Carlo check with this many runs")
    ap.add_argument("--mc-duration", type=float, default=600.0)
    ap.add_argument("--mc-rate", type=float, default=100.0)
    a = ap.parse_args(argv)
    if a.child:
        child(a.hours, a.rate)
        return 0
    if a.mc:
        mc(a.mc, a.mc_duration, a.mc_rate)
        return 0
    cold = None
    if not a.no_cold:
        with tempfile.TemporaryDirectory() as d:
            env = dict(os.environ, NUMBA_CACHE_DIR=d)
            out = subprocess.run([sys.executable, __file__, "--child", "--hours", str(a.hours),
                                  "--rate", str(a.rate)], env=env, capture_output=True, text=True,
                                 check=True)
            cold = json.loads(out.stdout.strip().splitlines()[-1])
    t0 = time.perf_counter()
    truth, imu, gnss, init, cfg = make_case(a.hours, a.rate)
    t_data = time.perf_counter() - t0
    run_once(imu, gnss, init, cfg)  # loads the on-disk cache / compiles
    walls, cpus = [], []
    res = None
    for _ in range(3):
        w, c, res = run_once(imu, gnss, init, cfg, cpu=True)
        walls.append(w)
        cpus.append(c)
    wall = min(walls)
    n = len(imu)
    tm = res.timing
    print(f"insgnss filter benchmark: {a.hours:g} h, {a.rate:g} Hz IMU ({n:,} samples), 1 Hz GNSS "
          f"position + velocity, forward filter + smoother (data generation {t_data:.1f} s)")
    if cold is not None:
        print(f"  cold first run (empty numba cache, compile included): {cold['wall']:.2f} s")
    print(f"  warm total wall time: {wall:.2f} s  (runs: {', '.join(f'{w:.2f}' for w in walls)}; "
          f"process CPU time {min(cpus):.2f} s; load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores)")
    print(f"  IMU samples/s: {n / wall:,.0f}")
    print("  split [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in tm.items()))
    err = nav_errors(res.forward, truth)
    errs = nav_errors(res.smoothed, truth)
    h = np.hypot(err["east"], err["north"])
    hs = np.hypot(errs["east"], errs["north"])
    print(f"  horizontal RMS forward {np.sqrt(np.mean(h**2)):.3f} m, smoothed {np.sqrt(np.mean(hs**2)):.3f} m"
          f" (GNSS sigma 1 m); epochs {res.epoch_times.size}, rejected {len(res.rejected)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
