"""Write a job file template for a common data format, ready to fill in.

The templates (``insgnss/data/templates/<format>.toml``) hold the keys a job in that format
usually needs, each with a comment saying what it means and what to put there; every key
and its default is in docs/jobs.md. ``kfgins`` is a KF-GINS / awesome-gins-datasets
recording; a KF-GINS YAML configuration converts with ``insgnss import-kfgins``.

Examples:
  insgnss init --format nmea -o my_drive.toml
  insgnss init --format kfgins            # prints the template
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "init"
HELP = "write a job file template (rtklib, kfgins, nmea, csv) to fill in"
FORMATS = ("rtklib", "kfgins", "nmea", "csv")


def template_path(fmt: str) -> Path:
    """The bundled template of a format."""
    from importlib import resources

    return Path(str(resources.files("insgnss") / "data" / "templates" / f"{fmt}.toml"))


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("--format", required=True, choices=FORMATS,
                   help="rtklib (IMU CSV + RTKLIB .pos), kfgins (KF-GINS files), nmea "
                   "(IMU CSV + NMEA), csv (IMU CSV + GNSS CSV)")
    p.add_argument("-o", "--output", type=Path, metavar="JOB.toml",
                   help="file to write (relative to the current folder; default: print)")
    p.add_argument("--force", action="store_true", help="replace an existing file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import ConfigError
    from ..io.native import atomic_write_text

    text = template_path(args.format).read_text()
    if args.output is None:
        print(text, end="")
        return 0
    if args.output.exists() and not args.force:
        raise ConfigError("the file exists (give --force to replace it)", file=args.output,
                          column="--output")
    atomic_write_text(args.output, text)
    print(f"wrote {args.output}: a {args.format} job template; fill in the paths and units, "
          f"then run: insgnss process {args.output}")
    return 0
