"""BLAS thread pinning: ``single_threaded()`` runs a block with every loaded BLAS on one thread.

Two reasons. A fit must give the same bytes whatever OMP_NUM_THREADS says: threaded BLAS
reductions round differently for each thread count. And the network's matrix products are
small (30 x 31 x n): BLAS threads cost more than they bring at these shapes and would compete
with the training loop's two worker threads.

The limits go through threadpoolctl, which finds the BLAS libraries actually loaded (numpy's
and scipy's OpenBLAS, MKL, BLIS, FlexiBLAS) whatever their symbol names, and restores their
thread counts afterwards. Apple's Accelerate offers no thread control and is not listed by it.
A library loaded inside a block is not pinned: import it (scipy) before entering one.
The OpenBLAS numpy ships (0.3.31) ignores a count set from another thread once the main thread
has set one: fricli opens these blocks from the thread that runs the command.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Iterator

import threadpoolctl

_lock = threading.Lock()
_depth = 0
_limiter: threadpoolctl.threadpool_limits | None = None


@contextlib.contextmanager
def single_threaded() -> Iterator[None]:
    """Run the block with the loaded BLAS libraries on one thread each.

    Re-entrant and shared between threads: the limit is set when the first block opens and
    lifted when the last one closes, so a thread that leaves early does not restore the
    count under another that is still running."""
    global _depth, _limiter
    with _lock:
        if _depth == 0:
            _limiter = threadpoolctl.threadpool_limits(limits=1, user_api="blas")
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _limiter is not None:
                _limiter.restore_original_limits()
                _limiter = None


def blas_threads() -> dict[str, int]:
    """Thread count of each loaded BLAS library, by file path."""
    return {lib["filepath"]: int(lib["num_threads"]) for lib in threadpoolctl.threadpool_info()
            if lib["user_api"] == "blas"}


def pinned(func):
    """``func`` run inside ``single_threaded()``, with scipy's linear algebra and optimisers
    loaded first (a library loaded inside the block would not be pinned)."""
    import functools

    @functools.wraps(func)
    def run(*args, **kwargs):
        import scipy.linalg  # noqa: F401
        import scipy.optimize  # noqa: F401

        with single_threaded():
            return func(*args, **kwargs)
    return run
