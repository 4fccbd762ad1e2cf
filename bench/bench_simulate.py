"""Benchmark: simulate 1 h of 200 Hz IMU data (truth + errors), target < 5 s.

Run: ``python bench/bench_simulate.py`` (prints the timings; not a test).

Stages timed: trajectory generation (a town/highway drive with stops and turns, 720,001 samples),
inverse mechanization (ideal increments), IMU error synthesis (tactical grade, Gauss-Markov bias
instability; and with the flicker bias-instability bank), and GNSS synthesis at 1 Hz. The first
pass warms the numba caches and imports on a short run.
"""

from __future__ import annotations

import time

import numpy as np

from insgnss.imu import GRADES
from insgnss.mechanization.inverse import inverse_mechanize
from insgnss.mechanization.strapdown import NAV_COLS
from insgnss.simulate.aiding import simulate_gnss
from insgnss.simulate.sensors import simulate_imu
from insgnss.simulate.trajectory import generate

D = np.pi / 180.0
RATE = 200.0
DURATION = 3600.0


def segments(total: float) -> list[dict]:
    """A repeating urban/highway pattern covering ``total`` seconds."""
    block = [
        {"type": "static", "duration": 20.0},
        {"type": "accelerate", "speed": 25.0, "acceleration": 1.5},
        {"type": "hold", "duration": 120.0},
        {"type": "turn", "angle": 90 * D, "rate": 6 * D},
        {"type": "climb", "height_change": 15.0, "rate": 0.8},
        {"type": "hold", "duration": 60.0},
        {"type": "turn", "angle": -45 * D, "rate": 4 * D},
        {"type": "descend", "height_change": 15.0, "rate": 0.8},
        {"type": "decelerate", "speed": 0.0, "acceleration": 2.0},
    ]
    out = []
    while sum(s.get("duration", 30.0) for s in out) < total:
        out += [dict(s) for s in block]
    return out


def run(duration: float, rate: float, verbose: bool) -> float:
    t0 = time.perf_counter()
    tr = generate(rate=rate, lat=45 * D, lon=7 * D, height=200.0, heading=30 * D,
                  segments=segments(duration), duration=duration, roll_gain=0.5 * D)
    t1 = time.perf_counter()
    ideal = inverse_mechanize(tr.truth[NAV_COLS])
    t2 = time.perf_counter()
    simulate_imu(ideal, GRADES["tactical"], 1)
    t3 = time.perf_counter()
    simulate_imu(ideal, GRADES["tactical"], 1, bias_instability="flicker")
    t4 = time.perf_counter()
    simulate_gnss(tr.truth, 2, rate=1.0, velocity=True, lever_arm=(0.0, 1.0, 1.5))
    t5 = time.perf_counter()
    total = (t1 - t0) + (t2 - t1) + (t3 - t2)
    if verbose:
        n = len(tr.truth)
        print(f"samples                     {n} ({duration:.0f} s at {rate:g} Hz)")
        print(f"trajectory (truth)          {t1 - t0:7.3f} s")
        print(f"inverse mechanization       {t2 - t1:7.3f} s")
        print(f"IMU errors (Gauss-Markov)   {t3 - t2:7.3f} s")
        print(f"IMU errors (flicker bank)   {t4 - t3:7.3f} s")
        print(f"GNSS 1 Hz (pos + vel)       {t5 - t4:7.3f} s")
        print(f"TOTAL truth + errors        {total:7.3f} s  ({n / total / 1e3:.0f} k samples/s; "
              f"target < 5 s)")
    return total


if __name__ == "__main__":
    run(60.0, RATE, verbose=False)  # warm-up: imports, numba cache
    best = min(run(DURATION, RATE, verbose=(i == 0)) for i in range(3))
    print(f"best of 3: {best:.3f} s")
