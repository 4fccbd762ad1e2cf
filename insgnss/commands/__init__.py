"""CLI sub-commands, one module each (see :mod:`insgnss.cli`)."""
