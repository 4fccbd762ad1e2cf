#!/usr/bin/env python3
"""Throughput of the stillness detector + ZUPT/ZARU filter on the PyShoe Vicon trials.

Loads every trial once (not timed), warms the compiled kernels up, then times, over all
trials and ``--repeat`` passes:

- ``detector``: gait-adaptive SHOE statistic, threshold and decisions (:func:`detect_arrays`);
- ``filter``: forward ZUPT + ZARU error-state filter (:func:`foot_filter_arrays`, no smoother);
- ``filter+smoother``: the same with the MBF backward pass (the preset);
- ``detector+filter+smoother``: both, the foot preset's whole navigation;
- ``run_foot_ins``: the public DataFrame API end to end (increments, tables, ENU output).

Prints IMU samples per second for each, from the wall-clock time and from the process CPU time
(the machine is shared: under load the wall-clock figure drops, the CPU figure much less).
PyShoe itself runs about 15,000 samples/s here.

Usage: ``python bench/bench_zupt.py [--data DIR] [--repeat N]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scenarios" / "pyshoe"))
import convert  # noqa: E402

from insgnss.detect import detect_arrays, imu_rates  # noqa: E402
from insgnss.foot import FootConfig, foot_filter_arrays, initial_state, run_foot_ins  # noqa: E402
from insgnss.imu import increments  # noqa: E402

DEFAULT_DATA = REPO.parent / "shared" / "data" / "pyshoe-vicon"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=DEFAULT_DATA)
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args(argv)
    cfg = FootConfig()
    fwd_cfg = FootConfig(smooth=False)
    lat, lon, h = convert.TORONTO
    trials = []
    for mat in sorted(a.data.glob("*.mat")):
        imu, _ = convert.to_insgnss(mat)
        t, gyro, acc = imu_rates(imu)
        _, dth, dv = increments(imu)
        trials.append((imu, t, gyro, acc, dth, dv))
    n = sum(tr[1].size for tr in trials)
    if not trials:
        print(f"no trials in {a.data}")
        return 1

    def detector(tr):
        _, t, gyro, acc, _, _ = tr
        return detect_arrays(t, gyro, acc, cfg.detector)

    pre = [detector(tr) for tr in trials]  # also warms up
    inits = [initial_state(tr[1], tr[2], tr[3], s[0], cfg, lat, lon, h)
             for tr, s in zip(trials, pre, strict=True)]

    def filt(c):
        def run(i):
            _, t, gyro, _, dth, dv = trials[i]
            still, stat, _ = pre[i]
            init, bg0 = inits[i]
            return foot_filter_arrays(t, dth, dv, gyro, still, stat, init, bg0, c)
        return run

    def full(i):
        _, t, gyro, acc, dth, dv = trials[i]
        still, stat, _ = detect_arrays(t, gyro, acc, cfg.detector)
        init, bg0 = initial_state(t, gyro, acc, still, cfg, lat, lon, h)
        return foot_filter_arrays(t, dth, dv, gyro, still, stat, init, bg0, cfg)

    def api(i):
        return run_foot_ins(trials[i][0], cfg, lat=lat, lon=lon, height=h)

    cases = {
        "detector": lambda i: detector(trials[i]),
        "filter (forward, ZUPT+ZARU)": filt(fwd_cfg),
        "filter+smoother": filt(cfg),
        "detector+filter+smoother": full,
        "run_foot_ins (DataFrame API)": api,
    }
    for fn in cases.values():  # warm-up / compile
        fn(0)
    print(f"{len(trials)} trials, {n} IMU samples ({n / 200.0:.0f} s at 200 Hz), "
          f"best of {a.repeat} passes")
    print(f"  {'':32s} {'wall':>9s} {'samples/s':>12s} {'CPU':>9s} {'samples/s':>12s}")
    for name, fn in cases.items():
        best, best_cpu = np.inf, np.inf
        for _ in range(a.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            for i in range(len(trials)):
                fn(i)
            best = min(best, time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
        print(f"  {name:32s} {best * 1e3:7.0f}ms {n / best:12,.0f} {best_cpu * 1e3:7.0f}ms "
              f"{n / best_cpu:12,.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
