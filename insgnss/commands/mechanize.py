"""Free-inertial LLF strapdown mechanization of an IMU file.

Reads an IMU file with the declared format, columns, units and sensor-to-body mounting (the
keys of a job's ``[inputs.imu]`` as options, or ``--job JOB.toml`` to reuse that table), aligns
over a static window (levelling + gyrocompassing, or a given heading) or takes a given initial
attitude (and velocity), runs the strapdown mechanization and writes the trajectory CSV
(insgnss native table: time [s], lat_deg, lon_deg, height [m], vel_e/n/u [m/s], roll_deg,
pitch_deg, heading_deg; with ``--frame wander`` also wander_angle_deg) and a figure. With
``--reference FILE`` (native CSV, KF-GINS .nav or RTKLIB .pos) it also writes the errors
against it at the reference epochs (``--errors``, default ``<output>_errors.csv``: east, north,
up, horizontal [m], vel_e/n/u [m/s], roll/pitch/heading [deg]). ``--frame wander`` mechanizes
in the wander-azimuth frame, which also works over the poles (docs/mechanization.md).

Examples:
  insgnss mechanize imu.csv --lat 51.08 --lon -114.13 --height 1100 --align 120 \\
      --gyro-unit deg/s --accel-unit g --axis-map y,x,-z -o trajectory.csv --figure nav.png
  insgnss mechanize --job drive.toml --lat 40.0966 --lon -105.1474 --height 1601 \\
      --attitude 0.5,-1.2,87 --velocity 8.1,0.4,0 --reference truth.nav -o free.csv
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ._imu_input import add_imu_arguments, read_imu_input, triple

NAME = "mechanize"
HELP = "free-inertial strapdown mechanization of an IMU file"


def register(p: argparse.ArgumentParser) -> None:
    add_imu_arguments(p, imu_help="IMU file (csv default header: time, gyro_x..z, accel_x..z "
                      "or dtheta_x..z, dv_x..z; see docs/formats.md); optional with --job")
    p.add_argument("-o", "--output", type=Path, required=True, help="trajectory CSV to write")
    p.add_argument("--figure", type=Path, help="figure to write (.png, .pdf, .svg)")
    p.add_argument("--reference", type=Path, metavar="FILE",
                   help="reference trajectory (native CSV, KF-GINS .nav, RTKLIB .pos): write "
                   "the errors against it")
    p.add_argument("--errors", type=Path, metavar="CSV",
                   help="errors file (default: <output stem>_errors.csv; with --reference)")
    g = p.add_argument_group("initial position")
    g.add_argument("--lat", type=float, required=True, help="latitude [deg]")
    g.add_argument("--lon", type=float, required=True, help="longitude [deg]")
    g.add_argument("--height", type=float, default=0.0, help="ellipsoidal height [m]")
    g = p.add_argument_group("initialization")
    g.add_argument("--align", type=float, metavar="SECONDS",
                   help="static coarse alignment over the first SECONDS")
    g.add_argument("--attitude", type=triple, metavar="R,P,H",
                   help="given initial roll, pitch, heading [deg] (instead of --align; write "
                   "--attitude=-1.5,2,90 when the first value is negative)")
    g.add_argument("--velocity", type=triple, metavar="VE,VN,VU",
                   help="given initial velocity, east, north, up [m/s] (with --attitude; "
                   "default at rest)")
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
    from ..checks import check_gyro_at_rest, check_upright
    from ..earth import GRAVITY_MODELS
    from ..errors import ConfigError
    from ..imu import grade
    from ..io.native import write_table
    from ..mechanization.core import frame_id
    from ..mechanization.strapdown import NavState, mechanize
    from ..validate import ensure_not_input, time_slice

    if args.gravity_model not in GRAVITY_MODELS:
        raise ConfigError("unknown gravity model", column="--gravity-model",
                          expected=sorted(GRAVITY_MODELS), found=args.gravity_model)
    frame_id(args.frame)  # ConfigError for an unknown frame
    if (args.align is None) == (args.attitude is None):
        raise ConfigError("give exactly one of --align SECONDS or --attitude R,P,H",
                          column="--align/--attitude")
    if args.velocity is not None and args.attitude is None:
        raise ConfigError("--velocity goes with --attitude (a static alignment starts at rest)",
                          column="--velocity")
    errors_path = None
    if args.reference is not None:
        errors_path = args.errors or args.output.with_name(f"{args.output.stem}_errors.csv")
    imu, src = read_imu_input(args)
    inputs = [src, args.reference]
    for out in (args.output, args.figure, errors_path):
        if out is not None:
            ensure_not_input(out, inputs)
    lat, lon = np.radians(args.lat), np.radians(args.lon)
    t0 = float(imu.index[0])
    if args.align is not None:
        window = time_slice(imu, None, t0 + args.align)
        model = grade(args.grade) if args.grade else None
        heading = None if args.heading is None else np.radians(args.heading)
        check_gyro_at_rest(window, model, file=src, column="--gyro-unit")
        res = coarse_align(window, lat, args.height, model=model, heading=heading,
                           gravity_model=args.gravity_model)
        check_upright(res.roll, res.pitch, what="the static alignment", file=src,
                      column="--axis-map")
        d = res.as_degrees()
        print(f"alignment over {args.align:g} s ({res.heading_source}): roll {d['roll']:.3f}, "
              f"pitch {d['pitch']:.3f}, heading {d['heading']:.3f} deg")
        x0 = NavState(lat, lon, args.height, np.zeros(3), res.C, res.time)
        imu = time_slice(imu, res.time)
    else:
        r, p_, h = np.radians(args.attitude)
        x0 = NavState.from_euler(lat, lon, args.height, args.velocity or (0.0, 0.0, 0.0), r,
                                 p_, h, time=t0)
    x0.wander_angle = float(np.radians(args.wander_angle))
    traj = mechanize(imu, x0, gravity_model=args.gravity_model,
                     attitude_update=args.attitude_update, coning=args.coning,
                     fix_height=args.fix_height, frame=args.frame)
    write_table(traj, args.output)
    print(f"wrote {len(traj)} epochs to {args.output}")
    if args.figure is not None:
        from ..plots import navigation_figure, save_figure

        save_figure(navigation_figure(traj, f"free-inertial: {src.name}"), args.figure)
        print(f"wrote {args.figure}")
    if errors_path is not None:
        from ..evaluate import trajectory_errors
        from ..io.reference import read_reference

        err = trajectory_errors(traj, read_reference(args.reference))
        h = err["horizontal"].dropna()
        if not len(h):
            raise ConfigError("the reference does not overlap the trajectory in time",
                              file=args.reference, column="time",
                              expected=f"epochs in {traj.index[0]:.3f} .. {traj.index[-1]:.3f} s",
                              found="none")
        write_table(err, errors_path)
        print(f"errors against {args.reference.name} at {len(h)} epochs: horizontal final "
              f"{h.iloc[-1]:.3f} m, max {h.max():.3f} m, RMS {np.sqrt(np.mean(h ** 2)):.3f} m; "
              f"wrote {errors_path}")
    return 0
