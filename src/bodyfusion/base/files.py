"""Files read and written safely: whether a path names a file a reader may open (a FIFO would
block the reader for ever, /dev/zero would feed it without end, a directory is no recording), and
outputs that replace the previous ones in one step or not at all: a file
(:func:`replaced_atomically`) or a set of files (:func:`staged_outputs`)."""

from __future__ import annotations

import os
import shutil
import stat
from collections.abc import Callable, Collection, Iterator
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


def refuse_to_replace(folder: Path, names: Collection[str], overwrite: bool, writer: str) -> None:
    """Refuse (:class:`FusionError` naming ``folder`` and the files) a ``folder`` that holds any of
    the ``names`` the ``writer`` (e.g. "the simulation") writes, unless ``overwrite``: nothing
    is replaced that the user did not ask to replace."""
    taken = sorted(name for name in names if (folder / name).exists()) if folder.is_dir() else []
    if taken and not overwrite:
        raise FusionError(f"{folder}: holds {', '.join(taken)}, which {writer} would replace; give another --out, "
                          "or --overwrite to replace them")


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


STAGING_PREFIX = ".staging."
"""Name of a staging folder (:func:`staged_outputs`) less the writer's process id."""


@contextmanager
def staged_outputs(folder: Path, last: tuple[str, ...] = (),
                   owned: Callable[[str], bool] = lambda name: False) -> Iterator[Path]:
    """A staging folder inside ``folder`` (same file system) to write a set of outputs into. Once
    the block ends without an error, each entry of it takes its place in ``folder`` (``os.replace``;
    a folder by :func:`_replace_folder`), the names in ``last`` after the others (a file that marks
    the set complete), and an entry of ``folder`` the set ``owned`` (a name the writer writes)
    though this set has none is removed before them (an earlier set's file this one does
    not make); else the staging folder is removed and ``folder`` keeps every earlier file.
    Nothing is replaced until everything is written, so a write that fails part-way (a full disk,
    a read-only file) leaves the earlier set whole, not some files of each; the step that puts
    them in place only renames, which needs no space. Staging folders a killed writer left behind
    (its process gone) are removed first. Call it as the folder's sole writer
    (:func:`sole_writer`)."""
    folder = Path(folder)
    for stale in folder.glob(STAGING_PREFIX + "*"):
        pid = stale.name[len(STAGING_PREFIX):]
        if pid.isdigit() and int(pid) != os.getpid() and not _process_alive(int(pid)):
            shutil.rmtree(stale, ignore_errors=True)
    staging = folder / f"{STAGING_PREFIX}{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        yield staging
        entries = sorted(staging.iterdir(), key=lambda p: (p.name in last, last.index(p.name) if p.name in last else 0,
                                                           p.name))
        written = {entry.name for entry in entries}
        for earlier in folder.iterdir():
            if owned(earlier.name) and earlier.name not in written:
                shutil.rmtree(earlier) if earlier.is_dir() else earlier.unlink()
        for entry in entries:
            if entry.is_dir():
                _replace_folder(entry, folder / entry.name)
            else:
                os.replace(entry, folder / entry.name)
        staging.rmdir()
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


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
