"""Writing a *set* of output files so that an interrupted run never leaves a half-written set.

:func:`insgnss.io.native.atomic_write` makes each file atomic; a run writes many files
(trajectories, logs, summary, report), and a Ctrl-C or a kill between two of them would leave
a folder mixing the new run's files with the previous run's. :class:`OutputSet` is a small
transaction over the folder:

1. **staging**: every file is written (atomically, fsynced) into a hidden staging folder
   ``<dir>/.insgnss-staging-<id>/`` under its final name; this is the slow part. An interrupt
   here leaves the previous outputs untouched and complete (Ctrl-C removes the staging folder;
   a SIGKILL leaves it behind, hidden, and the next run in that folder removes it);
2. **commit**: a marker file ``INCOMPLETE`` is written first, then each staged file is renamed
   onto its final name (``os.replace``, atomic per file, milliseconds for the whole set), files
   of a previous run that this run does not produce (``stale`` names) are removed, and the
   marker is removed last. An interrupt during the commit leaves the marker, so the set is
   clearly marked partial;
3. a run whose result is itself incomplete (the filter stopped early, see
   :class:`insgnss.errors.FilterHealthError`) commits with ``complete=False``: the marker stays
   and says why.

So the folder holds either the complete previous outputs, the complete new outputs, or a set
carrying an ``INCOMPLETE`` file; never a partial file under a final name.
"""

from __future__ import annotations

import os
import shutil
import time
import uuid
from collections.abc import Iterable
from pathlib import Path

from ..validate import ensure_not_input
from .native import atomic_write_text

#: name of the marker file of a partial output set
MARKER = "INCOMPLETE"
#: prefix of the hidden staging folders
STAGING_PREFIX = ".insgnss-staging-"


class OutputSet:
    """Transaction writing several output files into one folder (module docstring).

    Parameters
    ----------
    folder : path
        Output folder (created).
    protect : iterable of paths
        Inputs that no output may replace (:func:`insgnss.validate.ensure_not_input`).
    stale : iterable of str
        File names a previous run may have left in ``folder`` that this run replaces or, when
        it does not produce them, removes at commit (never other files).

    Use as a context manager: an exception (including ``KeyboardInterrupt``) inside the block
    removes the staging folder and leaves ``folder`` as it was::

        with OutputSet(out, protect=inputs) as outs:
            write_table(df, outs.path("forward.csv"))
            paths = outs.commit(complete=True)
    """

    def __init__(self, folder: str | os.PathLike, *, protect: Iterable = (),
                 stale: Iterable[str] = ()):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.protect = [p for p in protect if p is not None]
        self.stale = set(stale)
        for old in self.folder.glob(STAGING_PREFIX + "*"):  # left behind by a killed run
            if old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
        self.staging = self.folder / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}"
        self.staging.mkdir()
        self.names: list[str] = []
        self.committed = False

    def path(self, name: str) -> Path:
        """Where to write the output ``name`` now (inside the staging folder)."""
        if Path(name).name != name or name in ("", ".", "..", MARKER):
            raise ValueError(f"invalid output file name {name!r}")
        ensure_not_input(self.folder / name, self.protect)
        if name not in self.names:
            self.names.append(name)
        return self.staging / name

    def commit(self, complete: bool = True, reason: str = "") -> dict[str, Path]:
        """Move the staged files onto their final names; returns ``{name: final path}``.

        With ``complete=False`` the ``INCOMPLETE`` marker stays, holding ``reason``.
        """
        missing = [n for n in self.names if not (self.staging / n).is_file()]
        if missing:
            raise FileNotFoundError(f"outputs announced but not written: {missing}")
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        files = "\n".join(f"  {n}" for n in self.names)
        atomic_write_text(self.folder / MARKER,
                          f"insgnss: output set being written ({stamp}). If this file is still "
                          "here, the run was interrupted while replacing its outputs: the "
                          f"folder may mix this run's files with an earlier run's.\nfiles:\n"
                          f"{files}\n")
        out = {}
        for n in self.names:
            final = self.folder / n
            os.replace(self.staging / n, final)
            out[n] = final
        for n in sorted(self.stale - set(self.names) - {MARKER}):
            (self.folder / n).unlink(missing_ok=True)
        _fsync_dir(self.folder)
        if complete:
            (self.folder / MARKER).unlink()
        else:
            out[MARKER] = atomic_write_text(
                self.folder / MARKER,
                f"insgnss: INCOMPLETE output set ({stamp}).\n{reason.rstrip()}\nfiles written "
                f"(partial results up to the stop):\n{files}\n")
        _fsync_dir(self.folder)
        self.committed = True
        shutil.rmtree(self.staging, ignore_errors=True)
        return out

    def abort(self) -> None:
        """Drop everything staged; the folder keeps its previous content."""
        shutil.rmtree(self.staging, ignore_errors=True)

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self.committed:
            self.abort()


def _fsync_dir(folder: Path) -> None:
    """Make the renames durable (POSIX; a no-op where directories cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - e.g. Windows
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


__all__ = ["MARKER", "STAGING_PREFIX", "OutputSet"]
