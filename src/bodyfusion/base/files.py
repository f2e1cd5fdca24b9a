"""Files read and written safely: whether a path names a file a reader may open (a FIFO would
block the reader for ever, /dev/zero would feed it without end, a directory is no recording), and
outputs that replace the previous ones in one step or not at all."""

from __future__ import annotations

import os
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bodyfusion.base.errors import FusionError


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


@contextmanager
def replaced_atomically(path: Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write a file (or a folder) into; once the block ends
    without an error it takes ``path``'s place in one step (``os.replace``; a folder: the old one
    moved aside first, :func:`_replace_folder`), else it is removed and whatever stood at
    ``path`` before stays: a reader never sees a half-written file, and a failed rewrite (a full
    disk) never destroys the previous one. Nothing written: nothing replaced."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        yield tmp
        if tmp.is_dir():
            _replace_folder(tmp, path)
        elif tmp.exists():
            os.replace(tmp, path)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def _replace_folder(new: Path, path: Path) -> None:
    """Put the folder ``new`` (written completely) where the folder ``path`` is: the old one is
    moved aside first and removed after, so ``path`` holds one complete set of files or the other."""
    old = path.with_name(f".{path.name}.{os.getpid()}.old")
    if path.exists():
        os.replace(path, old)
    os.replace(new, path)
    shutil.rmtree(old, ignore_errors=True)


@contextmanager
def sole_writer(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` (an advisory ``flock`` on the folder itself, no file
    left behind) while the block writes into it; a second writer meanwhile gets a
    :class:`~bodyfusion.base.errors.FusionError` at once instead of mixing its files with the
    first's. Where ``flock`` does not exist the block runs unlocked."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FusionError(f"{folder}: another run is writing into this folder; give each run its own --out") from None
        yield
    finally:
        os.close(fd)  # closing releases the lock
