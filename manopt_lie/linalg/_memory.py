"""Freed heap memory handed back to the operating system after a large symbolic analysis.

CHOLMOD's analysis (through CVXOPT: the triplet build of the lower triangle, CVXOPT's packed
copy of it, CHOLMOD's permuted patterns) frees tens of MB of transients that glibc's
``malloc`` keeps in its heap: later allocations of other sizes do not fit in them, so the
resident set and its peak grow by them for the rest of the solve. ``malloc_trim(0)`` returns
them (LM's peak resident set, ``benchmarks/bench_scaling.py``'s worker: grid2d-316 318 → 303 MB,
cube-46 1238 → 1199 MB; 3 ms per call on grid2d-316, no slower solves). It only releases
free pages; on platforms without glibc it is absent and nothing happens.
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Callable

__all__ = ["TRIM_ENTRIES", "release_freed_memory"]

TRIM_ENTRIES = 1 << 20
"""Analyses of patterns with at least this many entries in the lower triangle trim the heap.
Below, the pages handed back cost more to fault in again than they save: cube-22
(6.8·10⁵ entries) solved 5 % slower with the trim, its peak unchanged (126 MB); grid2d-316
(1.6·10⁶) and cube-46 (6.2·10⁶) within ±1.5 % of their time without it."""


def _malloc_trim() -> Callable[[int], int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim  # glibc's, in the process's own symbols
    except (OSError, AttributeError):  # not glibc (e.g. musl)
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim  # type: ignore[no-any-return]


_TRIM = _malloc_trim()


def release_freed_memory() -> bool:
    """Return the heap's free pages to the operating system; whether any were returned."""
    return bool(_TRIM(0)) if _TRIM is not None else False
