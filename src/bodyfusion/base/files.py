"""Whether a path names a file a reader may open: a FIFO would block the reader for ever,
/dev/zero would feed it without end, a directory is no recording."""

from __future__ import annotations

import stat
from pathlib import Path


def file_problem(path: Path) -> str | None:
    """Why ``path`` is not a regular file to read (one phrase), or None if it is one. Asked of
    the file system without opening it (opening a FIFO blocks until a writer comes)."""
    try:
        mode = Path(path).stat().st_mode
    except FileNotFoundError:
        return "file not found"
    except NotADirectoryError:
        return "file not found (a part of the path is not a folder)"
    except OSError as err:
        return f"cannot read file: {err.strerror or err}"
    if stat.S_ISDIR(mode):
        return "is a directory, not a file"
    if not stat.S_ISREG(mode):
        kind = "a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "a device"
        return f"is {kind}, not a regular file: a recording must be a file on disk"
    return None
