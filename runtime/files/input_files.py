"""The check every file reader makes first: the path is a regular file (not a folder, FIFO or device).

A folder raises IsADirectoryError deep inside a reader, and a FIFO blocks
the reader forever; both are refused here, at the door, naming the path.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from facepuppet.runtime.errors import InputFileError


def regular_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path once it names a regular file; ``what`` says what was expected ("session file").

    Raises FileNotFoundError when nothing is there, InputFileError for a folder, FIFO,
    socket or device (never opened, so a FIFO cannot block).
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode  # follows links; stat never opens, so a FIFO does not block
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {what} not found") from None
    if stat.S_ISREG(mode):
        return path
    kind = ("a folder" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "not a regular file")
    raise InputFileError(f"{path}: expected a {what}, found {kind}")
