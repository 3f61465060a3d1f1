"""Information matrices a cost cannot use are refused naming the edge — never a bare
"Singular matrix", a numpy warning (the test suite turns RuntimeWarnings into errors) or a
silent nan."""

from __future__ import annotations

import re

import numpy as np
import pytest

from manopt_lie.problems import PoseGraph, g2o, rotation_averaging, synthetic
from manopt_lie.problems.costs import IndefiniteInformationError, InformationMatrixError


@pytest.fixture(scope="module")
def grid() -> PoseGraph:
    return synthetic.grid2d(4, 4, loop_closure_probability=0.5, seed=3).graph


def with_information(graph: PoseGraph, edit, lines: bool = True) -> PoseGraph:
    info = graph.information.copy()
    edit(info)
    lines_ = np.arange(graph.m) + 7 if lines else None
    return PoseGraph(graph.group, graph.edges, graph.measurements, info, name="edited", edge_lines=lines_)


def named(graph: PoseGraph, e: int) -> str:
    i, j = graph.ids[graph.edges[e]]
    return re.escape(f"{i}→{j} (line {e + 7})")


def set_block(e: int, rows: slice, value) -> object:
    def edit(info: np.ndarray) -> None:
        info[e, rows, rows] = value

    return edit


def test_zero_information_is_named_by_both_costs(grid: PoseGraph) -> None:
    """Audit: zero information gave a bare "Singular matrix" naming no edge."""
    bad = with_information(grid, set_block(2, slice(None), 0.0))
    for cost in ("chordal", "geodesic"):
        with pytest.raises(IndefiniteInformationError, match=named(bad, 2)):
            bad.problem(cost)
    with pytest.raises(IndefiniteInformationError, match=named(bad, 2)):
        bad.cost(grid.initialize("odometry"), "chordal")


def test_rank_deficient_translation_block(grid: PoseGraph) -> None:
    bad = with_information(grid, set_block(4, slice(0, 2), [[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(IndefiniteInformationError, match=named(bad, 4)):
        bad.problem("chordal")
    assert np.isnan(bad.se_sync_weights[1][4])  # singular: no weight, not inf


def test_indefinite_translation_block_never_gives_an_infinite_weight(grid: PoseGraph) -> None:
    """Audit: an indefinite translation block made τ = inf and the chordal cost nan, silently."""
    bad = with_information(grid, set_block(3, slice(0, 2), np.diag([1.0, -1.0])))
    _, tau = bad.se_sync_weights
    assert not np.isinf(tau).any()
    with pytest.raises(IndefiniteInformationError, match=named(bad, 3)):
        bad.cost(grid.initialize("odometry"), "chordal")
    with pytest.raises(IndefiniteInformationError, match=named(bad, 3)):
        bad.problem("geodesic")
    assert bad.problem("geodesic", repair_information=True).cost(grid.initialize("odometry")) > 0


def test_asymmetric_information_is_refused_or_symmetrized(grid: PoseGraph) -> None:
    def edit(info: np.ndarray) -> None:
        info[5, 0, 1] += 3.0

    bad = with_information(grid, edit)
    with pytest.raises(InformationMatrixError, match="not symmetric: " + named(bad, 5)):
        bad.problem("geodesic")
    repaired = bad.problem("geodesic", repair_information=True)
    assert np.isfinite(repaired.cost(grid.initialize("odometry")))
    assert g2o.lint(bad).asymmetric.tolist() == [5]


def test_non_finite_information_is_named(grid: PoseGraph) -> None:
    with pytest.raises(InformationMatrixError, match="non-finite information matrices on 1 edges: " + named(grid, 6)):
        with_information(grid, set_block(6, slice(None), np.nan))


def test_information_near_the_float_range(grid: PoseGraph) -> None:
    """Entries of 1e308 neither warn nor crash: the geodesic cost refuses the (rank-one,
    overflowing) matrix by name; the initialization still runs."""
    bad = with_information(grid, set_block(1, slice(None), 1e308))
    with pytest.raises(IndefiniteInformationError, match=named(bad, 1)):
        bad.problem("geodesic")
    with pytest.raises(IndefiniteInformationError, match=named(bad, 1)):
        bad.problem("chordal")
    x0 = bad.initialize("chordal")
    assert np.isfinite(x0.as_matrix()).all()


def test_names_use_source_ids_without_lines(grid: PoseGraph) -> None:
    bad = with_information(grid, set_block(2, slice(None), 0.0), lines=False)
    i, j = bad.ids[bad.edges[2]]
    with pytest.raises(IndefiniteInformationError, match=f"{i}→{j}; pass"):
        bad.problem("geodesic")


def test_rotation_averaging_inherits_the_names(grid: PoseGraph) -> None:
    bad = with_information(grid, set_block(2, slice(2, 3), 0.0))
    with pytest.raises(InformationMatrixError, match="kappa must be finite and positive.*" + named(bad, 2)):
        rotation_averaging.from_pose_graph(bad)


def test_a_graph_without_edges_says_so() -> None:
    """Audit: a graph without edges reported an internal array shape."""
    from manopt_lie import SE2

    empty = PoseGraph(SE2, np.zeros((0, 2), dtype=np.int64), SE2.identity((0,)), np.zeros((0, 3, 3)),
                      poses=SE2.identity((3,)), name="empty")  # fmt: skip
    for cost in ("geodesic", "chordal"):
        with pytest.raises(ValueError, match="empty: the graph has no edges"):
            empty.problem(cost)
