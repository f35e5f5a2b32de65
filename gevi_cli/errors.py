"""User-facing errors.

Every mistake a user can make (bad path, malformed file, wrong option) is raised as a
:class:`GeviError` naming *where* the problem is (a file, a row, an option).  The CLI prints it as
one line ``gevi: error: <where>: <what is wrong and what to do>`` and exits with status 2; a
traceback is shown only with ``gevi --debug``.
"""
from __future__ import annotations

from pathlib import Path


class GeviError(Exception):
    """A problem with the user's input, reported as one line.

    ``where`` is the file (optionally with ``:row``) or option at fault; ``message`` says what is
    wrong and, where possible, what to do about it.
    """

    exit_code = 2

    def __init__(self, where: str | Path | None, message: str):
        self.where = str(where) if where is not None else None
        self.message = message
        super().__init__(self.one_line())

    def one_line(self) -> str:
        return f"{self.where}: {self.message}" if self.where else self.message


class DataError(GeviError):
    """A data file exists but its content is invalid (bad rows, non-finite values, ...)."""


class LayoutError(GeviError):
    """A dataset folder or bag does not have the expected layout."""
