"""Pin numpy's BLAS to one thread while training.

The network's matrix products are small (30 x 31 x n). OpenBLAS's own threads cost more than
they bring at these shapes, and they would compete with the two worker threads that the
training loop runs over column chunks. ``single_threaded()`` sets OpenBLAS (as bundled with
numpy) to one thread and restores the previous count afterwards; with another BLAS it does
nothing. Results do not depend on it: OpenBLAS does not split the reduction dimension.
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
import threading

import numpy as np

_lock = threading.Lock()
_funcs: tuple | None = None
_depth = 0
_saved = None


def _openblas():
    """(get, set) thread-count functions of numpy's bundled OpenBLAS, or None."""
    global _funcs
    if _funcs is not None:
        return _funcs or None
    _funcs = ()
    root = os.path.dirname(np.__file__)
    candidates = glob.glob(os.path.join(root, os.pardir, "numpy.libs", "*openblas*"))
    candidates += glob.glob(os.path.join(root, ".dylibs", "*openblas*"))
    for path in candidates:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix, suffix in (("scipy_openblas", "64_"), ("scipy_openblas", ""), ("openblas", "")):
            try:
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}")
                set_ = getattr(lib, f"{prefix}_set_num_threads{suffix}")
            except AttributeError:
                continue
            get.restype, get.argtypes = ctypes.c_int, []
            set_.restype, set_.argtypes = None, [ctypes.c_int]
            _funcs = (get, set_)
            return _funcs
    return None


@contextlib.contextmanager
def single_threaded():
    """Run the block with numpy's OpenBLAS on one thread (re-entrant)."""
    global _depth, _saved
    funcs = _openblas()
    if funcs is None:
        yield
        return
    get, set_ = funcs
    with _lock:
        if _depth == 0:
            _saved = get()
            set_(1)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _saved:
                set_(_saved)
