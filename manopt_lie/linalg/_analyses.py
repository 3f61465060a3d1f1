"""Symbolic work kept across problems and solvers: analysed backends pooled by the pattern they
analysed, and block structures by the graph they were built for.

The ordering and symbolic factorization of ``H`` depend on its pattern only, and a run
of Gauss-Newton or Levenberg-Marquardt builds a fresh :class:`CholeskySolver` (``bind``)
for every solve. Problems of the same pattern — the same graph solved again, from
another start, with another cost of the same blocks, by a benchmark's repeats — would
redo the analysis each time. A backend object holds its numeric factor as well, which
CHOLMOD (through CVXOPT) cannot copy, so the pool lends each analysed backend to one
solver at a time: a solver takes an idle backend of its pattern, or analyses anew, and
gives it back when it is garbage-collected or analyses another pattern. Concurrent
solvers of one pattern (threads) thus each get their own.

Patterns are keyed by ``(backend, n, nnz, index dtypes, BLAKE2b(indptr, indices))`` (for a
structure's own pattern, the digest of its blocks and their sizes instead). The pool keeps
at most :data:`MAX_IDLE` idle backends and :data:`MAX_IDLE_NNZ` stored entries of
``H`` in all (least recently returned dropped first): a big factor is not kept alive
for a pattern that may never come back.

A :class:`~manopt_lie.linalg.BlockStructure` (the pattern of ``H`` and the scatter maps that fill
it) depends only on the variables' dimensions and on each factor type's edges and residual
length, and nothing changes it once built, so :data:`STRUCTURES` shares one among every problem
of the same graph (:func:`structure_key`), under the same bounds. :func:`clear_caches` empties
both pools: the next solve of any pattern pays its whole set-up.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .structure import BlockStructure

__all__ = ["ANALYSES", "STRUCTURES", "AnalysisPool", "StructurePool", "clear_caches", "pattern_key", "structure_key"]

MAX_IDLE = 8
MAX_IDLE_NNZ = 4_000_000

Key = tuple[str, int, int, str, bytes]
V = TypeVar("V")


def digest(*arrays: NDArray[Any]) -> bytes:
    """The first 128 bits of a SHA-256 digest of the arrays' bytes (no copy of contiguous arrays).
    SHA-256, not BLAKE2b: with the CPU's SHA instructions (current x86 and ARM) it hashes 2.5×
    faster here (a pose graph's edges, 19 kB: 11 µs against 28 µs)."""
    h = hashlib.sha256()
    for a in arrays:
        # .data, not memoryview(...): NumPy's stubs give ndarray a __buffer__ on Python 3.12+ only.
        h.update(np.ascontiguousarray(a).data.cast("B"))
    return h.digest()[:16]


def pattern_key(
    backend: str, indptr: NDArray[np.signedinteger], indices: NDArray[np.signedinteger], blocks: bytes | None = None
) -> Key:
    """The pool's key of a CSC pattern: its sizes, index dtype and a digest of its arrays, or
    ``blocks``, the digest of the blocks it expands (``BlockStructure.pattern_digest``: ``d²``
    times fewer bytes to hash; 1.6 ms → 0.05 ms on parking-garage)."""
    dtypes = f"{indptr.dtype.str}{indices.dtype.str}"
    key = digest(indptr, indices) if blocks is None else blocks
    return backend, int(indptr.size - 1), int(indices.size), dtypes, key


def _evict_oldest(entries: OrderedDict[Any, V], nnz: Callable[[V], int], max_count: int, max_nnz: int) -> None:
    """Drop the oldest entries until at most ``max_count`` remain holding ``max_nnz`` entries of ``H`` in all."""
    while len(entries) > max_count or sum(nnz(v) for v in entries.values()) > max_nnz:
        entries.popitem(last=False)


class AnalysisPool:
    """Idle analysed backends by pattern key; thread-safe.

    Attributes
    ----------
    hits, misses : int
        Analyses taken from the pool, and analyses the pool could not provide.
    """

    def __init__(self, max_idle: int = MAX_IDLE, max_idle_nnz: int = MAX_IDLE_NNZ) -> None:
        self.max_idle, self.max_idle_nnz = max_idle, max_idle_nnz
        self._idle: OrderedDict[int, tuple[Key, Any]] = OrderedDict()
        self._lock = threading.Lock()
        self._ticket = 0
        self.hits = self.misses = 0

    def acquire(self, key: Key) -> Any | None:
        """An idle backend of ``key`` (the most recently returned), now lent out, or ``None``."""
        with self._lock:
            for ticket in reversed(self._idle):
                if self._idle[ticket][0] == key:
                    self.hits += 1
                    return self._idle.pop(ticket)[1]
            self.misses += 1
            return None

    def release(self, key: Key, backend: Any) -> None:
        """Take ``backend`` (analysed for ``key``) back, dropping the oldest idle ones past the bounds."""
        if key[2] > self.max_idle_nnz:
            return
        with self._lock:
            self._ticket += 1
            self._idle[self._ticket] = (key, backend)
            _evict_oldest(self._idle, lambda entry: entry[0][2], self.max_idle, self.max_idle_nnz)

    def clear(self) -> None:
        """Drop every idle backend (and reset the counters)."""
        with self._lock:
            self._idle.clear()
            self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._idle)


ANALYSES = AnalysisPool()
"""The process's pool, used by every :class:`~manopt_lie.linalg.CholeskySolver`."""


def structure_key(dims: NDArray[np.integer], factors: Sequence[tuple[NDArray[np.integer], int]], dense: bool) -> bytes:
    """The key of a block structure's inputs: the variables' dimensions, every factor type's edge
    array (shape and dtype included) and residual length, and whether ``H`` is stored dense."""
    shapes = repr([(ids.shape, ids.dtype.str, int(r)) for ids, r in factors] + [dims.shape, dims.dtype.str, dense])
    return digest(dims, *(ids for ids, _ in factors)) + shapes.encode()


class StructurePool:
    """Built block structures by :func:`structure_key`, shared (never lent: nothing writes to a
    built structure, and one structure serves many threads); thread-safe. At most ``max_kept``
    structures with ``max_kept_nnz`` entries of ``H`` in all are kept, least recently used
    dropped first.

    Attributes
    ----------
    hits, misses : int
        Structures found in the pool, and structures built.
    """

    def __init__(self, max_kept: int = MAX_IDLE, max_kept_nnz: int = MAX_IDLE_NNZ) -> None:
        self.max_kept, self.max_kept_nnz = max_kept, max_kept_nnz
        self._kept: OrderedDict[bytes, BlockStructure] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = self.misses = 0

    def get(self, key: bytes, build: Callable[[], BlockStructure]) -> BlockStructure:
        """The structure of ``key``: the pooled one, else ``build()``'s (then pooled if small enough)."""
        with self._lock:
            found = self._kept.get(key)
            if found is not None:
                self._kept.move_to_end(key)
                self.hits += 1
                return found
            self.misses += 1
        built = build()  # outside the lock: a large structure takes seconds
        if built.nnz <= self.max_kept_nnz:
            with self._lock:
                self._kept[key] = built
                _evict_oldest(self._kept, lambda structure: structure.nnz, self.max_kept, self.max_kept_nnz)
        return built

    def __contains__(self, key: bytes) -> bool:
        """Whether a structure of ``key`` is kept (counted neither a hit nor a miss)."""
        with self._lock:
            return key in self._kept

    def clear(self) -> None:
        """Drop every structure (and reset the counters)."""
        with self._lock:
            self._kept.clear()
            self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._kept)


STRUCTURES = StructurePool()
"""The process's pool, used by every :class:`~manopt_lie.optim.LeastSquaresProblem`."""


def clear_caches() -> None:
    """Forget every pooled analysis and structure: the next solve of any pattern builds its
    structure and analyses its pattern anew (a benchmark's cold start, as a peer's)."""
    ANALYSES.clear()
    STRUCTURES.clear()
