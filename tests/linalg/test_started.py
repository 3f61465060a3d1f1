"""A structure built on the worker thread while a problem evaluates its first residuals
(``BlockStructure._shared_later``, ``early.c: early_start`` given the build): the arrays and the
analysis of the structure built here, pooled as :meth:`~BlockStructure.shared` pools, refused
edges raising as the constructor does, and safe after a fork, from threads and when dropped
unfinished."""

from __future__ import annotations

import multiprocessing
import threading

import numpy as np
import pytest

from manopt_lie.linalg import BlockStructure, _amd, _patterns, clear_caches
from manopt_lie.linalg._analyses import STRUCTURES

from .helpers import assert_same_structure, in_threads, structure_arrays
from .test_early import assert_same, expected

pytestmark = [
    pytest.mark.skipif(_patterns._library() is None, reason="no C compiler here"),
    pytest.mark.skipif(_amd.amd_order_address() is None, reason="AMD cannot be called directly here"),
]


@pytest.fixture(autouse=True)
def _empty_pools():
    clear_caches()
    yield
    clear_caches()


def graph(seed: int, n: int, d: int, repeats: bool) -> tuple[np.ndarray, list[tuple[np.ndarray, int]]]:
    """A chain of ``n`` variables of dimension ``d`` with chords and a unary factor type; ``repeats``:
    some chords again, one reversed (edges joining the same variables: ``H`` below its room)."""
    rng = np.random.default_rng(seed)
    chords = rng.choice(n, size=(min(n // 4, 60), 2))
    chain = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    edges = np.concatenate([chain, chords[chords[:, 0] != chords[:, 1]]])
    if repeats:
        edges = np.concatenate([edges, edges[-3:], edges[-1:, ::-1]])
    return np.full(n, d), [(edges, d), (rng.choice(n, size=(5, 1)), 2 * d)]


def started(dims: np.ndarray, factors: list[tuple[np.ndarray, int]]) -> BlockStructure:
    """A structure whose build is running on the worker (checked), unfinished."""
    S = BlockStructure._started(dims, factors, False)
    assert S is not None and S._build is not None
    return S


@pytest.mark.parametrize(("d", "n", "repeats"), [(3, 300, False), (3, 300, True), (6, 120, True), (1, 40, True)])
def test_a_structure_built_on_the_worker_is_the_one_built_here(d, n, repeats):
    """The same index arrays, entry for entry, and the same early analysis as the analysis made when
    asked (the triangle sized from the room, cut to its entries)."""
    dims, factors = graph(n, n, d, repeats)
    S = started(dims, factors)._finish()
    T = BlockStructure(dims, factors)
    assert S._build is None
    room = n * d * d + sum(f.m * (f.width**2 - sum(w * w for w in f.slot_dims)) for f in T._factors)
    assert S.nnz < room or not repeats  # repeated pairs: the triangle made in the room is cut
    assert_same_structure(S, T)
    made = S._early_analysis()
    assert_same(made, expected(S))
    assert made.simplicial is not None and made.simplicial.triangle[1].size == (S.nnz + S.n) // 2


def test_the_pool_gets_a_started_structure_once_finished_and_starts_none_it_has(monkeypatch):
    """Nothing is pooled while the build runs; finished, it is pooled as :meth:`shared` would pool it
    (one miss), and a second problem of the graph starts no build and gets that structure."""
    dims, factors = graph(0, 200, 3, True)
    finish = BlockStructure._shared_later(dims, factors, False)
    assert len(STRUCTURES) == 0
    first = finish()
    assert (STRUCTURES.misses, STRUCTURES.hits, len(STRUCTURES)) == (1, 0, 1)
    assert_same_structure(first, BlockStructure(dims, factors))
    monkeypatch.setattr(BlockStructure, "_started", lambda *args: pytest.fail("started a pooled structure"))
    assert BlockStructure._shared_later(dims, factors, False)() is first
    assert BlockStructure.shared(dims, factors) is first and STRUCTURES.hits == 2


@pytest.mark.parametrize(
    ("edges", "dims", "match"),
    [
        ([[0, 1], [2, 2]], [3, 3, 3], r"factor 0, edge 1"),  # a variable twice
        ([[0, 1], [1, 7]], [3, 3, 3], r"factor 0, edge 1"),  # out of range
        ([[0, 1], [1, 2]], [3, 6, 3], r"factor 0"),  # mixed dimensions: refused before the worker
    ],
)
def test_refused_edges_raise_as_the_constructor_and_nothing_is_pooled(edges, dims, match):
    factors = [(np.array(edges), 3)]
    with pytest.raises(ValueError, match=match) as built_here:
        BlockStructure(dims, factors)
    with pytest.raises(ValueError, match=match) as built_there:
        BlockStructure._shared_later(np.array(dims), factors, False)()
    assert str(built_there.value) == str(built_here.value)
    assert len(STRUCTURES) == 0


def test_structures_dropped_unfinished_are_waited_for():
    """A started structure dropped before it is finished waits for the thread, which writes into its
    arrays, before they are freed (under a memory checker this would show as a write after free)."""
    for seed in range(30):
        started(*graph(seed, 400, 3, True))  # dropped at once
    dims, factors = graph(99, 400, 3, True)
    assert_same_structure(started(dims, factors)._finish(), BlockStructure(dims, factors))


def test_structures_started_from_several_threads():
    """Twenty structures started and finished from four threads at once (one worker runs the builds
    and analyses in turn): each is its own graph's."""
    made: list[tuple[BlockStructure, int]] = []
    lock = threading.Lock()

    def run(thread: int) -> None:
        for k in range(5):
            seed = 10 * thread + k
            S = started(*graph(seed, 50 + 20 * k, 3, k % 2 == 1))._finish()
            with lock:
                made.append((S, seed))

    in_threads(run, 4)
    assert len(made) == 20
    for S, seed in made:
        dims, factors = graph(seed, S.dims.size, 3, seed % 10 % 2 == 1)
        assert_same_structure(S, BlockStructure(dims, factors))
        assert_same(S._early_analysis(), expected(S))


def _child(S: BlockStructure, queue: multiprocessing.Queue) -> None:
    """In a forked child: the parent's build is not waited for; the child builds the structure itself."""
    S._finish()
    queue.put([a.tolist() for a in structure_arrays(S)] + [S._early_analysis().order is None])


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork here")
def test_a_forked_child_builds_a_started_structure_itself():
    dims, factors = graph(5, 20000, 3, True)
    S = started(dims, factors)  # maybe still queued or running when the child is forked
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_child, args=(S, queue))
    child.start()
    *made, parents_unread = queue.get(timeout=120)
    child.join(timeout=60)
    assert child.exitcode == 0
    T = BlockStructure(dims, factors)
    for a, b in zip(made, structure_arrays(T), strict=True):
        np.testing.assert_array_equal(a, b)
    assert parents_unread  # the analysis stayed in the parent: the child's solver makes its own
    S._finish()  # the parent's own, unharmed
    assert_same_structure(S, T)
    assert_same(S._early_analysis(), expected(S))


def test_a_build_the_busy_worker_has_not_taken_is_made_by_the_caller():
    """The worker busy with other structures' analyses: the caller, finishing first, builds the
    structure itself (``early_built``) and the worker then only analyses it; the same arrays and
    analysis either way."""
    busy = [started(*graph(seed, 20000, 3, False)) for seed in range(3)]  # queued ahead, ms each
    dims, factors = graph(7, 300, 3, True)
    S = started(dims, factors)._finish()
    assert_same_structure(S, BlockStructure(dims, factors))
    assert_same(S._early_analysis(), expected(S))
    for B in busy:
        assert_same_structure(B._finish(), BlockStructure(*graph(busy.index(B), 20000, 3, False)))
