"""Translate a KF-GINS configuration (``kf-gins.yaml``) into an insgnss job file.

Every KF-GINS key becomes the insgnss key with the same meaning (files, processing interval,
initial attitude, velocity and sigmas, IMU noise as Gauss-Markov biases with their
correlation time, scale factors, antenna lever arm in right-forward-up), each with a comment
naming its source; what has no counterpart is listed at the top of the file
(insgnss.io.kfgins_yaml). KF-GINS resolves the YAML's paths in the folder it runs in: give it
with ``--kfgins-dir`` (default: the current folder); the job names them relative to itself.

Examples:
  insgnss import-kfgins dataset/kf-gins.yaml -o dataset/kfgins_job.toml
  insgnss process dataset/kfgins_job.toml
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "import-kfgins"
HELP = "translate a KF-GINS kf-gins.yaml into an insgnss job file"


def register(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", type=Path, metavar="KF-GINS.yaml", help="KF-GINS configuration")
    p.add_argument("-o", "--output", type=Path, metavar="JOB.toml",
                   help="job file to write (default: <config stem>.toml beside the config)")
    p.add_argument("--kfgins-dir", type=Path, default=Path("."), metavar="DIR",
                   help="folder KF-GINS runs in, where the YAML's paths start (default: the "
                   "current folder)")
    p.add_argument("--name", help="[job] name (default: the config's file name)")
    p.add_argument("--force", action="store_true", help="replace an existing job file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..config import load_job_dict
    from ..errors import ConfigError
    from ..io.kfgins_yaml import job_dict, job_toml, kfgins_job, read_kfgins_config
    from ..io.native import atomic_write_text
    from ..validate import ensure_not_input

    out = args.output or args.config.with_suffix(".toml")
    ensure_not_input(out, [args.config])
    if out.exists() and not args.force:
        raise ConfigError("the job file exists (give --force to replace it)", file=out,
                          column="--output")
    cfg = read_kfgins_config(args.config)
    tables, notes = kfgins_job(cfg, file=args.config, base=args.kfgins_dir,
                               job_dir=out.resolve().parent,
                               name=args.name or args.config.stem)
    load_job_dict(job_dict(tables), out)  # the translation is a valid job
    atomic_write_text(out, job_toml(tables, notes, str(args.config)))
    print(f"wrote {out} ({sum(len(r) for _, r in tables)} keys from {args.config})")
    for n in notes:
        print(f"  not translated: {n}")
    print(f"run it: insgnss process {out}")
    return 0
