"""One BLAS thread for work made of many small products (the diagnosis's joint fits).

``threadpoolctl.threadpool_limits`` reaches only the BLAS libraries loaded when it is entered.
NumPy and SciPy each bring their own OpenBLAS (``libscipy_openblas64_`` and
``libscipy_openblas``); SciPy's is loaded on the first import of ``scipy.linalg``, which the
diagnosis does lazily, so a limit entered before it left SciPy's BLAS at one thread per core.
Its idle threads then spin beside the main one: on the day world of
``benchmarks/diagnose_timing.py``, with another job on the second core, the diagnosis took
22.2 s instead of 16.8 s (``OPENBLAS_NUM_THREADS`` 2 against 1, same run).
"""

from __future__ import annotations

from typing import Any

__all__ = ["one_blas_thread"]


def one_blas_thread() -> Any:
    """A context manager limiting every BLAS of the process (NumPy's and SciPy's) to one thread.

    SciPy's BLAS is loaded first, so that the limit reaches it.
    """
    import scipy.linalg  # noqa: F401 - loads SciPy's OpenBLAS before the limit is set
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1, user_api="blas")
