"""Simulate a scenario file: truth, IMU (with errors), GNSS, odometer, magnetometer.

Writes ``truth.csv imu.csv imu_bias.csv gnss.csv odometer.csv magnetometer.csv`` (those the
scenario configures; native insgnss CSV tables, angles in degrees) and ``metadata.json`` (units,
frames, seed, configuration and the IMU/odometer error parameters actually drawn) into the output
folder. The run is reproducible from the seed (``[scenario] seed`` or ``--seed``).

Example::

    insgnss simulate scenarios/car_town_mems.toml -o out/car_town
"""

from __future__ import annotations

import argparse
import time

from ._outputs import add_wait_argument, output_folder

NAME = "simulate"
HELP = "simulate a scenario TOML file (truth, IMU, GNSS, odometer, magnetometer)"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    parser.add_argument("-o", "--output", metavar="DIR", required=True,
                        help="output folder (created if missing)")
    parser.add_argument("--seed", type=int, default=None,
                        help="random seed (overrides [scenario] seed)")
    parser.add_argument("--duration", type=float, default=None,
                        help="duration [s] (overrides [scenario] duration; truncates or extends)")
    add_wait_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..simulate.scenario import simulate_scenario

    with output_folder(args, args.output, protect=[args.scenario]):
        t0 = time.perf_counter()
        result = simulate_scenario(args.scenario, seed=args.seed, duration=args.duration)
        t1 = time.perf_counter()
        paths = result.write(args.output)
        t2 = time.perf_counter()
    meta = result.metadata
    tm = meta["time"]
    print(f"scenario {meta['scenario']['name']}: seed {meta['seed']}, "
          f"{tm['samples']} IMU samples at {tm['imu_rate']:g} Hz over {tm['end'] - tm['start']:.1f} s, "
          f"IMU {meta['imu']['grade']}")
    for name, path in paths.items():
        rows = len(result.tables()[name]) if name in result.tables() else None
        print(f"  {path}" + (f"  ({rows} rows)" if rows is not None else ""))
    print(f"simulated in {t1 - t0:.2f} s, written in {t2 - t1:.2f} s")
    return 0
