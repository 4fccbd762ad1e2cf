"""Benchmark: integration accuracy and order of the strapdown step against an analytic flight.

A 20-minute coordinated flight (200-240 m/s, ten turns with 15-35 deg peak bank, +-4 m/s climbs,
start 45 deg N, 1000 m) is defined in closed form with exact IMU increments
(:class:`insgnss.simulate.analytic.CoordinatedFlight`: kinematic ODE at rtol 1e-13, Gauss-Legendre
quadrature of the continuous sensor outputs; nothing shared with the discrete step). The free-
inertial mechanization starts from the exact state and its end-position error is printed for
IMU rates 50..800 Hz, with and without two-sample coning/sculling, with the observed order
``log2(e(dt) / e(dt/2))`` (2 for a second-order step).

Run: ``python bench/bench_integration_order.py [--duration 1200] [--rates 50,100,200,400,800]``.
Prints numbers; not a timed test.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def end_error(out, state) -> np.ndarray:
    """ENU end-position error [m] of a mechanization table against the exact final state."""
    from insgnss.earth import radii

    e = out.iloc[-1]
    lat, lon, h = state["lat"][-1], state["lon"][-1], state["h"][-1]
    M, N = radii(lat)
    return np.array([(e.lon - lon) * (N + h) * np.cos(lat), (e.lat - lat) * (M + h), e.height - h])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--duration", type=float, default=1200.0, help="flight duration [s]")
    ap.add_argument("--rates", default="50,100,200,400,800", help="IMU rates [Hz]")
    args = ap.parse_args()
    from insgnss.mechanization.strapdown import NavState, mechanize
    from insgnss.simulate.analytic import CoordinatedFlight

    t0 = time.perf_counter()
    flight = CoordinatedFlight(duration=args.duration)
    s = flight.state(np.array([0.0, flight.duration]))
    x0 = NavState.from_euler(s["lat"][0], s["lon"][0], s["h"][0], s["vel"][0], s["roll"][0],
                             s["pitch"][0], s["heading"][0])
    bank = np.degrees(np.abs(flight.state(flight.times(10.0))["roll"]).max())
    print(f"analytic flight: {flight.duration:.0f} s, max bank {bank:.1f} deg, "
          f"{len(flight.turns)} turns (reference built in {time.perf_counter() - t0:.1f} s)")
    rates = [float(r) for r in args.rates.split(",")]
    print(f"{'rate [Hz]':>9} {'coning':>6} {'east':>9} {'north':>9} {'up':>9} "
          f"{'|err| [m]':>10} {'order':>6}")
    for coning in (True, False):
        prev = None
        for rate in rates:
            imu = flight.increments(rate)
            err = end_error(mechanize(imu, x0, coning=coning), s)
            n = np.linalg.norm(err)
            order = "" if prev is None else f"{np.log2(prev / n):6.2f}"
            print(f"{rate:9.0f} {'yes' if coning else 'no':>6} {err[0]:9.5f} {err[1]:9.5f} "
                  f"{err[2]:9.5f} {n:10.5f} {order:>6}")
            prev = n


if __name__ == "__main__":
    main()
