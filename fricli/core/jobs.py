"""Unattended jobs: a lock per output file, and skipping work whose input has not changed."""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
from typing import Iterator

from fricli.core import modelfile
from fricli.core.errors import FricliError, LockedError, ModelFileError, OutputError


@contextlib.contextmanager
def output_lock(path: str) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (``flock`` on ``.NAME.lock`` beside it) or raise LockedError.

    The lock file is removed when the block ends. The kernel releases the lock when the process
    dies; a job killed with SIGKILL leaves the empty lock file, which the next job locks and removes.
    """
    if path == "-":
        yield
        return
    folder, name = os.path.split(os.path.abspath(path))
    lock_path = os.path.join(folder, f".{name}.lock")
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {path}: folder {folder} does not exist")
    while True:
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise LockedError(f"{path} is being written by another fricli job") from None
        # the previous holder may have removed the file between our open and flock: then the
        # lock is on a file nobody else can see, so open the current one again
        held = os.fstat(fd)
        try:
            current = os.stat(lock_path)
        except FileNotFoundError:
            current = None
        if current is not None and (current.st_dev, current.st_ino) == (held.st_dev, held.st_ino):
            break
        os.close(fd)
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock_path)  # still holding the lock, so no other job is using this file
        os.close(fd)


def file_sha256(path: str) -> str:
    """sha256 of a file's bytes (a model given as input); ModelFileError when unreadable."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot read ({exc.strerror})") from None
    return digest.hexdigest()


def job_record(command: str, options: dict, inputs: dict[str, str] | None = None) -> dict:
    """What made a model, stored as ``provenance.job``: the command, every option that shapes
    the result (JSON-normalised, so tuples become lists) and the sha256 of each input model
    file (``inputs``: name -> path)."""
    record = {"command": command, "options": json.loads(json.dumps(options, sort_keys=True, allow_nan=False)),
              "inputs": {name: file_sha256(path) for name, path in sorted((inputs or {}).items())}}
    return record


def up_to_date(model_path: str, log_sha256: str, job: dict) -> bool:
    """True when ``model_path`` is a fricli model made from the same log bytes by the same job
    (command, options and input models, see ``job_record``)."""
    if model_path == "-" or not os.path.exists(model_path):
        return False
    try:
        meta, _ = modelfile.read(model_path)
    except FricliError:
        return False
    prov = meta.get("provenance", {})
    return isinstance(prov, dict) and prov.get("log_sha256") == log_sha256 and prov.get("job") == job
