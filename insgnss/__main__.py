"""``python -m insgnss``: the ``insgnss`` command (:func:`insgnss.cli.entry`), for an
environment whose scripts folder is not on ``PATH``."""

from .cli import entry

if __name__ == "__main__":  # pragma: no cover
    entry()
