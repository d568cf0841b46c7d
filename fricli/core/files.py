"""Reading an input file whole, with its failures as one user-facing error.

Only regular files are read: a device (``/dev/urandom``), a named pipe or a socket never ends or
blocks, so it is refused with one line before any byte is read. stdin (a pipe in a shell
pipeline) is read in chunks up to ``STDIN_LIMIT`` bytes: an endless stdin is refused at the limit,
not read until memory runs out. Reads go in chunks so that SIGINT and SIGTERM are honoured while a
large file is read (Python runs signal handlers only between its own steps).
"""

from __future__ import annotations

import os
import stat

CHUNK = 1 << 20
STDIN_LIMIT = 1 << 30      # bytes of stdin held in memory at most (more: give a file)
SPOOL_LIMIT = 64 << 30     # bytes of stdin spooled to a temporary file at most (a log read in batches)


def path_arg(value, what: str, who: str) -> str:
    """A file argument of a Python call as text (str, bytes or os.PathLike; "-" where the call
    takes stdin or stdout); OptionError naming ``what`` for anything else."""
    from fricli.core.errors import OptionError

    if isinstance(value, (str, bytes, os.PathLike)):
        return os.fsdecode(value)
    raise OptionError(f"{who}: {what} must be a file's path, not {type(value).__name__}", what)


def _kind(mode: int) -> str | None:
    """What a file that is not regular is, or None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_regular(path: str, error: type[Exception], missing: str, folder: str) -> None:
    """``error`` unless ``path`` is a regular file (following symbolic links)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise error(f"{path}: no such {missing}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{path}: is a folder, not a {folder}")
    kind = _kind(st.st_mode)
    if kind is not None:
        raise error(f"{path}: is {kind}, not a regular file; fricli reads a {folder} only from a regular "
                    "file (or - for stdin)")


def read_stream(fh, name: str, error: type[Exception], limit: int) -> bytes:
    """Everything ``fh`` holds, in chunks; ``error`` once it holds more than ``limit`` bytes."""
    parts, size = [], 0
    while True:
        chunk = fh.read(min(CHUNK, limit + 1 - size))
        if not chunk:
            return b"".join(parts)
        parts.append(chunk)
        size += len(chunk)
        if size > limit:
            raise error(f"{name}: more than {limit:,} bytes on stdin (the limit); write the input to a file "
                        "and give its path")


def read_bytes(path: str, error: type[Exception], missing: str, folder: str) -> bytes:
    """The bytes of the regular file ``path``; ``error`` (a FricliError) with "no such ``missing``",
    "is a folder, not a ``folder``", "is a device / a named pipe" or the system's reason when it
    cannot be read. The file is read up to the size it had when opened (a file that grows while
    it is read is not followed without end)."""
    check_regular(path, error, missing, folder)
    try:
        # O_NONBLOCK: a FIFO put in the path's place after the check does not block the open
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise error(f"{path}: no such {missing}") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, not a {folder}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
    try:
        st = os.fstat(fd)
        kind = _kind(st.st_mode)
        if stat.S_ISDIR(st.st_mode):
            raise error(f"{path}: is a folder, not a {folder}")
        if kind is not None:
            raise error(f"{path}: is {kind}, not a regular file; fricli reads a {folder} only from a regular "
                        "file (or - for stdin)")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=True) as fh:
            fd = -1
            parts, size = [], 0
            while size < st.st_size:
                chunk = fh.read(min(CHUNK, st.st_size - size))
                if not chunk:
                    break
                parts.append(chunk)
                size += len(chunk)
            return b"".join(parts)
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
    finally:
        if fd >= 0:
            os.close(fd)


def read_stdin(error: type[Exception], limit: int | None = None) -> bytes:
    """stdin's bytes, in chunks, up to ``limit`` (default ``STDIN_LIMIT``)."""
    import sys

    return read_stream(sys.stdin.buffer, "stdin", error, STDIN_LIMIT if limit is None else limit)
