"""RISS benchmark: throughput of the mechanization kernel and of the RISS/GNSS filter, and the
full-size NEES Monte Carlo (50 runs of a 10-minute land-vehicle drive per grade).

The drive, the sensor-error synthesis and the NEES bookkeeping are those of the tests
(``tests/riss_helpers.py``): errors are drawn from the filter's own model (turn-on bias +
Gauss-Markov instability + white noise, odometer scale factor and white noise), GNSS position and
velocity at 1 Hz, the constant quantities drawn moment-matched. Prints, per grade, the average
NEES and the share of epochs inside the two-sided 95 % chi-square bounds, for the 11 reported
quantities and for the full error state.

    python bench/bench_riss.py [--runs 50] [--duration 600]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from riss_helpers import perfect_drive, riss_monte_carlo  # noqa: E402

from insgnss.filter import FilterConfig, GnssPosition, GnssVelocity  # noqa: E402
from insgnss.filter.riss_model import run_riss_filter  # noqa: E402
from insgnss.imu import grade  # noqa: E402
from insgnss.mechanization.riss import mechanize_riss, riss_inputs  # noqa: E402
from insgnss.stats import chi2_ppf  # noqa: E402


def throughput(duration: float) -> None:
    truth, imu, odo, init = perfect_drive(duration, 100.0)
    n = len(imu)
    mechanize_riss(imu.iloc[:1000], odo.iloc[:1000], init)  # compile
    t0 = time.perf_counter()
    inputs = riss_inputs(imu, odo, window=1.0)
    t1 = time.perf_counter()
    mechanize_riss(imu, odo, init, inputs=inputs)
    t2 = time.perf_counter()
    print(f"RISS inputs ({n} samples): {t1 - t0:.3f} s; mechanization: {t2 - t1:.3f} s "
          f"({n / (t2 - t1) / 1e6:.2f} M samples/s)")
    rng = np.random.default_rng(0)
    from riss_helpers import gnss_from_truth

    g = gnss_from_truth(truth, rng)
    meas = [GnssPosition(g), GnssVelocity(g)]
    cfg = FilterConfig(imu_model="tactical")
    run_riss_filter(imu.iloc[:2000], odo.iloc[:2000], init, meas, cfg)  # compile
    t0 = time.perf_counter()
    res = run_riss_filter(imu, odo, init, meas, cfg)
    t1 = time.perf_counter()
    tm = {k: round(v, 3) for k, v in res.timing.items()}
    print(f"RISS/GNSS filter + smoother, {duration:.0f} s at 100 Hz, 1 Hz GNSS pos+vel: "
          f"{t1 - t0:.2f} s ({n / (t1 - t0):.0f} IMU samples/s); split {tm}")


def nees_mc(grade_name: str, runs: int, duration: float) -> None:
    drive = perfect_drive(duration, 100.0)
    for reported in (True, False):
        t0 = time.perf_counter()
        ne, ep, res = riss_monte_carlo(runs, duration, grade(grade_name), seed=2026,
                                       config_kw={"bias_model": "gauss_markov"},
                                       riss_kw={"slip_std": 0.005}, reported=reported,
                                       drive=drive)
        n = 11 if reported else res.layout.n
        m = ne.mean(axis=0)[1:]
        lo = chi2_ppf(0.025, runs * n) / runs
        hi = chi2_ppf(0.975, runs * n) / runs
        inside = np.mean((m >= lo) & (m <= hi))
        what = "reported quantities" if reported else "full error state"
        print(f"{grade_name:8s} {what:19s} n={n:2d}: mean NEES {m.mean():6.2f}, bounds "
              f"[{lo:.2f}, {hi:.2f}], inside {100 * inside:5.1f} %, below "
              f"{100 * np.mean(m < lo):5.1f} %, above {100 * np.mean(m > hi):5.1f} % "
              f"({runs} runs x {duration:.0f} s, {time.perf_counter() - t0:.0f} s)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--skip-nees", action="store_true")
    args = ap.parse_args(argv)
    throughput(args.duration)
    if not args.skip_nees:
        for g in ("consumer", "tactical"):
            nees_mc(g, args.runs, args.duration)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
