"""Free-inertial LLF strapdown mechanization of an IMU CSV file.

Reads an IMU CSV with declared units and sensor-to-body mounting, aligns over a static window
(levelling + gyrocompassing, or a given heading) or takes a given initial attitude, runs the
strapdown mechanization and writes the trajectory CSV (insgnss native table: time [s], lat_deg,
lon_deg, height [m], vel_e/n/u [m/s], roll_deg, pitch_deg, heading_deg; with ``--frame wander``
also wander_angle_deg) and a figure. ``--frame wander`` mechanizes in the wander-azimuth frame,
which also works over the poles (docs/mechanization.md).

Example:
  insgnss mechanize imu.csv --lat 51.08 --lon -114.13 --height 1100 --align 120 \\
      --gyro-unit deg/s --accel-unit g --axis-map y,x,-z -o trajectory.csv --figure nav.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "mechanize"
HELP = "free-inertial strapdown mechanization of an IMU CSV"


def _triple(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected three comma-separated numbers, got {text!r}") from None
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"expected three comma-separated numbers, got {text!r}")
    return vals


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("imu", type=Path, help="IMU CSV (header: time, gyro_x..z, accel_x..z or "
                   "dtheta_x..z, dv_x..z; see docs/formats.md)")
    p.add_argument("-o", "--output", type=Path, required=True, help="trajectory CSV to write")
    p.add_argument("--figure", type=Path, help="figure to write (.png, .pdf, .svg)")
    g = p.add_argument_group("initial position")
    g.add_argument("--lat", type=float, required=True, help="latitude [deg]")
    g.add_argument("--lon", type=float, required=True, help="longitude [deg]")
    g.add_argument("--height", type=float, default=0.0, help="ellipsoidal height [m]")
    g = p.add_argument_group("input units and mounting")
    g.add_argument("--gyro-unit", default="rad/s", help="rad/s, deg/s, rad or deg (increments)")
    g.add_argument("--accel-unit", default="m/s^2", help="m/s^2, g or m/s (increments)")
    g.add_argument("--time-unit", default="s", help="s, ms, us or ns")
    g.add_argument("--time-offset", type=float, default=0.0, help="added to the time [s]")
    g.add_argument("--axis-map", help='sensor-to-body axis map, e.g. "y,x,-z" (FRD -> RFU)')
    g.add_argument("--mounting", type=_triple, metavar="R,P,Y",
                   help="sensor mounting Euler angles relative to the body [deg]")
    g.add_argument("--sensor-axes", choices=["rfu", "frd"], default="rfu",
                   help="axes of the (mapped) sensor triad")
    g = p.add_argument_group("initialization")
    g.add_argument("--align", type=float, metavar="SECONDS",
                   help="static coarse alignment over the first SECONDS")
    g.add_argument("--attitude", type=_triple, metavar="R,P,H",
                   help="given initial roll, pitch, heading [deg] (instead of --align)")
    g.add_argument("--heading", type=float, help="given heading [deg] with --align "
                   "(for IMUs that cannot gyrocompass)")
    g.add_argument("--grade", default=None,
                   help="IMU grade for the stillness test and accuracy: navigation, tactical, "
                   "consumer")
    g = p.add_argument_group("mechanization")
    # names checked in run() against insgnss.earth.GRAVITY_MODELS / mechanization.core.FRAMES
    # (kept out of the CLI start-up)
    g.add_argument("--gravity-model", default="somigliana",
                   help="normal gravity: somigliana, grs80_series, inverse_square, j2")
    g.add_argument("--frame", default="enu",
                   help="navigation frame: enu (local level) or wander (wander azimuth, "
                   "works over the poles)")
    g.add_argument("--wander-angle", type=float, default=0.0, metavar="DEG",
                   help="initial wander angle [deg] (--frame wander)")
    g.add_argument("--attitude-update", default="exact", choices=["exact", "first_order"])
    g.add_argument("--coning", action="store_true", help="two-sample coning/sculling")
    g.add_argument("--fix-height", action="store_true",
                   help="hold height (the free vertical channel is unstable)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ..align import coarse_align
    from ..earth import GRAVITY_MODELS
    from ..errors import ConfigError
    from ..imu import grade
    from ..io.imu_csv import read_imu_csv
    from ..io.native import write_table
    from ..mechanization.core import frame_id
    from ..mechanization.strapdown import NavState, mechanize
    from ..validate import ensure_not_input

    if args.gravity_model not in GRAVITY_MODELS:
        raise ConfigError("unknown gravity model", column="--gravity-model",
                          expected=sorted(GRAVITY_MODELS), found=args.gravity_model)
    frame_id(args.frame)  # ConfigError for an unknown frame
    ensure_not_input(args.output, [args.imu])
    if args.figure is not None:
        ensure_not_input(args.figure, [args.imu])
    if (args.align is None) == (args.attitude is None):
        raise ConfigError("give exactly one of --align SECONDS or --attitude R,P,H",
                          column="--align/--attitude")
    imu = read_imu_csv(args.imu, gyro_unit=args.gyro_unit, accel_unit=args.accel_unit,
                       time_unit=args.time_unit, time_offset=args.time_offset,
                       axis_map=args.axis_map, mounting_euler_deg=args.mounting,
                       sensor_axes=args.sensor_axes)
    lat, lon = np.radians(args.lat), np.radians(args.lon)
    t0 = float(imu.index[0])
    if args.align is not None:
        window = imu.loc[: t0 + args.align]
        model = grade(args.grade) if args.grade else None
        heading = None if args.heading is None else np.radians(args.heading)
        res = coarse_align(window, lat, args.height, model=model, heading=heading,
                           gravity_model=args.gravity_model)
        d = res.as_degrees()
        print(f"alignment over {args.align:g} s ({res.heading_source}): roll {d['roll']:.3f}, "
              f"pitch {d['pitch']:.3f}, heading {d['heading']:.3f} deg")
        x0 = NavState(lat, lon, args.height, np.zeros(3), res.C, res.time)
        imu = imu.loc[res.time:]
    else:
        r, p_, h = np.radians(args.attitude)
        x0 = NavState.from_euler(lat, lon, args.height, (0, 0, 0), r, p_, h, time=t0)
    x0.wander_angle = float(np.radians(args.wander_angle))
    traj = mechanize(imu, x0, gravity_model=args.gravity_model,
                     attitude_update=args.attitude_update, coning=args.coning,
                     fix_height=args.fix_height, frame=args.frame)
    write_table(traj, args.output)
    print(f"wrote {len(traj)} epochs to {args.output}")
    if args.figure is not None:
        from ..plots import navigation_figure, save_figure

        save_figure(navigation_figure(traj, f"free-inertial: {args.imu.name}"), args.figure)
        print(f"wrote {args.figure}")
    return 0
