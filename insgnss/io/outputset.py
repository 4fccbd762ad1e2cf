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

Inputs are never touched: no output may replace an input (:meth:`OutputSet.path`), and a
stale name that is an input (the same path after resolving links and ``..``, or the same file
by device and inode) is kept at commit, with a warning. :func:`check_output_location` finds
every unusable output location (a file, a folder that cannot be created or written, an input
under an output's name) before a command computes anything.

**One run per folder.** A run holds a lock on its output folder (:func:`lock_output_folder`,
taken by the command before it computes and by :class:`OutputSet`; re-entrant within one
process): the file ``<dir>/.insgnss-lock`` holds the holder's pid, host and start time, and an
exclusive ``flock`` on it marks it live (released by the kernel when the holder dies, also on
NFS). A second run refuses with "output folder DIR in use by pid N since T (host H)"
(:class:`~insgnss.errors.OutputBusyError`, exit 2) or, asked to wait, polls until the folder is
free. A lock file left by a killed run is taken over with a warning. Where ``flock`` is not
available the lock is the exclusive creation of the file, and a lock of a dead process on the
same host is stale.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import socket
import time
import uuid
from collections.abc import Iterable
from pathlib import Path

from ..errors import ConfigError, OutputBusyError, OutputError
from ..validate import ensure_not_input, input_clash, warn
from .native import atomic_write_text

#: name of the marker file of a partial output set
MARKER = "INCOMPLETE"
#: prefix of the hidden staging folders
STAGING_PREFIX = ".insgnss-staging-"
#: the lock file of an output folder
LOCK_NAME = ".insgnss-lock"


def check_output_location(folder: str | os.PathLike, *, protect: Iterable = (),
                          names: Iterable[str] = ()) -> Path:
    """Make sure a run can write its outputs into ``folder``, before it computes anything.

    Creates the folder and returns it. Raises :class:`~insgnss.errors.ConfigError` when the
    folder is one of the inputs ``protect`` or when an input sits in it under one of the
    output ``names`` (the run would replace or remove it), and
    :class:`~insgnss.errors.OutputError` when it is a file, cannot be created or is not
    writable (tested by creating and removing a file, which also holds for root and for
    read-only file systems).
    """
    protect = [q for q in protect if q is not None]
    p = Path(folder).expanduser().absolute()
    ensure_not_input(p, protect)
    if p.exists() and not p.is_dir():
        raise OutputError("the output folder is not a folder: a file of that name exists",
                          file=p, expected="a folder (or a path to create one)", found="a file")
    parent = p
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"cannot create the output folder: {parent} is a file, not a folder",
                          file=p, expected="a folder path", found=f"the file {parent}")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder ({exc.strerror or exc})",
                          file=p) from None
    probe = p / f".insgnss-probe-{uuid.uuid4().hex[:12]}"
    try:
        os.close(os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        probe.unlink()
    except OSError as exc:
        raise OutputError(f"the output folder is not writable ({exc.strerror or exc})",
                          file=p, expected="a folder this user can write") from None
    for n in names:
        q = input_clash(p / n, protect)
        if q is not None:
            raise ConfigError(
                f"an input of the job is in the output folder under the output name {n!r}: "
                "the run would replace or remove it; write the outputs elsewhere or move the "
                "input", file=p / n, expected="no input under an output name",
                found=f"the input {str(q)!r}")
    return p


def _lock_info(path: Path) -> dict:
    try:
        info = json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def _describe(info: dict) -> str:
    return (f"pid {info.get('pid', '?')} since {info.get('started', '?')} (host "
            f"{info.get('host', '?')})")


def _alive(info: dict) -> bool:
    """The holder may still run (only a process on this host can be checked)."""
    if info.get("host") != socket.gethostname():
        return True
    try:
        os.kill(int(info.get("pid")), 0)
    except ProcessLookupError:
        return False
    except (PermissionError, TypeError, ValueError):
        return True
    return True


_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
#: output folders this process holds: resolved path -> [OutputLock, count]
_HELD: dict[str, list] = {}


class OutputLock:
    """The lock of one output folder (module docstring); use :func:`lock_output_folder`."""

    def __init__(self, folder: str | os.PathLike, *, wait: bool = False, poll: float = 0.5):
        self.folder = Path(folder)
        self.wait = wait
        self.poll = float(poll)
        self._fd: int | None = None
        self._key: str | None = None
        self._holding = False

    @property
    def path(self) -> Path:
        return self.folder / LOCK_NAME

    def acquire(self) -> OutputLock:
        self.folder.mkdir(parents=True, exist_ok=True)
        key = str(self.folder.resolve())
        if self._holding:
            return self
        if key in _HELD:  # this process holds it already (a command and its output set)
            _HELD[key][1] += 1
            self._key, self._holding = key, True
            return self
        announced = False
        while True:
            fd, holder = self._try()
            if fd is not None:
                break
            if not self.wait:
                raise OutputBusyError(
                    f"output folder {self.folder} in use by {_describe(holder)}",
                    file=self.folder, expected="a folder no other run is writing (or wait "
                    "for it: --wait)", found=f"the lock file {self.path}")
            if not announced:
                warn(f"output folder {self.folder} in use by {_describe(holder)}; waiting",
                     file=self.folder)
                announced = True
            time.sleep(self.poll)
        info = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, (json.dumps(info) + "\n").encode())
        os.fsync(fd)
        self._fd, self._key, self._holding = fd, key, True
        _HELD[key] = [self, 1]
        return self

    def _try(self) -> tuple[int | None, dict]:
        """One attempt: ``(fd, {})`` when taken, ``(None, holder info)`` when busy."""
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX
            fcntl = None
        if fcntl is not None:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | _CLOEXEC, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    return None, _lock_info(self.path)
                if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
                    raise
            else:
                try:  # a releasing holder unlinks the file: ours must still be the one there
                    current = os.path.samestat(os.fstat(fd), os.stat(self.path))
                except FileNotFoundError:
                    current = False
                if not current:
                    os.close(fd)
                    return self._try()
                old = _lock_info(self.path)
                if old:
                    warn(f"took over the stale lock of {_describe(old)}: that run ended "
                         "without releasing the output folder (killed?)", file=self.folder)
                return fd, {}
        # no flock: exclusive creation; a lock of a dead process on this host is stale
        try:
            return os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | _CLOEXEC,
                           0o644), {}
        except FileExistsError:
            old = _lock_info(self.path)
            if old and not _alive(old):
                warn(f"took over the stale lock of {_describe(old)}: that process has ended",
                     file=self.folder)
                self.path.unlink(missing_ok=True)
                return self._try()
            return None, old

    def release(self) -> None:
        """Give the lock back (once per acquire; the last holder in the process removes the
        lock file)."""
        if not self._holding:
            return
        self._holding = False
        entry = _HELD.get(self._key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] > 0:
            return
        owner = entry[0]
        del _HELD[self._key]
        if owner._fd is not None:
            owner.path.unlink(missing_ok=True)  # while still holding it (see _try)
            os.close(owner._fd)
            owner._fd = None

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, exc_type, exc, tb) -> None:
        self.release()


def lock_output_folder(folder: str | os.PathLike, *, wait: bool = False,
                       poll: float = 0.5) -> OutputLock:
    """Context manager holding the lock of ``folder`` (module docstring).

    Raises :class:`~insgnss.errors.OutputBusyError` when another run holds it, or with
    ``wait=True`` warns once and polls every ``poll`` seconds until it is free.
    """
    return OutputLock(folder, wait=wait, poll=poll)


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
                 stale: Iterable[str] = (), wait: bool = False):
        self.folder = check_output_location(folder)
        self.protect = [p for p in protect if p is not None]
        self.stale = set(stale)
        self._lock = lock_output_folder(self.folder, wait=wait).acquire()
        try:
            # no other run uses the folder now: a staging folder is a killed run's leftover
            for old in self.folder.glob(STAGING_PREFIX + "*"):
                if old.is_dir():
                    shutil.rmtree(old, ignore_errors=True)
            self.staging = self.folder / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}"
            self.staging.mkdir()
        except BaseException:
            self._lock.release()
            raise
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
            q = input_clash(self.folder / n, self.protect)
            if q is not None:  # never remove an input, whatever its name
                warn(f"{n} of a previous run is kept: it is an input of this run ({q})",
                     file=self.folder / n)
                continue
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
        self._lock.release()
        return out

    def abort(self) -> None:
        """Drop everything staged; the folder keeps its previous content."""
        shutil.rmtree(self.staging, ignore_errors=True)
        self._lock.release()

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self.committed:
            self.abort()
        self._lock.release()


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


__all__ = ["LOCK_NAME", "MARKER", "STAGING_PREFIX", "OutputBusyError", "OutputLock", "OutputSet",
           "check_output_location", "lock_output_folder"]
