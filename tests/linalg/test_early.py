"""A structure's analysis started on a thread at construction (``linalg._early``, ``patterns.c:
early_start``): the same order, symbolic factorization and triangle as the analysis makes when asked,
the same factor and solves; nothing where it should not run; safe from several threads, after a
fork, and when dropped unread."""

from __future__ import annotations

import multiprocessing
import threading

import numpy as np
import pytest

from manopt_lie.linalg import BlockStructure, CholeskySolver, _amd, _cholmod, _early, _patterns, clear_caches

from .helpers import in_threads, pose_graph, random_factor_graph

pytestmark = [
    pytest.mark.skipif(_patterns._library() is None, reason="no C compiler here"),
    pytest.mark.skipif(_amd.amd_order_address() is None, reason="AMD cannot be called directly here"),
]


def chain_with_chords(n: int, d: int, chords: int, rng: np.random.Generator) -> BlockStructure:
    """A pose-graph-like pattern: a chain of ``n`` variables of dimension ``d`` and random chords."""
    chain = [(i, i + 1) for i in range(n - 1)]
    edges = np.array(chain + [tuple(rng.choice(n, 2, replace=False)) for _ in range(chords)])
    return BlockStructure(np.full(n, d), [(edges, d)])


def expected(S: BlockStructure) -> _early.Analysis:
    """The analysis made when asked, step by step: AMD, the variables' symbolic factorization, and
    ``B``'s simplicial factor as ``Cholmod._analyze_blocks`` and ``_expand`` make it."""
    order = _amd.variable_order(*S.block_pattern)
    symbolic = _patterns.block_symbolic(*S.block_pattern, order)
    assert symbolic is not None
    variables, counts = symbolic
    d, nv = int(S.dims[0]), S.dims.size
    lnz_b, fl_b = float(counts.sum()), float(np.dot(counts, counts))
    lnz = d * d * lnz_b - nv * d * (d - 1) / 2
    fl = d**3 * fl_b - d * d * (d - 1) * lnz_b + nv * (d - 1) * d * (2 * d - 1) / 6
    columns = (d * counts[:, None] - np.arange(d)).astype(np.int32).ravel()
    made = _patterns.permuted_block_triangle(S.indptr, S.dims, *S.block_pattern, variables, upper=True)
    assert made is not None
    return _early.Analysis(order, symbolic, _early.Simplicial((lnz, fl), columns, *made))


def assert_same(made: _early.Analysis, wanted: _early.Analysis, simplicial: bool = True) -> None:
    np.testing.assert_array_equal(made.order, wanted.order)
    assert made.symbolic is not None and wanted.symbolic is not None
    for a, b in zip(made.symbolic, wanted.symbolic, strict=True):
        np.testing.assert_array_equal(a, b)
    if not simplicial:
        assert made.simplicial is None
        return
    assert made.simplicial is not None and wanted.simplicial is not None
    assert made.simplicial.cost == wanted.simplicial.cost  # the same sums in the same order: bit for bit
    pairs = [(made.simplicial.column_counts, wanted.simplicial.column_counts)]
    pairs += zip(made.simplicial.triangle, wanted.simplicial.triangle, strict=True)
    for a, b in pairs:
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(made.simplicial.perm, wanted.simplicial.perm)


@pytest.mark.parametrize(("d", "n", "chords"), [(3, 300, 40), (6, 200, 30), (2, 5, 0), (1, 1, 0)])
def test_the_early_analysis_is_the_analysis_made_when_asked(rng, d, n, chords):
    """Order, postordered variables and their counts, ``B``'s cost and column counts, its upper
    triangle and ``P``: the same numbers as the analysis makes when asked."""
    S = chain_with_chords(n, d, chords, rng) if n > 1 else BlockStructure([d], [(np.zeros((1, 1), int), d)])
    assert S._early is not None
    made = S._early_analysis()
    if n == 1:
        np.testing.assert_array_equal(made.order, [0])
        return
    assert_same(made, expected(S))
    assert S.variable_ordering() is made.order
    assert S._early_analysis() is made  # joined once


def test_a_supernodal_pattern_gets_no_early_simplicial_factor(rng):
    """Where CHOLMOD's default choice is supernodal (flops per entry of ``L`` past its switch), ``B``'s
    factor is CHOLMOD's and its triangle the other one in another order: only the order and the
    variables' symbolic are made."""
    n = 60
    edges = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.5])
    S = BlockStructure(np.full(n, 6), [(edges, 6)])
    made = S._early_analysis()
    assert_same(made, expected(S), simplicial=False)
    factor = _cholmod.Cholmod(S.indptr, S.indices, None, None, (S.dims, *S.block_pattern),
                              variables=S.variable_ordering(), early=made)  # fmt: skip
    assert factor.supernodal


def test_past_the_budget_the_symbolic_and_triangle_are_left_to_the_analysis(monkeypatch, rng):
    monkeypatch.setattr(_patterns, "SIMPLICIAL_FILL", 0)
    S = chain_with_chords(80, 3, 20, rng)
    made = S._early_analysis()
    np.testing.assert_array_equal(made.order, _amd.variable_order(*S.block_pattern))
    assert made.symbolic is None and made.simplicial is None


def test_no_early_analysis_where_it_should_not_run(monkeypatch, rng):
    """Mixed dimensions, past ``EARLY_ENTRIES``, without AMD or compiled code: none is started, and
    the structure orders its variables as before."""
    dims, factors = random_factor_graph(rng, n_vars=30)
    assert len(set(dims.tolist())) > 1
    S = BlockStructure(dims, factors)
    assert S._early is None and S._early_analysis() is None
    np.testing.assert_array_equal(S.variable_ordering(), _amd.variable_order(*S.block_pattern))
    monkeypatch.setattr(_early, "EARLY_ENTRIES", 100)
    assert chain_with_chords(50, 3, 5, rng)._early is None
    monkeypatch.undo()
    monkeypatch.setattr(_amd, "amd_order_address", lambda: None)
    assert chain_with_chords(50, 3, 5, rng)._early is None


@pytest.mark.parametrize("supernodal", [None, False, True], ids=["auto", "simplicial", "supernodal"])
def test_a_solve_with_the_early_analysis_is_the_solve_without(monkeypatch, rng, supernodal):
    """The same kind, cost, order and solution as a solver whose structure started nothing."""
    results = []
    for start in (_early.EarlyAnalysis.start, lambda *args: None):
        monkeypatch.setattr(_early.EarlyAnalysis, "start", start)
        clear_caches()
        S, blocks, residuals = pose_graph(np.random.default_rng(7), n_poses=150, d=3)
        assert (S._early is not None) == (start is not _early.EarlyAnalysis.start or len(results) == 0)
        H, g = S.normal_equations(blocks, residuals)
        solver = CholeskySolver(supernodal=supernodal).bind(S)
        x = solver(H, -g)
        impl = solver._impl
        results.append((x, impl.supernodal, impl.cost, impl.permutation()))
    clear_caches()
    (x1, kind1, cost1, perm1), (x2, kind2, cost2, perm2) = results
    assert kind1 == kind2 and cost1 == cost2
    np.testing.assert_array_equal(perm1, perm2)
    np.testing.assert_allclose(x1, x2, rtol=1e-12, atol=1e-14)


def test_many_analyses_from_several_threads(rng):
    """Twenty structures started from four threads at once (one worker runs them in turn): each
    analysis is its own pattern's."""
    structures: list[BlockStructure] = []
    lock = threading.Lock()

    def build(seed: int) -> None:
        local = np.random.default_rng(seed)
        made = [chain_with_chords(int(local.integers(20, 120)), 3, 10, local) for _ in range(5)]
        with lock:
            structures.extend(made)

    in_threads(build, 4)
    assert len(structures) == 20
    for S in structures:
        assert_same(S._early_analysis(), expected(S))


def test_dropped_unread_the_analysis_is_waited_for():
    """A structure dropped before its analysis is read waits for the thread, which writes into its
    arrays, before they are freed (under a memory checker this would show as a write after free)."""
    rng = np.random.default_rng(3)
    for _ in range(30):
        chain_with_chords(400, 3, 80, rng)  # dropped at once
    S = chain_with_chords(400, 3, 80, rng)
    assert_same(S._early_analysis(), expected(S))


def _child(S: BlockStructure, queue: multiprocessing.Queue) -> None:
    """In a forked child: the parent's analysis is not waited for, the child's own is made."""
    made = S._early_analysis()
    fresh = chain_with_chords(60, 3, 10, np.random.default_rng(5))
    queue.put((made.order is None, S.variable_ordering().tolist(), fresh._early_analysis().order.tolist()))


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork here")
def test_a_forked_child_makes_its_own_analysis(rng):
    S = chain_with_chords(5000, 3, 50, rng)  # started, maybe running, when the child is forked
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_child, args=(S, queue))
    child.start()
    parents_unread, order, fresh = queue.get(timeout=60)
    child.join(timeout=60)
    assert child.exitcode == 0
    assert parents_unread  # the thread stayed in the parent
    np.testing.assert_array_equal(order, _amd.variable_order(*S.block_pattern))
    other = chain_with_chords(60, 3, 10, np.random.default_rng(5))
    np.testing.assert_array_equal(fresh, other.variable_ordering())
    assert_same(S._early_analysis(), expected(S))  # the parent's own, unharmed


def test_an_analysis_left_running_is_joined_without_module_globals(monkeypatch):
    """A plan's thread is joined in ``__del__``, also as the interpreter exits, when the module's
    globals may be gone already (``None``): joining reads none of them."""
    edges = np.stack([np.arange(3000), np.arange(1, 3001)], axis=1)
    S = BlockStructure._started(np.full(3001, 3), [(edges, 3)], False)
    plan = S._early._plan
    assert plan.handle is not None
    for name in ("STATUS", "BUILD_STATUS", "_library", "_at"):
        monkeypatch.setattr(_patterns, name, None)
    assert plan.join() and plan.handle is None


def test_past_the_limit_an_automatic_solver_makes_the_same_analysis_here(monkeypatch, rng):
    """A structure past ``EARLY_ENTRIES`` starts no analysis; a solver of the automatic choice makes the
    same one on the caller (``_early.analyse_here``), once, and factors with the compiled ``LDLᵀ``
    where it is simplicial; where CHOLMOD's rule says supernodal, CHOLMOD factors, with the symbolic
    made here."""
    monkeypatch.setattr(_early, "EARLY_ENTRIES", 100)
    clear_caches()
    S, blocks, residuals = pose_graph(np.random.default_rng(11), n_poses=120, d=3)
    assert S._early is None
    made = S._analysis()
    assert_same(made, expected(S))
    assert S._analysis() is made and S.variable_ordering() is made.order
    H, g = S.normal_equations(blocks, residuals)
    solver = CholeskySolver().bind(S)
    x = solver(H, -g)
    assert solver.backend == "ldl" and solver._impl.cost == made.simplicial.cost
    np.testing.assert_allclose(H @ x, -g, atol=1e-9 * np.abs(g).max())
    n = 60
    edges = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.5])
    dense = BlockStructure(np.full(n, 3), [(edges, 3)])
    assert dense._early is None
    assert_same(dense._analysis(), expected(dense), simplicial=False)
    H = dense.add_diagonal(dense.normal_equations([rng.standard_normal((len(edges), 3, 6))],
                                                  [np.zeros((len(edges), 3))])[0], 1.0)  # fmt: skip
    solver = CholeskySolver().bind(dense)
    solver(H, np.ones(H.shape[0]))
    assert solver.backend == "cholmod"
    assert not _cholmod.available() or solver._impl.supernodal  # (CVXOPT's interface does not tell)
    clear_caches()
