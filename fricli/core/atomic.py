"""Atomic output: write to a temporary file beside the target, fsync, then ``os.replace``.

A killed or failed job leaves the previous file untouched and no temporary file behind, except
after SIGKILL: then its ``.NAME.XXXXXXXX.tmp`` is left, and the next write to NAME removes it.

Several writers of one output (outputs without an output lock: ``predict``, ``import``,
``export -o``) never remove each other's temporary files. A writer creates its temporary file
with ``O_EXCL`` and holds an exclusive ``flock`` on it until the file is renamed or removed; a
writer looking for leftovers removes a ``.NAME.*.tmp`` only when it can take that lock without
waiting, i.e. when the process that made the file is gone (the kernel releases a dead process's
locks). A leftover is taken between its creation and its creator's ``flock`` only in an instant;
the creator then finds its file gone (it waits for the lock, then compares the inode) and starts
again under a new name. Each writer renames its own complete file, so the output ends as the
complete file of the writer that renamed last. ``flock`` is local: writers on different machines
sharing a network file system without it are not kept apart.

An output that is a symbolic link stays one: the file it points to is replaced, the same way.

The temporary file is created with mode 0o666 and the kernel applies the umask, so the output
gets the usual permissions without the process umask being read or changed.
"""

from __future__ import annotations

import contextlib
import fcntl
import glob
import os
import secrets
import stat
import sys
from typing import BinaryIO, Callable, Iterator

from fricli.core.errors import OutputError

_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC | os.O_NOFOLLOW
_PROBE = os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOFOLLOW


def _same_file(path: str, fd: int) -> bool:
    """Whether ``path`` still names the file open as ``fd``."""
    try:
        current = os.stat(path, follow_symlinks=False)
    except FileNotFoundError:
        return False
    held = os.fstat(fd)
    return (current.st_dev, current.st_ino) == (held.st_dev, held.st_ino)


def _temp_names(path: str) -> list[str]:
    folder, name = os.path.split(os.path.abspath(path))
    return glob.glob(os.path.join(folder, f".{glob.escape(name)}.*.tmp"))


def remove_stale_temps(path: str) -> list[str]:
    """Remove the temporary files of ``path`` whose writer is gone (no lock held on them);
    returns their names. A live writer's file is left alone."""
    removed = []
    for temp in _temp_names(path):
        try:
            fd = os.open(temp, _PROBE)
        except OSError:  # gone meanwhile, or not a regular file we may open
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: its writer is alive
            os.close(fd)
            continue
        try:
            if _same_file(temp, fd):
                os.unlink(temp)
                removed.append(temp)
        except OSError:
            pass
        finally:
            os.close(fd)
    return removed


def _create_temp(path: str, folder: str, name: str) -> tuple[int, str]:
    """A new ``.NAME.XXXXXXXX.tmp`` in ``folder``, open for writing and locked: (fd, its path)."""
    for _ in range(100):
        temp = os.path.join(folder, f".{name}.{secrets.token_hex(4)}.tmp")
        try:
            fd = os.open(temp, _CREATE, 0o666)
        except FileExistsError:
            continue
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror}") from exc
        fcntl.flock(fd, fcntl.LOCK_EX)  # waits only while another writer checks whether it is stale
        if _same_file(temp, fd):
            return fd, temp
        os.close(fd)  # taken for a leftover before we locked it: start again
    raise OutputError(f"cannot write {path}: no free temporary name in {folder}")


@contextlib.contextmanager
def atomic_open(path: str, *, binary: bool = False) -> Iterator[BinaryIO]:
    """Open ``path`` for binary writing; the file appears only if the block succeeds.

    ``path == "-"`` yields stdout's binary buffer instead (refused on a terminal for ``binary``
    content: Parquet, a model file); a device or FIFO (``/dev/null``) is written as it is.
    """
    if path == "-":
        if sys.stdout is None or sys.stdout.closed:
            raise OutputError("cannot write to stdout: it is closed")
        if binary and sys.stdout.isatty():
            raise OutputError("stdout is a terminal: redirect the binary output to a file (> FILE) or a "
                              "command (| fricli ...), or give -o FILE")
        try:
            yield sys.stdout.buffer
            sys.stdout.buffer.flush()
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise OutputError(f"cannot write to stdout: {exc.strerror or exc}") from exc
        return
    if os.path.islink(path):
        # the link stays a link: its target is replaced (a dangling link's target is created)
        shown, path = path, os.path.realpath(path)
    else:
        shown = path
    folder, name = os.path.split(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {shown}: folder {folder} does not exist")
    if os.path.exists(path) and not os.path.isdir(path) and not stat.S_ISREG(os.stat(path).st_mode):
        yield from _write_through(path)     # a device or a FIFO: written as it is, never replaced
        return
    remove_stale_temps(path)  # left by a job killed with SIGKILL
    fd, temp = _create_temp(path, folder, name)
    fh = os.fdopen(fd, "wb")
    try:  # the lock on the temporary file is held until fh is closed, after the rename
        yield fh
        fh.flush()
        os.fsync(fh.fileno())
        os.replace(temp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise
    finally:
        with contextlib.suppress(OSError):  # after a failure, what is left in the buffer is lost anyway
            fh.close()
    with contextlib.suppress(OSError):  # make the rename itself durable
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def _write_through(path: str) -> Iterator[BinaryIO]:
    try:
        with open(path, "wb") as fh:
            yield fh
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc


class Cuttable:
    """A binary file (``atomic_open``'s) that passes writes on until ``cut()``. A streaming writer
    closed after a failure (pyarrow's ParquetWriter writes the footer as it closes) then leaves
    stdout, a pipe or a device without the end of its format, so that the reader downstream finds
    the output damaged, not a complete file of fewer rows. (A regular file is never renamed into
    place after a failure.)"""

    closed = False

    def __init__(self, fh: BinaryIO):
        self._fh, self._cut, self._pos = fh, False, 0

    def cut(self) -> None:
        self._cut = True

    def write(self, data) -> int:
        if not self._cut:
            self._fh.write(data)
        self._pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        if not self._cut:
            self._fh.flush()

    def close(self) -> None:
        """Left to ``atomic_open``."""


def atomic_write_bytes(path: str, data: bytes, *, binary: bool = False) -> None:
    with atomic_open(path, binary=binary) as fh:
        fh.write(data)


def atomic_write_with(path: str, writer: Callable[[BinaryIO], None]) -> None:
    with atomic_open(path) as fh:
        writer(fh)
