"""Output folders of the sub-commands: checked and locked before anything is computed.

Every command that writes a set of outputs calls :func:`output_folder` once it knows its
inputs and before it reads data or computes: the folder must be usable
(:func:`insgnss.io.outputset.check_output_location`: a folder, creatable, writable, not an
input, no input under an output's name) and is locked for the whole command
(:func:`insgnss.io.outputset.lock_output_folder`). With ``--wait`` a command waits for a folder
another run holds; without, it stops with exit status 2.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path


def add_wait_argument(p: argparse.ArgumentParser) -> None:
    """``--wait``: wait for an output folder another run is writing."""
    p.add_argument("--wait", action="store_true",
                   help="if another run is writing the output folder, wait until it is done "
                   "(default: stop with exit status 2)")


@contextmanager
def output_folder(args: argparse.Namespace, folder, *, protect: Iterable = (),
                  names: Iterable[str] = ()) -> Iterator[Path]:
    """Check ``folder`` and hold its lock for the body (module docstring)."""
    from ..io.outputset import check_output_location, lock_output_folder

    out = check_output_location(folder, protect=protect, names=names)
    with lock_output_folder(out, wait=bool(getattr(args, "wait", False))):
        yield out
