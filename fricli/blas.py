"""numpy's bundled OpenBLAS, called directly: its thread count and one banded solve.

``single_threaded()`` pins OpenBLAS to one thread for a block and restores the count
afterwards. The network's matrix products are small (30 x 31 x n): OpenBLAS's own threads cost
more than they bring at these shapes and would compete with the training loop's two worker
threads; and a fit must give the same bytes whatever OMP_NUM_THREADS says. Results do not
otherwise depend on it: OpenBLAS does not split the reduction dimension.

``recurrence(band, b)`` solves z[k] = a[k] z[k-1] + b[k] as a unit lower bidiagonal system with
BLAS ``dtbsv``, the same routine scipy.linalg.blas wraps, without importing scipy.linalg
(about a quarter of a second). With a numpy that bundles no OpenBLAS both fall back: one does
nothing, the other calls scipy.
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
import threading

import numpy as np

_lock = threading.Lock()
_lib: ctypes.CDLL | None | bool = False     # False: not looked for yet
_funcs: tuple | None = None
_tbsv = None
_depth = 0
_saved = None

# (prefix, suffix, integer type) of the symbol names in the OpenBLAS builds numpy has shipped
_NAMINGS = (("scipy_", "64_", ctypes.c_int64), ("scipy_", "", ctypes.c_int), ("", "64_", ctypes.c_int64),
            ("", "", ctypes.c_int))
_COL_MAJOR, _LOWER, _NO_TRANS, _UNIT = 102, 122, 111, 132     # CBLAS enum values


def _openblas_lib():
    """numpy's bundled OpenBLAS as a ctypes library, or None."""
    global _lib
    if _lib is False:
        _lib = None
        root = os.path.dirname(np.__file__)
        candidates = glob.glob(os.path.join(root, os.pardir, "numpy.libs", "*openblas*"))
        candidates += glob.glob(os.path.join(root, ".dylibs", "*openblas*"))
        for path in candidates:
            try:
                _lib = ctypes.CDLL(path)
                break
            except OSError:
                continue
    return _lib


def _symbol(name: str):
    """(function, integer type) of the OpenBLAS symbol for ``name``, or None."""
    lib = _openblas_lib()
    if lib is None:
        return None
    for prefix, suffix, int_type in _NAMINGS:
        try:
            return getattr(lib, f"{prefix}{name}{suffix}"), int_type
        except AttributeError:
            continue
    return None


def _openblas():
    """(get, set) thread-count functions of numpy's bundled OpenBLAS, or None."""
    global _funcs
    if _funcs is None:
        found = _symbol("openblas_get_num_threads"), _symbol("openblas_set_num_threads")
        _funcs = ()
        if all(found):
            (get, _), (set_, _) = found
            get.restype, get.argtypes = ctypes.c_int, []
            set_.restype, set_.argtypes = None, [ctypes.c_int]
            _funcs = (get, set_)
    return _funcs or None


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


def recurrence(band: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve z[k] = a[k] z[k-1] + b[k] (z[-1] = 0) in place in b (n,) float64, contiguous.

    band: (2, n) float64 in Fortran order, dtbsv's band storage of the unit lower bidiagonal
    matrix: band[1, k] = -a[k+1] for k < n-1 (row 0 and band[1, n-1] are not read). Returns b.
    """
    global _tbsv
    n = len(b)
    if _tbsv is None:
        found = _symbol("cblas_dtbsv")
        if found is None:
            _tbsv = ()
        else:
            fn, int_type = found
            fn.restype = None
            fn.argtypes = [ctypes.c_int] * 4 + [int_type] * 2 + [ctypes.c_void_p, int_type,
                                                                 ctypes.c_void_p, int_type]
            _tbsv = (fn,)
    if n == 0:
        return b
    if not _tbsv or not (b.flags.c_contiguous and band.flags.f_contiguous and b.dtype == band.dtype == np.float64):
        from scipy.linalg import blas as scipy_blas

        z = scipy_blas.dtbsv(1, band, b, lower=1, diag=1, overwrite_x=1)
        if not np.shares_memory(z, b):
            b[:] = z
        return b
    _tbsv[0](_COL_MAJOR, _LOWER, _NO_TRANS, _UNIT, n, 1, band.ctypes.data, 2, b.ctypes.data, 1)
    return b
