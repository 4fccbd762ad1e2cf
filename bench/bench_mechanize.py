"""Benchmark: batch LLF strapdown mechanization throughput (IMU samples/s) and compile time.

Run: ``python bench/bench_mechanize.py [--samples N]``. Prints numbers; not a timed test.
The first call in a fresh process loads the numba cache (or compiles, when the cache is cold:
``--cold`` runs with an empty temporary ``NUMBA_CACHE_DIR`` and measures the compile time; the
package's own cache is left alone).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def _setup(n: int):
    from insgnss.imu import increments_table
    from insgnss.mechanization.strapdown import NavState

    rng = np.random.default_rng(0)
    rate = 200.0
    t = np.arange(n) / rate
    dth = rng.normal(0, 1e-4, (n, 3))
    dv = rng.normal(0, 1e-3, (n, 3)) + np.array([0, 0, 9.80665 / rate])
    return increments_table(t, dth, dv), NavState.from_euler(0.7, 0.1, 100.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=2_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--cold", action="store_true", help="measure compile time with an empty cache")
    args = ap.parse_args()
    if args.cold and not os.environ.get("INSGNSS_BENCH_COLD"):
        # numba reads NUMBA_CACHE_DIR at import: run this benchmark again in a child process
        # whose cache is an empty temporary folder
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, "INSGNSS_BENCH_COLD": "1"}
            sys.exit(subprocess.run([sys.executable, *sys.argv], env=env).returncode)
    t0 = time.perf_counter()
    from insgnss.mechanization.strapdown import mechanize

    imu_small, x0 = _setup(10)
    mechanize(imu_small, x0)
    first = time.perf_counter() - t0
    imu, x0 = _setup(args.samples)
    best = np.inf
    for _ in range(args.repeat):
        t1 = time.perf_counter()
        mechanize(imu, x0)
        best = min(best, time.perf_counter() - t1)
    from insgnss import aot

    what = "cache load" if not args.cold else "compile" if not aot.table() else "no compile"
    print(f"first call (import + {what}): {first:.2f} s (ahead-of-time kernels: "
          f"{aot.status()})")
    print(f"mechanize: {args.samples:,} samples in {best:.3f} s (best of {args.repeat}) "
          f"= {args.samples / best:,.0f} samples/s")
    if not args.cold:
        out = subprocess.run([sys.executable, __file__, "--cold", "--samples", "100000",
                              "--repeat", "1"], capture_output=True, text=True,
                             env={k: v for k, v in os.environ.items()
                                  if k != "INSGNSS_BENCH_COLD"})
        print("cold start:", out.stdout.splitlines()[0] if out.stdout else out.stderr[-500:])


if __name__ == "__main__":
    main()
