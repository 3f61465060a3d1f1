"""Marginal covariances of least-squares problems: against the dense inverse of the
Gauss-Newton matrix, against a Monte-Carlo estimate, and against GTSAM's ``Marginals``."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.uncertainty import right_to_left_covariance
from manopt_lie.linalg import SingularSystemError, _ldl
from manopt_lie.optim import (
    GaussNewton,
    LeastSquaresProblem,
    gtsam_tangent_order,
    marginal_covariances,
    to_gtsam_order,
    to_left_frame,
)
from manopt_lie.problems import costs
from manopt_lie.problems.synthetic import cube, grid2d
from tests.optim.test_blocks import landmark_world

# ldl is compiled here: skipped without a C compiler (MANOPT_LIE_NATIVE=0)
BACKENDS = ["cholmod", pytest.param("ldl", marks=pytest.mark.skipif(not _ldl.available(), reason="no compiled ldl")),
            "qdldl", "superlu"]  # fmt: skip
METHODS = ["selected", "solve"]


def dense_covariance(problem, x):
    """``H⁻¹`` on the free variables (zero rows and columns on the fixed ones), dense."""
    H = problem.linearize(x).hessian.toarray()
    free = np.repeat(~problem.fixed, problem.dims)
    out = np.zeros_like(H)
    out[np.ix_(free, free)] = np.linalg.inv(H[np.ix_(free, free)])
    return out


def block(Z, problem, u, v):
    o = np.cumsum(problem.dims) - problem.dims
    d = problem.dims
    return Z[o[u] : o[u] + d[u], o[v] : o[v] + d[v]]


def relative(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


@pytest.fixture(scope="module", params=["2d", "3d"])
def pose_graph(request):
    """A solved small pose graph (anchor fixed) and its dense covariance."""
    inst = grid2d(5, 6, seed=1) if request.param == "2d" else cube(3, seed=2, loop_closure_probability=0.3)
    problem = inst.graph.problem("geodesic")
    x = GaussNewton(grad_rtol=1e-12).solve(problem, inst.truth).x
    return inst.graph, problem, x, dense_covariance(problem, x)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", METHODS)
def test_pose_graph_against_the_dense_inverse(pose_graph, method, backend):
    graph, problem, x, Z = pose_graph
    n, far = graph.n, graph.n - 1
    pairs = [(1, 2), (far, 3), (2, far), (4, 4)]  # neighbours, far apart (off the pattern), both orders
    cov = marginal_covariances(problem, x, pairs=pairs, method=method, backend=backend)
    assert cov.method == method and cov.backend == backend
    assert cov.variables.tolist() == list(range(1, n)) and cov.fixed.size == 0  # the anchor left out
    expected = np.stack([block(Z, problem, v, v) for v in range(1, n)])
    assert relative(cov.stacked(), expected) < 1e-10
    assert cov.indices().tolist() == list(range(1, n))
    for u, v in [*pairs, (3, far)]:
        assert relative(cov.cross(u, v), block(Z, problem, u, v)) < 1e-10
    assert relative(cov.joint(1, 2), Z[np.ix_(*[np.r_[1 * graph.group.dim : 3 * graph.group.dim]] * 2)]) < 1e-10
    assert np.array_equal(cov[5], cov.stacked()[4]) and 5 in cov and 0 not in cov


def test_few_variables_restrict_the_recursion(pose_graph):
    graph, problem, x, Z = pose_graph
    chosen = [graph.n - 1, 2]
    selected = marginal_covariances(problem, x, chosen, method="selected")
    solved = marginal_covariances(problem, x, chosen, method="solve")
    assert marginal_covariances(problem, x, chosen).method == "solve"  # auto: few columns
    assert marginal_covariances(problem, x).method == "selected"  # auto: all variables
    for cov in (selected, solved):
        assert cov.variables.tolist() == [2, graph.n - 1]
        for v in chosen:
            assert relative(cov[v], block(Z, problem, v, v)) < 1e-10


def test_fixed_variables_are_reported_and_zero(pose_graph):
    _, problem, x, _ = pose_graph
    cov = marginal_covariances(problem, x, [0, 3], pairs=[(0, 3)])
    assert cov.fixed.tolist() == [0] and cov.variables.tolist() == [0, 3]
    assert repr(cov).startswith("MarginalCovariances(2 variables, 1 pairs, 1 fixed, method='solve'")
    assert not cov[0].any() and not cov.cross(0, 3).any() and cov[3].any()


def test_solves_in_chunks(pose_graph, monkeypatch):
    import manopt_lie.optim.marginals as marginals

    _, problem, x, Z = pose_graph
    monkeypatch.setattr(marginals, "_CHUNK_BYTES", 1)  # one column variable per solve
    cov = marginal_covariances(problem, x, [1, 4, 7], pairs=[(2, 7), (7, 1)], method="solve")
    for v in (1, 4, 7):
        assert relative(cov[v], block(Z, problem, v, v)) < 1e-10
    for u, v in [(2, 7), (7, 1)]:
        assert relative(cov.cross(u, v), block(Z, problem, u, v)) < 1e-10


@pytest.mark.parametrize("backend", BACKENDS)
def test_poses_and_landmarks_against_the_dense_inverse(backend):
    rng = np.random.default_rng(7)
    manifold, factors, x0, _, _ = landmark_world(rng)
    problem = LeastSquaresProblem(manifold, factors, fixed={"poses": [0]})
    x = GaussNewton(grad_rtol=1e-12).solve(problem, x0).x
    Z = dense_covariance(problem, x)
    landmarks = [0, 2, 5]
    # The observations' (pose, landmark) pairs lie on the pattern, (9, 1) may not.
    observed = factors[1].variables
    links = observed[observed[:, 0] > 0][:4]
    for method in METHODS:
        cov = marginal_covariances(problem, x, {"landmarks": landmarks, "poses": [3]},
                                   pairs={("poses", "landmarks"): np.r_[links, [[9, 1]]]}, method=method,
                                   backend=backend)  # fmt: skip
        assert cov.indices("landmarks").tolist() == landmarks and cov.stacked("landmarks").shape == (3, 2, 2)
        expected = np.stack([block(Z, problem, 10 + i, 10 + i) for i in landmarks])
        assert relative(cov.stacked("landmarks"), expected) < 1e-10
        assert relative(cov["poses", 3], block(Z, problem, 3, 3)) < 1e-10 and cov["poses", 3].shape == (3, 3)
        local, crosses = cov.stacked_cross("poses", "landmarks")
        assert local.tolist() == [*links.tolist(), [9, 1]] and crosses.shape == (5, 3, 2)
        for (pose, point), c in zip(local, crosses, strict=True):
            assert relative(c, block(Z, problem, pose, 10 + point)) < 1e-10
            assert np.array_equal(cov.cross(("landmarks", point), ("poses", pose)), c.T)
    every = marginal_covariances(problem, x, "landmarks")
    assert every.indices("landmarks").tolist() == list(range(6)) and every.indices("poses").size == 0
    by_key = marginal_covariances(problem, x, [("landmarks", 1), 2], pairs=[(2, ("landmarks", 1))])
    assert by_key.variables.tolist() == [2, 11] and by_key.pairs.tolist() == [[2, 11]]
    assert list(by_key) == [("poses", 2), ("landmarks", 1)]
    assert all(np.array_equal(b, by_key[k]) for k, b in by_key.items())
    assert relative(by_key.joint(2, 11), Z[np.ix_(*[np.r_[6:9, 32:34]] * 2)]) < 1e-10


def test_robust_losses_use_the_irls_weighted_matrix():
    inst = grid2d(4, 4, seed=3, outlier_rate=0.3, loop_closure_probability=0.5)
    robust = inst.graph.problem("geodesic", robust="cauchy:0.5")
    x = GaussNewton(grad_rtol=1e-10).solve(robust, inst.truth).x
    cov = marginal_covariances(robust, x)
    Z = dense_covariance(robust, x)
    assert relative(cov[5], block(Z, robust, 5, 5)) < 1e-10
    plain = inst.graph.problem("geodesic")
    assert relative(marginal_covariances(plain, x)[5], cov[5]) > 1e-3  # the weights matter


def test_frames_and_orderings(rng):
    inst = cube(3, seed=4)
    problem = inst.graph.problem("geodesic")
    x = GaussNewton().solve(problem, inst.truth).x
    cov = marginal_covariances(problem, x, pairs=[(1, 2)])
    left = cov.left(x)
    np.testing.assert_allclose(left, right_to_left_covariance(x[cov.indices()], cov.stacked()), rtol=1e-12)
    ad1, ad2 = x[1].adjoint(), x[2].adjoint()
    np.testing.assert_allclose(to_left_frame(x[1], cov.cross(1, 2), x[2]), ad1 @ cov.cross(1, 2) @ ad2.T)
    # A left perturbation Exp(Ad τ)·X equals the right one X·Exp(τ): the covariance of Ad τ.
    tau = rng.multivariate_normal(np.zeros(6), cov[1], size=20000)
    moved = x[1].rplus(tau).lminus(x[1])
    np.testing.assert_allclose(np.cov(moved.T), left[0], rtol=0.1, atol=0.05 * np.abs(left[0]).max())
    p = gtsam_tangent_order(SE3)
    assert p.tolist() == [3, 4, 5, 0, 1, 2] and gtsam_tangent_order(SE2).tolist() == [0, 1, 2]
    g = to_gtsam_order(cov.stacked(), SE3)
    assert g.shape == cov.stacked().shape and np.array_equal(g[:, :3, :3], cov.stacked()[:, 3:, 3:])
    assert np.array_equal(to_gtsam_order(cov.cross(1, 2), SE3, SE3)[3:, :3], cov.cross(1, 2)[:3, 3:])
    with pytest.raises(ValueError, match="no GTSAM tangent ordering"):
        gtsam_tangent_order(int)


def test_errors(pose_graph):
    graph, problem, x, _ = pose_graph
    with pytest.raises(ValueError, match="method must be"):
        marginal_covariances(problem, x, method="dense")
    with pytest.raises(ValueError, match="outside"):
        marginal_covariances(problem, x, [graph.n])
    with pytest.raises(ValueError, match="unknown backend"):
        marginal_covariances(problem, x, backend="mumps")
    with pytest.raises(KeyError, match="no block named 'landmarks'"):
        marginal_covariances(problem, x, "landmarks")
    with pytest.raises(ShapeError, match="pairs"):
        marginal_covariances(problem, x, pairs=[1, 2, 3])
    with pytest.raises(KeyError, match="by index only"):
        marginal_covariances(problem, x, [("poses", 1)])  # no blocks on a power manifold
    cov = marginal_covariances(problem, x, [1, 2])
    assert list(cov) == [1, 2]
    with pytest.raises(KeyError, match="not requested"):
        cov[3]
    with pytest.raises(KeyError, match="not requested"):
        cov.cross(1, 2)
    free = LeastSquaresProblem(problem.manifold, problem.factors)  # no gauge fixed: H is singular
    with pytest.raises(SingularSystemError):
        marginal_covariances(free, x, [1], backend="cholmod")


# ---- Monte Carlo ----------------------------------------------------------------------------


def test_against_monte_carlo():
    """Simulate the measurement noise of the model (``Z ⊕ ε``, ``ε ~ N(0, Ω⁻¹)``), re-solve
    from the truth, and compare the sample covariance of the errors ``X̂ ⊖ X`` (right tangent
    of the truth) with the marginals. The runs are disjoint copies of one tiny graph solved
    as one problem (one anchor per copy): one Gauss-Newton solve for all of them."""
    runs = 400
    inst = grid2d(3, 3, seed=5, loop_closure_probability=1.0, translation_noise=0.1, rotation_noise=0.05)
    graph, truth = inst.graph, inst.truth
    n, m = graph.n, graph.m
    rng = np.random.default_rng(11)
    exact = truth[graph.edges[:, 0]].between(truth[graph.edges[:, 1]])
    cov_e = np.linalg.inv(graph.information)
    noise = np.einsum("eij,rej->rei", np.linalg.cholesky(cov_e), rng.standard_normal((runs, m, 3)))
    measured = SE2.concatenate([exact.rplus(eps) for eps in noise])  # (runs·m,)
    edges = (graph.edges[None] + n * np.arange(runs)[:, None, None]).reshape(-1, 2)
    info = np.tile(graph.information, (runs, 1, 1))
    factor = costs.geodesic_factor(edges, measured, costs.information_sqrt(info))
    copies = SE2.concatenate([truth] * runs)
    big = LeastSquaresProblem(graph.manifold.__class__(graph.manifold.manifold, n * runs), [factor],
                              fixed=n * np.arange(runs))  # fmt: skip
    result = GaussNewton(grad_rtol=1e-12, max_iterations=50).solve(big, copies)
    assert result.success
    errors = result.x.rminus(copies).reshape(runs, n, 3)[:, 1:]  # the anchors are exact
    sample = np.einsum("rvi,rvj->vij", errors, errors) / runs  # zero mean: unbiased to first order
    # The model's marginals at the truth (noise-free measurements: the Laplace approximation).
    model = marginal_covariances(graph.problem("geodesic"), truth).stacked()
    norm = np.linalg.norm(model, axis=(1, 2))
    frobenius = np.linalg.norm(sample - model, axis=(1, 2)) / norm
    # A Gaussian's sample covariance has E‖S − Σ‖²_F = (tr Σ² + (tr Σ)²)/N: three sigmas of it.
    trace = np.trace(model, axis1=1, axis2=2)
    sigma = np.sqrt((np.einsum("vij,vji->v", model, model) + trace**2) / runs) / norm
    assert frobenius.max() < 0.2 and (frobenius < 3 * sigma).all(), (frobenius, sigma)
    # NEES: τᵀΣ⁻¹τ ~ χ²(3) per pose (variance 6); runs are independent, the poses of one run not.
    nees = np.einsum("rvi,vij,rvj->", errors, np.linalg.inv(model), errors) / (runs * (n - 1))
    assert abs(nees - 3) < 3 * np.sqrt(6 / runs), nees


# ---- GTSAM --------------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["2d", "3d"])
def test_against_gtsam_marginals(which):
    gtsam = pytest.importorskip("gtsam")
    from manopt_lie.bench.peers import gtsam_problem

    inst = grid2d(5, 5, seed=6) if which == "2d" else cube(3, seed=7, loop_closure_probability=0.3)
    graph = inst.graph
    problem = graph.problem("geodesic")
    x = GaussNewton(grad_rtol=1e-12).solve(problem, inst.truth).x
    factors, values = gtsam_problem(gtsam, graph, x)  # the anchor held by a constrained prior
    theirs = gtsam.Marginals(factors, values)
    ours = marginal_covariances(problem, x)
    expected = np.stack([theirs.marginalCovariance(k) for k in range(1, graph.n)])
    assert relative(to_gtsam_order(ours.stacked(), graph.group), expected) < 1e-6
    joint = theirs.jointMarginalCovariance([1, 2]).at(1, 2)
    assert relative(to_gtsam_order(marginal_covariances(problem, x, pairs=[(1, 2)]).cross(1, 2), graph.group,
                                   graph.group), joint) < 1e-6  # fmt: skip
