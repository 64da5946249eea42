"""Errors raised for a user's input.

Library code raises :class:`InputError` for anything that is the user's mistake (a missing file, a
malformed row, an inconsistent configuration). The command line turns it into a one-line message
``fusion-vo: error: FILE:LINE: message`` and exit status 2, never a traceback.
"""

from __future__ import annotations

from pathlib import Path


class InputError(Exception):
    """A problem with the user's input, located by file and (optionally) line.

    Parameters
    ----------
    message : str
        What is wrong, in plain words.
    path : str or Path, optional
        The file (or folder) at fault.
    line : int, optional
        1-based line number in ``path``.
    """

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.message = message
        self.path = None if path is None else Path(path)
        self.line = line
        super().__init__(str(self))

    def __str__(self) -> str:
        where = ""
        if self.path is not None:
            where = f"{self.path}"
            if self.line is not None:
                where += f":{self.line}"
            where += ": "
        return where + self.message
