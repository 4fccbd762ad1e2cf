"""Allan deviation of a static IMU log with ARW/VRW, bias instability and rate random walk.

Reads an IMU file - by default a native insgnss IMU table (increments ``dtheta_* dv_*`` or
rates ``gyro_* accel_*``), or any format, columns, units and mounting a job's ``[inputs.imu]``
describes (the same options as ``insgnss mechanize``, or ``--job JOB.toml``) -, computes the
overlapping Allan deviation of the six axes (rate tables from the rates as sampled, increment
tables from the increments), prints the noise coefficients in datasheet units
(quantisation Q where the curve shows the -1 slope, ARW/VRW, bias instability, RRW) and writes
``<stem>_allan.png`` (curves with the fitted -1, -1/2, 0 and +1/2 reference slopes),
``<stem>_allan.csv`` (the deviation per tau, SI) and ``<stem>_allan_coefficients.csv``.

Examples::

    insgnss allan out/static/imu.csv -o out/static --start 0 --stop 3600
    insgnss allan static_log.csv --format csv --gyro-unit deg/s --accel-unit g --time-unit ms
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "allan"
HELP = "Allan deviation of a static IMU log: ARW/VRW, bias instability, RRW and a figure"


def register(parser: argparse.ArgumentParser) -> None:
    from ._imu_input import add_imu_arguments

    add_imu_arguments(parser, imu_help="IMU file (default format: native insgnss table); "
                      "optional with --job")
    parser.add_argument("-o", "--output", metavar="DIR", default=None,
                        help="output folder (default: the folder of IMU_FILE)")
    parser.add_argument("--start", type=float, default=None, help="first time to use [s]")
    parser.add_argument("--stop", type=float, default=None, help="last time to use [s]")
    parser.add_argument("--points-per-decade", type=int, default=10,
                        help="tau values per decade (default 10)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..analysis.allan import allan_analysis, coefficients_table, plot_allan
    from ..errors import InvalidValueError
    from ..io.native import atomic_write
    from ._imu_input import read_imu_input

    imu, src = read_imu_input(args, default_format="native")  # columns checked there
    if args.start is not None:
        imu = imu[imu.index >= args.start]
    if args.stop is not None:
        imu = imu[imu.index <= args.stop]
    try:
        result = allan_analysis(imu, points_per_decade=args.points_per_decade)
    except ValueError as exc:
        raise InvalidValueError(str(exc), file=src) from None
    out = Path(args.output) if args.output else src.parent
    out.mkdir(parents=True, exist_ok=True)
    stem = src.stem
    table = coefficients_table(result)
    fig = plot_allan(result, title=f"{src.name}: {result.duration / 3600:.2f} h at "
                                   f"{result.rate:g} Hz")
    png = atomic_write(out / f"{stem}_allan.png", lambda p: fig.savefig(p, format="png", dpi=120))
    adev_csv = atomic_write(out / f"{stem}_allan.csv",
                            lambda p: result.adev.to_csv(p, float_format="%.9g"))
    coef_csv = atomic_write(out / f"{stem}_allan_coefficients.csv",
                            lambda p: table.to_csv(p, float_format="%.6g"))
    print(f"{src}: {result.duration:.1f} s at {result.rate:g} Hz")
    print(f"{'axis':8s} {'quantisation Q (as LSB)':>32s} {'ARW/VRW':>22s} {'bias instab.':>18s} "
          f"{'(min/0.664)':>12s} {'tau_min [s]':>11s} {'RRW':>24s}")
    for ax, r in table.iterrows():
        print(f"{ax:8s} {r['quantization']:9.3g} {r['quantization_unit']:>6s} "
              f"({r['quantization_lsb']:8.3g} {r['quantization_lsb_unit']:>5s}) "
              f"{r['arw_vrw']:10.4g} {r['arw_vrw_unit']:>11s} "
              f"{r['bias_instability']:10.4g} {r['bias_instability_unit']:>7s} "
              f"{r['bias_instability_min']:12.4g} {r['tau_min']:11.4g} "
              f"{r['rrw']:10.4g} {r['rrw_unit']:>13s}")
    for p in (png, adev_csv, coef_csv):
        print(f"  {p}")
    return 0
