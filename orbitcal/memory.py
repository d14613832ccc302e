"""Keep the C heap from holding on to freed arrays (glibc ``malloc``).

glibc serves an allocation above its *mmap threshold* with a mapping of its own, unmapped again
when freed; below it, from the heap, which is returned to the system only from its top. The
threshold starts at 128 kB and, by default, rises to the size of every mapped block freed (up
to 32 MB): after the first few arrays of a diagnosis are freed, arrays of a few MB come from the
heap, and the heap then keeps their pages when the arrays around them are still alive (on the
one-day world ~170 MB of the peak resident memory was such freed heap).
:func:`release_freed_arrays` fixes the threshold at :data:`MMAP_THRESHOLD_BYTES` (which stops the
rise) so that freed arrays are returned at once. No effect off glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

__all__ = ["MMAP_THRESHOLD_BYTES", "release_freed_arrays", "trim_heap"]

#: Allocations of at least this size are mapped on their own and unmapped when freed [bytes].
MMAP_THRESHOLD_BYTES = 4 * 1024 * 1024

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


@functools.cache
def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return ctypes.CDLL(name)
    except OSError:
        return None


def trim_heap() -> None:
    """Give freed memory back to the system now: pyarrow's pool (mimalloc keeps what a CSV read
    used: 330 MB after reading a week at 1 Hz) and glibc's heap (``malloc_trim``)."""
    import sys

    pa = sys.modules.get("pyarrow")
    if pa is not None:
        pa.default_memory_pool().release_unused()
    libc = _libc()
    trim = getattr(libc, "malloc_trim", None)
    if trim is not None:
        trim.argtypes = [ctypes.c_size_t]
        trim(0)


@functools.cache
def release_freed_arrays() -> bool:
    """Fix glibc's mmap threshold (and trim threshold) for this process; True if applied."""
    mallopt = getattr(_libc(), "mallopt", None)
    if mallopt is None:
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
    ok &= mallopt(_M_TRIM_THRESHOLD, 2 * MMAP_THRESHOLD_BYTES) == 1
    return bool(ok)
