"""The console entry ends the process without the interpreter's teardown (insgnss.cli.entry):
the exit status, the exit handlers and the buffered output are kept."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _run(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          cwd=REPO, timeout=120)


def test_exit_now_runs_exit_handlers_and_flushes():
    r = _run("import atexit, sys\n"
             "from insgnss.cli import exit_now\n"
             "atexit.register(lambda: sys.stdout.write('handler ran\\n'))\n"
             "sys.stdout.write('buffered line\\n')\n"
             "sys.stderr.write('to stderr\\n')\n"
             "exit_now(7)\n"
             "print('not reached')\n")
    assert r.returncode == 7
    assert r.stdout == "buffered line\nhandler ran\n"
    assert r.stderr == "to stderr\n"


def test_entry_keeps_the_status_of_main():
    # no command: main prints the help and returns 1
    r = _run("import sys; sys.argv = ['insgnss']\nfrom insgnss.cli import entry\nentry()\n")
    assert r.returncode == 1
    assert "usage: insgnss" in r.stdout and "process" in r.stdout


def test_exit_now_waits_for_other_threads():
    # a running thread: the normal exit, which waits for it
    r = _run("import threading, time\n"
             "from insgnss.cli import exit_now\n"
             "def late():\n"
             "    time.sleep(0.3)\n"
             "    print('thread done', flush=True)\n"
             "threading.Thread(target=late).start()\n"
             "exit_now(4)\n")
    assert r.returncode == 4
    assert r.stdout == "thread done\n"


def test_exit_now_does_not_wait_for_daemon_threads():
    # a daemon thread (tqdm's monitor) ends with the process, as at a normal exit
    r = _run("import threading, time\n"
             "from insgnss.cli import exit_now\n"
             "threading.Thread(target=time.sleep, args=(30,), daemon=True).start()\n"
             "print('before', flush=False)\n"
             "exit_now(5)\n")
    assert r.returncode == 5
    assert r.stdout == "before\n"
