"""BLAS threads: run small dense linear algebra on one OpenBLAS thread.

Bundle adjustment at the workbook's sizes makes many small BLAS calls (vector norms in LSMR, a 200×200
Cholesky): threads only add synchronisation, and numpy's and scipy's two OpenBLAS thread pools spinning against
each other on a busy 2-core machine slow the solvers down several times (see the README's note on BLAS threads).
Both bundle-adjustment solvers run inside :func:`single_threaded_blas`.
"""
import contextlib
import ctypes
import functools
import sys

_BLAS_NAMES = [("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
               ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
               ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
               ("openblas_get_num_threads", "openblas_set_num_threads")]


def _openblas_controls():
    """(get, set) thread-count functions of every OpenBLAS loaded in this process (Linux; else empty).

    Looked up again only when modules were imported since the last look (reading the process's memory map and
    opening the libraries cost about a millisecond: too much for the many small solves of SfM)."""
    return _openblas_controls_cached(len(sys.modules))


@functools.lru_cache(maxsize=1)
def _openblas_controls_cached(_n_modules):
    try:
        with open("/proc/self/maps") as f:
            paths = sorted({line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line})
    except OSError:
        return []
    controls = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get, set_ in _BLAS_NAMES:
            if hasattr(lib, get) and hasattr(lib, set_):
                controls.append((getattr(lib, get), getattr(lib, set_)))
                break
    return controls


@contextlib.contextmanager
def single_threaded_blas():
    """Run a block with every loaded OpenBLAS (numpy's and scipy's copies) on one thread, then restore.

    A no-op where OpenBLAS is not found (other BLAS, other systems); ``OPENBLAS_NUM_THREADS=1`` does the same
    globally.

    >>> with single_threaded_blas():
    ...     pass
    """
    controls = _openblas_controls()
    old = [get() for get, _ in controls]
    for _, set_ in controls:
        set_(1)
    try:
        yield
    finally:
        for (_, set_), n in zip(controls, old):
            set_(n)

