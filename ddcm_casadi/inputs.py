"""Input files named by users: one check that says what is wrong with a path, in one line."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from .errors import InputError


def input_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it names a regular file that exists.

    Parameters
    ----------
    path : str or PathLike
        The file a user named.
    what : str
        What the file is, for the message (``"config file"``, ``"data file"``, ...).

    Raises
    ------
    InputError
        One line saying which of these it is: not found (or a dangling symbolic link), a
        directory, a symbolic link loop, not a regular file (a device, a pipe), or not accessible.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InputError(f"{what} is a symbolic link loop: {path}") from None
        if exc.errno == errno.ENOENT and os.path.islink(path):
            raise InputError(f"{what} is a dangling symbolic link to {os.readlink(path)}: {path}") from None
        if exc.errno == errno.ENOENT:
            raise InputError(f"{what} not found: {path}") from None
        raise InputError(f"cannot access {what} {path}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise InputError(f"{what} is a directory, not a file: {path}")
    if not stat.S_ISREG(mode):
        raise InputError(f"{what} is not a regular file: {path}")
    return path
