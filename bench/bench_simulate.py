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


class Clock:
    """Wall-clock and process CPU time of consecutive stages (CPU time is what this process
    used: on a shared, loaded machine it is the fairer number)."""

    def __init__(self):
        self.marks = [(time.perf_counter(), time.process_time())]

    def lap(self) -> tuple[float, float]:
        self.marks.append((time.perf_counter(), time.process_time()))
        (w0, c0), (w1, c1) = self.marks[-2], self.marks[-1]
        return w1 - w0, c1 - c0


def run(duration: float, rate: float, verbose: bool) -> tuple[float, float]:
    clk = Clock()
    tr = generate(rate=rate, lat=45 * D, lon=7 * D, height=200.0, heading=30 * D,
                  segments=segments(duration), duration=duration, roll_gain=0.5 * D)
    s_traj = clk.lap()
    ideal = inverse_mechanize(tr.truth[NAV_COLS])
    s_inv = clk.lap()
    simulate_imu(ideal, GRADES["tactical"], 1)
    s_err = clk.lap()
    simulate_imu(ideal, GRADES["tactical"], 1, bias_instability="flicker")
    s_flk = clk.lap()
    simulate_gnss(tr.truth, 2, rate=1.0, velocity=True, lever_arm=(0.0, 1.0, 1.5))
    s_gnss = clk.lap()
    wall = s_traj[0] + s_inv[0] + s_err[0]
    cpu = s_traj[1] + s_inv[1] + s_err[1]
    if verbose:
        n = len(tr.truth)
        print(f"samples                     {n} ({duration:.0f} s at {rate:g} Hz)")
        print(f"{'stage':27s} {'wall [s]':>9s} {'cpu [s]':>9s}")
        for name, (w, c) in [("trajectory (truth)", s_traj), ("inverse mechanization", s_inv),
                             ("IMU errors (Gauss-Markov)", s_err),
                             ("IMU errors (flicker bank)", s_flk), ("GNSS 1 Hz (pos + vel)", s_gnss)]:
            print(f"{name:27s} {w:9.3f} {c:9.3f}")
        print(f"{'TOTAL truth + errors':27s} {wall:9.3f} {cpu:9.3f}   (target < 5 s; "
              f"{n / wall / 1e3:.0f} k samples/s wall)")
    return wall, cpu


if __name__ == "__main__":
    run(60.0, RATE, verbose=False)  # warm-up: imports, numba cache
    runs = [run(DURATION, RATE, verbose=(i == 0)) for i in range(3)]
    print(f"best of 3: wall {min(r[0] for r in runs):.3f} s, cpu {min(r[1] for r in runs):.3f} s")
