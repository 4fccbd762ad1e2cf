"""The ``insgnss`` command line.

Sub-commands live in :mod:`insgnss.commands`, one module each, discovered automatically: a module
defines ``NAME`` (the sub-command), ``HELP`` (one line) and ``register(parser)`` that adds its
arguments and sets ``parser.set_defaults(func=run)`` where ``run(args) -> int``.
The CLI only parses arguments, calls the pipeline and reports; :class:`InsgnssError` is printed
without a traceback and the exit status is 2 (as for running out of memory); warnings are
printed one line each, without the Python source line (:func:`_warning_printer`). Commands
that write outputs check and lock their output folder before computing
(:mod:`insgnss.commands._outputs`).
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import pkgutil
import sys
import threading

from . import commands
from ._version import __version__
from .errors import InsgnssError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="insgnss",
        description="Inertial navigation and INS/GNSS integration toolkit "
        "(ENU navigation frame, right-forward-up body frame, SI units).",
    )
    parser.add_argument("--version", action="version", version=f"insgnss {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        mod = importlib.import_module(f"{commands.__name__}.{info.name}")
        if not hasattr(mod, "register"):
            continue
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=(mod.__doc__ or mod.HELP).strip(),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.register(p)
    return parser


def _warning_printer(command: str):
    """``warnings.formatwarning`` of the command line: one line per warning, ``insgnss
    COMMAND: warning: MESSAGE`` (the category in brackets unless it is an
    :class:`~insgnss.errors.InsgnssWarning`), without the Python file, line number and source
    line a user cannot act on (the message names the data file, row and column). A warning
    already printed by this command is not printed again (the same check run twice, e.g. an
    initialization repeated with the measured noise, said the same thing twice)."""
    from .errors import InsgnssWarning

    printed: set[str] = set()

    def fmt(message, category, filename, lineno, line=None):
        kind = "" if issubclass(category, InsgnssWarning) else f" ({category.__name__})"
        text = f"insgnss {command}: warning{kind}: {message}\n"
        if text in printed:
            return ""
        printed.add(text)
        return text

    return fmt


def main(argv: list[str] | None = None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    saved = warnings.formatwarning
    warnings.formatwarning = _warning_printer(args.command)
    try:
        return int(args.func(args) or 0)
    except InsgnssError as exc:
        print(f"insgnss {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"insgnss {args.command}: interrupted", file=sys.stderr)
        return 130
    except MemoryError:  # a resource limit, not a bug: say so without a traceback
        print(f"insgnss {args.command}: error: out of memory: the run needs more memory than "
              "this process may use (a longer log, a shorter filter.epoch_interval or more "
              "outage windows need more; the smoother stores covariances per epoch); the "
              "previous outputs are left as they were", file=sys.stderr)
        return 2
    finally:
        warnings.formatwarning = saved


def entry() -> None:
    """The console script ``insgnss`` (and ``python -m insgnss``, ``python -m insgnss.cli``):
    :func:`main`, then the process ends at once (:func:`exit_now`) instead of through the
    interpreter's teardown.

    The teardown of a long run frees the run's objects one by one: 1.0-1.4 s of a
    1 h / 200 Hz ``process`` run, after every output is written and closed. Code that calls
    :func:`main` in a process that goes on (the tests, scripts) keeps the normal exit.
    """
    exit_now(main())


def exit_now(code: int) -> None:
    """End the process with status ``code`` without the interpreter's teardown: the exit
    handlers (:mod:`atexit`, e.g. ``weakref.finalize`` callbacks) run and ``stdout`` /
    ``stderr`` are flushed first, then :func:`os._exit`. With another non-daemon thread
    still running the normal exit (which waits for it) is taken; daemon threads (a progress
    bar's monitor) end with the process either way."""
    me = threading.current_thread()
    if any(t is not me and not t.daemon and t.is_alive() for t in threading.enumerate()):
        sys.exit(code)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing left to save
            pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
