"""One thread for BLAS and OpenCV while gevi computes: results that do not depend on the machine's core
count or on what runs beside it, and timings that compare.

Every run path enters :func:`one_thread` (``gevi run`` and each batch run through
:func:`gevi_cli.run.session.execute`, :func:`gevi_cli.api.run`, ``gevi batch`` for its evaluation,
``gevi imu``).  It acts on the libraries already loaded, whenever numpy was imported (unlike the
``OPENBLAS_NUM_THREADS`` variables, read once when a library loads), and puts the previous counts back
on exit, so the API leaves its caller's process as it found it.
"""
from __future__ import annotations

from contextlib import contextmanager


@contextmanager
def one_thread():
    """Within the block: OpenCV's ``cv2.setNumThreads(1)`` and one thread in every BLAS/OpenMP library
    loaded (threadpoolctl; numpy's, scipy's and OpenCV's own OpenBLAS copies are loaded first, so that
    none escapes the limit by loading later)."""
    import cv2
    import numpy  # noqa: F401 - loads numpy's BLAS
    import scipy.linalg  # noqa: F401 - loads scipy's BLAS
    from threadpoolctl import threadpool_limits

    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        cv2.setNumThreads(before)
