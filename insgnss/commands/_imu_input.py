"""IMU input options shared by the commands that read one IMU file (``mechanize``, ``allan``):
the keys of a job file's ``[inputs.imu]`` table as options, or ``--job JOB.toml`` to reuse that
table as it is. Either way the file is read exactly as ``insgnss process`` reads it
(:func:`insgnss.job.inputs.read_imu`: the same schema, checks, readers, units and mounting).

Paths: an IMU file on the command line is relative to the current folder; paths inside the
job file stay relative to the job file (docs/jobs.md, "Paths").
"""

from __future__ import annotations

import argparse
from pathlib import Path

#: option -> ``[inputs.imu]`` key
KEYS = {"format": "format", "tag": "tag", "columns": "columns", "gyro_unit": "gyro_unit",
        "accel_unit": "accel_unit", "time_unit": "time_unit", "time_offset": "time_offset",
        "axis_map": "axis_map", "mounting": "mounting_deg",
        "mounting_convention": "mounting_convention", "sensor_axes": "sensor_axes",
        "rate_hz": "rate_hz", "delimiter": "delimiter", "header": "header",
        "header_rows": "header_rows"}


def triple(text: str) -> tuple[float, float, float]:
    """``"a,b,c"`` -> three floats (argparse type)."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected three comma-separated numbers, got {text!r}") from None
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"expected three comma-separated numbers, got {text!r}")
    return vals


def columns(text: str) -> dict[str, str | int]:
    """``"time=t_ms,gyro_x=gx,..."`` -> ``{slot: column}`` (a digit-only column is an index)."""
    out: dict[str, str | int] = {}
    for part in text.split(","):
        slot, sep, col = part.partition("=")
        if not sep or not slot.strip() or not col.strip():
            raise argparse.ArgumentTypeError(
                f"expected SLOT=COLUMN pairs separated by commas, got {part!r}")
        col = col.strip()
        out[slot.strip()] = int(col) if col.isdigit() else col
    return out


def add_imu_arguments(p: argparse.ArgumentParser, *, imu_help: str) -> None:
    """The IMU file (optional with ``--job``) and the ``[inputs.imu]`` options."""
    p.add_argument("imu", type=Path, nargs="?", metavar="IMU_FILE", help=imu_help)
    g = p.add_argument_group(
        "IMU input", "the keys of a job's [inputs.imu] table (docs/jobs.md); default: the "
        "job's value with --job, else the schema default")
    g.add_argument("--job", type=Path, metavar="JOB.toml",
                   help="read the IMU as this job's [inputs.imu] describes (its path unless "
                   "IMU_FILE is given; the options below override single keys)")
    g.add_argument("--format", choices=["csv", "native", "kfgins", "rtklibexplorer"],
                   help="IMU file format (default csv)")
    g.add_argument("--tag", help="RTKLIB .tag file (rtklibexplorer format)")
    g.add_argument("--columns", type=columns, metavar="SLOT=COLUMN,...",
                   help="column of each slot, e.g. time=t_ms,gyro_x=gx,...,accel_z=az "
                   "(csv format; a number is a 0-based index)")
    g.add_argument("--gyro-unit", help="rad/s, deg/s, rad or deg (increments); default rad/s")
    g.add_argument("--accel-unit", help="m/s^2, g or m/s (increments); default m/s^2")
    g.add_argument("--time-unit", help="s, ms, us, ns or sample; default s")
    g.add_argument("--time-offset", type=float, help="added to the time [s]")
    g.add_argument("--axis-map", help='sensor-to-body axis map, e.g. "y,x,-z" (FRD -> RFU)')
    g.add_argument("--mounting", type=triple, metavar="R,P,Y",
                   help="sensor mounting Euler angles relative to the body [deg]")
    g.add_argument("--mounting-convention", choices=["active", "passive"])
    g.add_argument("--sensor-axes", choices=["rfu", "frd"],
                   help="axes of the (mapped) sensor triad")
    g.add_argument("--rate-hz", type=float, help="declared IMU rate (checked)")
    g.add_argument("--delimiter", help="field separator (csv; default ',')")
    g.add_argument("--no-header", dest="header", action="store_false", default=None,
                   help="the file has no header line (csv: columns by index)")
    g.add_argument("--header-rows", type=int, help="header lines (csv; default 1)")


def imu_job(args: argparse.Namespace, default_format: str = "csv"):
    """The validated job (:class:`insgnss.config.Job`) whose ``[inputs.imu]`` the options
    describe: ``--job``'s table with the options given on top, else the options alone."""
    import tomllib

    from ..batch import merge_settings
    from ..config import load_job_dict
    from ..errors import ConfigError

    given = {KEYS[k]: list(v) if isinstance(v, tuple) else v for k in KEYS
             if (v := getattr(args, k, None)) is not None}
    if args.imu is not None:
        given["path"] = str(args.imu.resolve())
    if args.job is None:
        if args.imu is None:
            raise ConfigError("give an IMU file or --job JOB.toml", column="IMU_FILE")
        given.setdefault("format", default_format)
        return load_job_dict({"inputs": {"imu": given}}, None)
    try:
        data = tomllib.loads(args.job.read_text())
    except FileNotFoundError:
        raise ConfigError("job file not found", file=args.job) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=args.job) from None
    keep = {k: v for k, v in data.items() if k == "inputs"}
    keep = merge_settings(keep, {"inputs": {"imu": given}})
    keep["inputs"] = {"imu": keep["inputs"]["imu"]}  # the IMU table only
    job = load_job_dict(keep, args.job)
    if job["inputs"]["imu"]["path"] is None:
        raise ConfigError("the job has no [inputs.imu] path and no IMU_FILE is given",
                          file=args.job, column="inputs.imu.path")
    return job


def read_imu_input(args: argparse.Namespace, default_format: str = "csv"):
    """Read the IMU the options describe; returns ``(table, path)``."""
    from ..job.inputs import read_imu

    job = imu_job(args, default_format)
    return read_imu(job), job.resolve(job["inputs"]["imu"]["path"])
