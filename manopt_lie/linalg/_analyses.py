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

Patterns are keyed by ``(backend, n, nnz, index dtypes, SHA-256(indptr, indices))`` (for a
structure's own pattern, the structure's inputs instead: :class:`StructureInputs`). The pool keeps
at most :data:`MAX_IDLE` idle backends and :data:`MAX_IDLE_NNZ` stored entries of
``H`` in all (least recently returned dropped first): a big factor is not kept alive
for a pattern that may never come back.

A :class:`~manopt_lie.linalg.BlockStructure` (the pattern of ``H`` and the scatter maps that fill
it) depends only on the variables' dimensions and on each factor type's edges and residual
length, and nothing changes it once built, so :data:`STRUCTURES` shares one among every problem
of the same graph (keyed by its inputs), under the same bounds. :func:`clear_caches` empties
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

__all__ = ["ANALYSES", "STRUCTURES", "AnalysisPool", "StructureInputs", "StructurePool", "clear_caches", "pattern_key"]

MAX_IDLE = 8
MAX_IDLE_NNZ = 4_000_000

Key = tuple[str, int, int, str, "bytes | StructureInputs"]
V = TypeVar("V")


def digest(*arrays: NDArray[Any]) -> bytes:
    """The first 128 bits of a SHA-256 digest of the arrays' bytes (no copy of contiguous arrays).
    SHA-256, not BLAKE2b: with the CPU's SHA instructions (current x86 and ARM) it hashes 2.5×
    faster here (19 kB: 11 µs against 28 µs)."""
    h = hashlib.sha256()
    for a in arrays:
        # .data, not memoryview(...): NumPy's stubs give ndarray a __buffer__ on Python 3.12+ only.
        h.update(np.ascontiguousarray(a).data.cast("B"))
    return h.digest()[:16]


def pattern_key(
    backend: str, indptr: NDArray[np.signedinteger], indices: NDArray[np.signedinteger],
    inputs: StructureInputs | None = None,
) -> Key:  # fmt: skip
    """The pool's key of a CSC pattern: its sizes, index dtype and a digest of its arrays, or
    ``inputs``, the key of the structure whose own pattern it is (which determines it: no pass
    over its arrays; a digest of parking-garage's coordinates takes 1.6 ms)."""
    dtypes = f"{indptr.dtype.str}{indices.dtype.str}"
    key = digest(indptr, indices) if inputs is None else inputs
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


class StructureInputs:
    """What determines a block structure — the variables' dimensions, each factor type's edge array
    and residual length, the dense flag — as a key of the pools: hashed by the arrays' shapes and
    kinds alone, equal where every array is equal too (NumPy's comparison, made only against a key
    of the same hash). A cold solve's key costs ~2 µs instead of a digest of every edge (SHA-256:
    44 µs on CSAIL, 72 µs on intel, cold), a warm one's look-up a comparison at memory speed.

    Parameters
    ----------
    dims : ndarray of int, shape (n_vars,)
    factors : sequence of (var_ids, residual_dim)
        As :class:`~manopt_lie.linalg.BlockStructure`'s. The key holds the arrays, not copies: a
        pooled key holds its structure's own (read-only) arrays, a key for a look-up its caller's.
    dense : bool
    """

    __slots__ = ("_arrays", "_hash", "_shapes")

    def __init__(self, dims: NDArray[Any], factors: Sequence[tuple[NDArray[Any], int]], dense: bool) -> None:
        self._arrays = (dims, *(ids for ids, _ in factors))
        kinds = tuple((a.shape, a.dtype.kind) for a in self._arrays)
        self._shapes = (bool(dense), kinds, tuple(int(r) for _, r in factors))
        self._hash = hash(self._shapes)

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        if not isinstance(other, StructureInputs) or self._shapes != other._shapes:
            return False
        return all(a is b or np.array_equal(a, b) for a, b in zip(self._arrays, other._arrays, strict=True))


class StructurePool:
    """Built block structures by their inputs (:class:`StructureInputs`), shared (never lent:
    nothing writes to a built structure, and one structure serves many threads); thread-safe. At
    most ``max_kept`` structures with ``max_kept_nnz`` entries of ``H`` in all are kept, least
    recently used dropped first.

    Attributes
    ----------
    hits, misses : int
        Structures found in the pool, and structures built.
    """

    def __init__(self, max_kept: int = MAX_IDLE, max_kept_nnz: int = MAX_IDLE_NNZ) -> None:
        self.max_kept, self.max_kept_nnz = max_kept, max_kept_nnz
        self._kept: OrderedDict[StructureInputs, BlockStructure] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = self.misses = 0

    def get(self, key: StructureInputs, build: Callable[[], BlockStructure]) -> BlockStructure:
        """The structure of ``key``: the pooled one, else ``build()``'s, then pooled (if small
        enough) under its own key: the arrays of ``key`` are the caller's, which it may change."""
        with self._lock:
            found = self._kept.get(key)
            if found is not None:
                self._kept.move_to_end(found._inputs)  # the pooled key itself: found without comparing again
                self.hits += 1
                return found
            self.misses += 1
        built = build()  # outside the lock: a large structure takes seconds
        if built.nnz <= self.max_kept_nnz:
            with self._lock:
                self._kept[built._inputs] = built
                _evict_oldest(self._kept, lambda structure: structure.nnz, self.max_kept, self.max_kept_nnz)
        return built

    def __contains__(self, key: StructureInputs) -> bool:
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
