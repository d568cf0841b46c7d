"""Unattended jobs: a lock per output file, and skipping work whose input has not changed."""

from __future__ import annotations

import contextlib
import fcntl
import os
from typing import Iterator

from fricli import modelfile
from fricli.errors import FricliError, LockedError, OutputError


@contextlib.contextmanager
def output_lock(path: str) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (via ``.NAME.lock`` beside it) or raise LockedError.

    The lock is released when the block ends or the process dies; the small lock file stays.
    """
    if path == "-":
        yield
        return
    folder, name = os.path.split(os.path.abspath(path))
    lock_path = os.path.join(folder, f".{name}.lock")
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise LockedError(f"{path} is being written by another fricli job") from None
        yield
    finally:
        os.close(fd)


def up_to_date(model_path: str, log_sha256: str, options: dict) -> bool:
    """True when ``model_path`` is a fricli model made from the same log bytes and options."""
    if model_path == "-" or not os.path.exists(model_path):
        return False
    try:
        meta, _ = modelfile.read(model_path)
    except FricliError:
        return False
    prov = meta.get("provenance", {})
    return prov.get("log_sha256") == log_sha256 and prov.get("options") == options
