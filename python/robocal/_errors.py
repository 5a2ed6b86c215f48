"""robocal's exceptions and warnings.

They mirror the command line's exit codes: ``BadInput`` is what ``robocal`` exits 2 for (an input that
cannot be read, a malformed table, a bad option value: fix the call or the data), ``RuntimeFailure``
what it exits 1 for (the input was fine but the work or the writing failed). The message is the one
line the command line prints, naming the file or column, the row and the field.
"""

from __future__ import annotations

from typing import Any


class Error(Exception):
    """Base class of robocal's errors."""


class BadInput(Error, ValueError):
    """Bad input or usage (the command line's exit 2): a table, file, robot or option value is wrong."""


class RuntimeFailure(Error, RuntimeError):
    """The input was fine but the work failed (the command line's exit 1), e.g. a calibration that
    did not converge (its report is in ``report``) or a file that cannot be written."""

    def __init__(self, message: str, report: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        #: The ``calibrate --json`` document of a calibration that did not converge, else None.
        self.report = report


class DataWarning(UserWarning):
    """Something about the data worth a look that does not stop the work (the command line's
    ``warning:`` lines): values beyond joint limits, units that look like millimetres or degrees."""
