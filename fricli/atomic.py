"""Atomic output: write to a temporary file beside the target, fsync, then ``os.replace``.

A killed or failed job leaves the previous file untouched and no temporary file behind
(except after SIGKILL, where the ``.NAME.*.tmp`` file is removed by the next run).
"""

from __future__ import annotations

import contextlib
import glob
import os
import sys
import tempfile
from typing import BinaryIO, Callable, Iterator

from fricli.errors import OutputError


def _stale_temps(path: str) -> list[str]:
    folder, name = os.path.split(os.path.abspath(path))
    return glob.glob(os.path.join(folder, f".{glob.escape(name)}.*.tmp"))


@contextlib.contextmanager
def atomic_open(path: str) -> Iterator[BinaryIO]:
    """Open ``path`` for binary writing; the file appears only if the block succeeds.

    ``path == "-"`` yields stdout's binary buffer instead.
    """
    if path == "-":
        yield sys.stdout.buffer
        sys.stdout.buffer.flush()
        return
    folder, name = os.path.split(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {path}: folder {folder} does not exist")
    for stale in _stale_temps(path):  # left by a job killed with SIGKILL
        with contextlib.suppress(OSError):
            os.unlink(stale)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror}") from exc
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs get the usual permissions
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    with contextlib.suppress(OSError):  # make the rename itself durable
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def atomic_write_bytes(path: str, data: bytes) -> None:
    with atomic_open(path) as fh:
        fh.write(data)


def atomic_write_with(path: str, writer: Callable[[BinaryIO], None]) -> None:
    with atomic_open(path) as fh:
        writer(fh)
