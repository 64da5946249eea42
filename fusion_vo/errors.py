"""Errors raised for a user's input.

Library code raises :class:`InputError` for anything that is the user's mistake (a missing file, a
malformed row, an inconsistent configuration). The command line turns it into a one-line message
``fusion-vo: error: FILE:LINE: message`` and exit status 2, never a traceback.
"""

from __future__ import annotations

import errno
import os
import stat
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


def _stat(path: Path, missing: str, cannot: str) -> os.stat_result:
    """``os.stat(path)``, or :class:`InputError` naming ``path``: a symbolic link loop, a broken symbolic
    link, ``missing`` (nothing there) or ``cannot`` with the system's reason."""
    try:
        return os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputError("symbolic link loop", path) from None
        if exc.errno == errno.ENOENT:
            raise InputError("broken symbolic link" if os.path.islink(path) else missing, path) from None
        raise InputError(f"{cannot} ({exc.strerror})", path) from None


def check_file(path: str | Path) -> Path:
    """Raise :class:`InputError` naming ``path`` unless it is a regular file that can be opened.

    The message says what is wrong: not found, a broken symbolic link, a symbolic link loop, a folder, not
    a regular file, or the system's reason (permission denied ...).
    """
    path = Path(path)
    st = _stat(path, "file not found", "cannot read file")
    if stat.S_ISDIR(st.st_mode):
        raise InputError("is a folder, not a file", path)
    if not stat.S_ISREG(st.st_mode):
        raise InputError("not a regular file", path)
    return path


def check_folder(path: str | Path, what: str = "folder") -> Path:
    """Raise :class:`InputError` naming ``path`` unless it is a folder; ``what`` names the kind of folder
    expected (``"run folder"``, ``"recording folder"``) in the message.

    The message says what is wrong: not found, a broken symbolic link, a file (not a folder), or the
    system's reason.
    """
    path = Path(path)
    st = _stat(path, f"{what} not found", f"cannot open {what}")
    if not stat.S_ISDIR(st.st_mode):
        raise InputError(f"is a file, not a {what}", path)
    return path
