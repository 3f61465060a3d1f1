"""The relative-measurement costs: values, Jacobians, exact chordal Hessian, information
matrices; and the initializations on exactly consistent graphs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.check import check_gradient, check_hessian
from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import LeastSquaresProblem
from manopt_lie.problems import PoseGraph, costs, initialization
from manopt_lie.problems.initialization import DisconnectedGraphError

GROUPS = [SO2, SO3, SE2, SE3]


def loop_graph(n, rng, extra=4):
    """A cycle 0→1→…→n−1→0 plus ``extra`` random chords."""
    chords = rng.choice(n, size=(extra, 2))
    chords = chords[chords[:, 0] != chords[:, 1]]
    return np.concatenate([np.stack([np.arange(n), (np.arange(n) + 1) % n], 1), chords])


def random_information(rng, m, k):
    a = rng.standard_normal((m, k, k))
    return a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(k)


def column_weights(group, rng, m):
    c = group.point_dim + (1 if group in (SE2, SE3) else 0)
    return rng.uniform(0.5, 2.0, (m, c))


def numeric_jacobians(factor, xi, xj, eps=1e-6):
    out = []
    for slot in range(2):
        cols = []
        for k in range(xi.dim):
            d = np.zeros((len(xi), xi.dim))
            d[:, k] = eps
            plus = [xi, xj]
            minus = [xi, xj]
            plus[slot], minus[slot] = plus[slot].rplus(d), plus[slot].rplus(-d)
            cols.append((factor.residual(*plus) - factor.residual(*minus)) / (2 * eps))
        out.append(np.stack(cols, axis=-1))
    return out


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
@given(seed=st.integers(0, 2**32 - 1))
def test_factor_jacobians_match_central_differences(group, seed):
    rng = np.random.default_rng(seed)
    edges = loop_graph(6, rng)
    m = len(edges)
    x, z = group.random(rng, (6,)), group.random(rng, (m,))
    for factor in (
        costs.geodesic_factor(edges, z, costs.information_sqrt(random_information(rng, m, group.dim))),
        costs.chordal_factor(edges, z, column_weights(group, rng, m)),
    ):
        xi, xj = x[edges[:, 0]], x[edges[:, 1]]
        _, analytic = factor.residual(xi, xj, jac=True)
        for a, n in zip(analytic, numeric_jacobians(factor, xi, xj), strict=True):
            np.testing.assert_allclose(a, n, atol=1e-6 * max(1.0, np.abs(n).max()))


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_cost_values(group, rng):
    edges = loop_graph(5, rng)
    m = len(edges)
    x, z = group.random(rng, (5,)), group.random(rng, (m,))
    info, w = random_information(rng, m, group.dim), column_weights(group, rng, m)
    r = x[edges[:, 0]].between(x[edges[:, 1]]).rminus(z)  # Log(Z⁻¹ X_i⁻¹ X_j)
    assert costs.geodesic_cost(x, edges, z, info) == pytest.approx(
        0.5 * sum(ri @ oi @ ri for ri, oi in zip(r, info, strict=True)), rel=1e-12
    )
    xm, zm = x.as_matrix(), z.as_matrix()
    d = group.point_dim
    loop = sum(
        np.sum(((xm[j] - xm[i] @ zm[e])[:d] * w[e]) ** 2) for e, (i, j) in enumerate(edges)
    )  # Σ ‖(X_j − X_i Z) W‖² on the top rows
    assert costs.chordal_cost(x, edges, z, w) == pytest.approx(loop, rel=1e-12)
    factor = costs.chordal_factor(edges, z, w)
    res = factor.residual(x[edges[:, 0]], x[edges[:, 1]])
    assert 0.5 * np.sum(res**2) == pytest.approx(loop, rel=1e-12)


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_exact_chordal_hessian_passes_the_checkers(group, rng):
    edges = loop_graph(6, rng)
    m = len(edges)
    z, w = group.random(rng, (m,)), column_weights(group, rng, m)
    manifold = Power(LieGroupManifold(group), 6)
    hessian = costs.ChordalHessian(manifold, edges, z, w, np.zeros(0, dtype=np.int64))
    problem = LeastSquaresProblem(manifold, [costs.chordal_factor(edges, z, w)], hessian=hessian)
    x = group.random(rng, (6,))
    assert check_gradient(problem, x, rng=rng).passed
    report = check_hessian(problem, x, rng=rng)
    assert report.passed, report.message
    # f = tr(X Q Xᵀ) on the stacked top rows.
    rows = x.as_matrix()[:, : group.point_dim, :]
    stacked = rows.transpose(1, 0, 2).reshape(group.point_dim, -1)
    assert np.trace(stacked @ hessian.Q @ stacked.T) == pytest.approx(costs.chordal_cost(x, edges, z, w), rel=1e-12)


def test_fixed_variables_see_the_identity_in_the_exact_hessian(rng):
    edges = loop_graph(5, rng)
    m = len(edges)
    z, w = SE3.random(rng, (m,)), column_weights(SE3, rng, m)
    manifold = Power(LieGroupManifold(SE3), 5)
    hessian = costs.ChordalHessian(manifold, edges, z, w, np.array([2]))
    v = rng.standard_normal((5, 6))
    out = hessian(SE3.random(rng, (5,)), v)
    np.testing.assert_array_equal(out[2], v[2])


def test_information_sqrt_whitens_and_names_indefinite_edges(rng):
    info = random_information(rng, 4, 3)
    lt = costs.information_sqrt(info)
    np.testing.assert_allclose(np.swapaxes(lt, 1, 2) @ lt, info, atol=1e-12)
    info[1] = np.diag([1.0, -1.0, 1.0])
    info[3] = np.diag([1.0, 1.0, 0.0])
    with pytest.raises(costs.IndefiniteInformationError, match=r"2 edges .*e1, e3"):
        costs.information_sqrt(info, [f"e{k}" for k in range(4)])
    repaired = costs.information_sqrt(info, repair=True)
    assert np.all(np.isfinite(repaired))
    assert np.all(np.linalg.eigvalsh(np.swapaxes(repaired, 1, 2) @ repaired) > 0)
    near = costs.nearest_positive_definite(info[1:2])
    np.testing.assert_allclose(near[0], np.diag([1.0, 1e-9, 1.0]), atol=1e-15)


def test_information_sqrt_of_exactly_symmetric_matrices_skips_nothing_it_must_check(rng):
    """The shortcut for exactly symmetric matrices gives the factor of the round-off-asymmetric
    path, still refuses and repairs indefinite ones, and never writes into the caller's array."""
    info = random_information(rng, 6, 4)
    info = 0.5 * (info + np.swapaxes(info, 1, 2))  # bit-exact symmetry: x + y == y + x
    assert np.array_equal(info, np.swapaxes(info, 1, 2))
    nudged = info.copy()
    nudged[:, 0, 1] *= 1 + 1e-14  # asymmetric by round-off only: the symmetric part is used
    np.testing.assert_allclose(costs.information_sqrt(info), costs.information_sqrt(nudged), rtol=1e-12, atol=1e-15)
    nudged[4, 0, 1] += 1.0
    with pytest.raises(costs.InformationMatrixError, match=r"1 edges .*not symmetric: 4;"):
        costs.information_sqrt(nudged)
    info[2] = np.diag([1.0, -1.0, 1.0, 1.0])
    with pytest.raises(costs.IndefiniteInformationError, match=r"1 edges .*: 2;"):
        costs.information_sqrt(info)
    before = info.copy()
    repaired = costs.information_sqrt(info, repair=True)
    np.testing.assert_array_equal(info, before)
    assert np.all(np.linalg.eigvalsh(np.swapaxes(repaired, 1, 2) @ repaired) > 0)


@pytest.mark.parametrize(
    "bad",
    [np.zeros((3, 3)), np.diag([1.0, np.nan, 1.0]), np.diag([1.0, np.inf, 1.0]), np.full((3, 3), 1.0),
     np.diag([1e300, 1.0, -1e-300])],
    ids=["zero", "nan", "inf", "rank-one", "huge-and-negative"],
)  # fmt: skip
def test_information_sqrt_takes_one_factorization_only_when_every_matrix_is_definite(rng, bad):
    """The batched Cholesky shortcut never lets a singular, non-finite or indefinite matrix
    through: it falls back to the eigenvalues, which name the edge."""
    info = random_information(rng, 5, 3)
    root = costs.information_sqrt(info)
    np.testing.assert_allclose(np.swapaxes(root, 1, 2) @ root, info, atol=1e-12)
    info[2] = bad
    with pytest.raises(costs.IndefiniteInformationError, match=r"1 edges .*: e2;"):
        costs.information_sqrt(info, [f"e{k}" for k in range(5)])
    huge = random_information(rng, 2, 3) * 1e300  # definite, near the float range: still factorized
    assert np.isfinite(costs.information_sqrt(huge)).all()


def test_se_sync_weights():
    info2 = np.diag([2.0, 4.0, 7.0])[None]
    kappa, tau = costs.se_sync_weights(info2, 2)
    assert kappa[0] == 7.0 and tau[0] == pytest.approx(2 / (1 / 2 + 1 / 4))
    info3 = np.diag([1.0, 2.0, 4.0, 10.0, 20.0, 40.0])[None]
    kappa, tau = costs.se_sync_weights(info3, 3)
    assert tau[0] == pytest.approx(3 / (1 + 1 / 2 + 1 / 4))
    assert kappa[0] == pytest.approx(3 / (2 * (1 / 10 + 1 / 20 + 1 / 40)))


# ---- initializations -------------------------------------------------------------------


def consistent_graph(group, rng, n=40, extra=30):
    truth = group.random(rng, (n,))
    edges = loop_graph(n, rng, extra)
    z = truth[edges[:, 0]].between(truth[edges[:, 1]])
    info = np.broadcast_to(np.eye(group.dim), (len(edges), group.dim, group.dim))
    return PoseGraph(group, edges, z, info), truth


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
@pytest.mark.parametrize("init", ["chordal_initialization", "odometry_initialization"])
def test_initializations_recover_exact_measurements(group, init, rng):
    graph, truth = consistent_graph(group, rng)
    x = getattr(graph, init)()
    expected = truth[0].inverse() @ truth  # anchor at the identity (the graph has no poses)
    np.testing.assert_allclose(x.as_matrix(), expected.as_matrix(), atol=1e-9)
    assert graph.cost(x, "geodesic") < 1e-16 and graph.cost(x, "chordal") < 1e-16


def test_initialization_keeps_the_sources_frame(rng):
    graph, truth = consistent_graph(SE3, rng)
    with_poses = PoseGraph(SE3, graph.edges, graph.measurements, graph.information, poses=truth)
    np.testing.assert_allclose(with_poses.chordal_initialization().as_matrix(), truth.as_matrix(), atol=1e-9)


def test_spanning_tree_prefers_odometry_and_composes_long_chains(rng):
    n = 5000  # a long chain: pointer doubling needs ⌈log₂ n⌉ rounds
    truth = SE2.random(rng, (n,))
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], 1)
    z = truth[edges[:, 0]].between(truth[edges[:, 1]])
    x = initialization.spanning_tree(SE2, n, edges[::-1], z[np.arange(n - 2, -1, -1)], anchor=0)
    np.testing.assert_allclose(x.as_matrix(), (truth[0].inverse() @ truth).as_matrix(), atol=1e-6)


def test_reversed_edges_are_inverted(rng):
    graph, truth = consistent_graph(SE2, rng, n=10, extra=0)
    flipped = PoseGraph(SE2, graph.edges[:, ::-1].copy(), graph.measurements.inverse(), graph.information)
    np.testing.assert_allclose(
        flipped.odometry_initialization().as_matrix(), (truth[0].inverse() @ truth).as_matrix(), atol=1e-9
    )


def test_disconnected_graph_names_the_unreachable_vertices(rng):
    edges = np.array([[0, 1], [1, 2], [3, 4]])
    z = SE2.random(rng, (3,))
    graph = PoseGraph(SE2, edges, z, np.broadcast_to(np.eye(3), (3, 3, 3)), ids=np.array([10, 11, 12, 13, 14]))
    for init in (graph.chordal_initialization, graph.odometry_initialization):
        with pytest.raises(DisconnectedGraphError, match=r"2 vertices .* vertex 10: \[13, 14\]"):
            init()
