"""Exception types. Every problem insgnss reports to a user derives from :class:`InsgnssError`
and says where (file, 1-based row as an editor shows it, column or key), what was expected and
what was found. The CLI prints these without a traceback and exits with status 2.
"""

from __future__ import annotations


class _Located:
    """Location fields (file, row, column) and expected/found, formatted into the message."""

    def __init__(self, message: str, *, file=None, row: int | None = None, column=None,
                 expected=None, found=None):
        self.message = message
        self.file = None if file is None else str(file)
        self.row = row
        self.column = column
        self.expected = expected
        self.found = found
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.file is not None:
            where.append(f"{self.file}")
        if self.row is not None:
            where.append(f"row {self.row}")
        if self.column is not None:
            where.append(f"column {self.column!r}")
        text = (", ".join(where) + ": " if where else "") + self.message
        if self.expected is not None:
            text += f"; expected {self.expected}"
        if self.found is not None:
            text += f", found {self.found}"
        return text


class InsgnssError(_Located, Exception):
    """Base class of all insgnss errors meant for the user.

    Parameters
    ----------
    message : str
        What is wrong.
    file, row, column : optional
        Location: file path, 1-based row number (as an editor shows it, header included),
        column name or job-file key.
    expected, found : optional
        What was expected and what was found.
    """


class InputFormatError(InsgnssError):
    """A file cannot be parsed: empty, missing/extra columns, non-numeric cells, bad header."""


class InvalidValueError(InsgnssError):
    """Values are present but invalid: NaN/inf, out of the plausible range for the declared unit."""


class TimeOrderError(InsgnssError):
    """Timestamps that are not strictly increasing, duplicated, or outside the expected span."""


class DataGapError(InsgnssError):
    """A gap in the data longer than the configured policy allows."""


class UnitError(InsgnssError):
    """Values that do not fit the declared unit (e.g. deg/s declared as rad/s)."""


class ConfigError(InsgnssError):
    """A job file or an argument is wrong: unknown key, wrong type, missing value."""


class AlignmentError(InsgnssError):
    """Alignment is impossible with the data given (e.g. a window that is not static)."""


class FilterHealthError(InsgnssError):
    """The Kalman filter became non-finite, non-positive-definite, or its NIS ran away."""


class RateMismatchError(InsgnssError):
    """The measured sample rate does not match the declared rate."""


class NoUsableAidingError(InsgnssError):
    """A job asks for an aiding source of which nothing can be applied (every epoch removed by
    a quality filter, an outage window, the IMU time span, the innovation gate...); the message
    names the step that removed the last of it."""


class OutputError(InsgnssError):
    """An output location cannot be used: not a folder, cannot be created, not writable."""


class OutputBusyError(OutputError):
    """The output folder is locked by another run (``insgnss.io.outputset``)."""


class InsgnssWarning(_Located, UserWarning):
    """A problem insgnss repaired or tolerated (bridged gap, dropped duplicate, trimmed epoch).

    Emitted with :func:`warnings.warn`; carries the same location fields as
    :class:`InsgnssError`. The reader that warns also records what it did in the table's
    ``attrs`` (e.g. ``attrs["gaps"]``, ``attrs["dropped_duplicates"]``).
    """
