"""One computation in a forked child process while this process runs another.

Two trainings in two threads of one process share its interpreter lock: a training step is a
hundred short numpy calls, each of which gives the lock up and waits for it again, and two
such loops slow each other down by half (measured: docs/studies/performance.md). In two processes they
run at full speed on two cores. ``beside`` forks (Linux only; elsewhere, and where
``AVAILABLE`` is off, both run on threads of this process), and the child sends its result back
as JSON and numpy arrays through a temporary file (``np.savez``, read with
``allow_pickle=False``): nothing is pickled.

The child ends with ``os._exit``: it never runs this process's cleanup, and it closes every
file it inherited but standard input, output and error (so a lock this process holds goes with
it). It takes the default action on SIGINT and SIGTERM, and a trainer in it stops at its next step
once its parent is gone (``Orphaned``). When ``here`` raises (an error, Ctrl-C, SIGTERM), the child is killed and
reaped before the exception goes on.
"""

from __future__ import annotations

import io
import json
import mmap
import os
import signal
import sys
import tempfile
import warnings
from typing import Callable, TypeVar

import numpy as np

from fricli.core import errors

AVAILABLE = sys.platform.startswith("linux")
T = TypeVar("T")
_PARAMS, _ERROR = "__params__", "__error__"


def _text(obj) -> np.ndarray:
    return np.frombuffer(json.dumps(obj).encode(), dtype=np.uint8)


def _child(there: Callable, out) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)
    # the parent's files stay the parent's: a lock it holds (fricli.core.jobs, atomic) is
    # released when it ends, whatever the child is doing then
    keep = out.fileno()
    os.closerange(3, keep)
    os.closerange(keep + 1, os.sysconf("SC_OPEN_MAX"))
    try:
        params, arrays = there()
        payload = {**arrays, _PARAMS: _text(params)}
    except BaseException as exc:   # handed to the parent, which raises it
        payload = {_ERROR: _text([type(exc).__name__, str(exc)])}
    buf = io.BytesIO()
    np.savez(buf, **payload)
    out.write(buf.getvalue())
    out.flush()


def _raise_from(name: str, message: str) -> None:
    cls = getattr(errors, name, None)
    if isinstance(cls, type) and issubclass(cls, errors.FricliError):
        raise cls(message)
    raise RuntimeError(f"the computation in the child process failed: {name}: {message}")


def beside(there: Callable[[], tuple[dict, dict[str, np.ndarray]]], here: Callable[[], T]
           ) -> tuple[tuple[dict, dict[str, np.ndarray]], T]:
    """Run ``there`` in a forked child and ``here`` in this process, at the same time.

    ``there`` returns (params, arrays): a JSON-serialisable dict and numpy arrays (no object
    dtype). Returns (what ``there`` returned, what ``here`` returned). An exception of
    ``there`` is raised here once ``here`` has finished (fricli's own errors keep their class)."""
    with tempfile.TemporaryFile() as out:
        sys.stdout.flush()
        sys.stderr.flush()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)   # Python 3.12+: forking with threads
            pid = os.fork()
        if pid == 0:   # pragma: no cover - the child's coverage is not collected
            try:
                _child(there, out)
            finally:
                os._exit(0)
        try:
            result = here()
        except BaseException:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise
        _, status = os.waitpid(pid, 0)
        out.seek(0)
        data = out.read()
    if status != 0 or not data:
        raise RuntimeError(f"the computation in the child process ended without a result (status {status})")
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        arrays = {key: npz[key] for key in npz.files}
    if _ERROR in arrays:
        _raise_from(*json.loads(arrays[_ERROR].tobytes()))
    params = json.loads(arrays.pop(_PARAMS).tobytes())
    return (params, arrays), result


class Orphaned:
    """``is_set()`` once the process ``parent`` (a pid taken before forking) is no longer this
    one's parent: a ``threading.Event``-like stop for a trainer in the child, checked every step."""

    def __init__(self, parent: int):
        self.parent = parent

    def is_set(self) -> bool:
        return os.getppid() != self.parent


def shared_zeros(n: int, dtype=np.int64) -> np.ndarray:
    """n zeros of ``dtype`` (8 bytes each) in memory that a child forked afterwards shares with this process."""
    return np.frombuffer(mmap.mmap(-1, 8 * max(n, 1)), dtype=dtype)[:n]
