"""Between, prior and rotation factors on every group: residuals, right Jacobians against
central differences through ``X ⊕ δ``, and the geodesic pose-graph factor of ``problems``."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SE23, SO2, SO3, Rn, Sim3, _kernels
from manopt_lie.factors import Diagonal, Information, Isotropic, _poses, between_factor, prior_factor, rotation_factor
from manopt_lie.lie import LieGroup
from manopt_lie.optim.losses import Huber

from ..kernel_paths import PATHS, use
from .helpers import assert_jacobians

GROUPS = [SO2, SO3, SE2, SE3, Rn(3), SE23, Sim3]
REGIMES = ["random", "near identity", "near pi"]
M = 12


def sample(group: type[LieGroup], rng: np.random.Generator, regime: str, m: int = M) -> LieGroup:
    if regime == "random":
        return group.random(rng, (m,))
    if regime == "near identity":
        return group.exp(1e-8 * rng.standard_normal((m, group.dim)))
    tau = 0.1 * rng.standard_normal((m, group.dim))
    if group in (SO2, SE2):
        tau[:, -1] = np.pi - 1e-4
    elif group in (SO3, SE3):
        axis = rng.standard_normal((m, 3))
        tau[:, -3:] = (np.pi - 1e-4) * axis / np.linalg.norm(axis, axis=1, keepdims=True)
    return group.exp(tau)


def pairs(m: int = M) -> np.ndarray:
    return np.c_[np.arange(m), np.arange(m, 2 * m)]


# SE(2)/SE(3) between factors run in native code, on CasADi's virtual machine or the array kernels.
KERNELS = [(g, "native") for g in GROUPS] + [(g, p) for g in _poses.FUSED_GROUPS for p in PATHS[1:]]


@pytest.mark.parametrize(("group", "path"), KERNELS, ids=lambda g: getattr(g, "__name__", g))
@pytest.mark.parametrize("regime", REGIMES)
def test_between_jacobians(rng, group, path, regime, monkeypatch):
    use(path, monkeypatch)
    xi, z = group.random(rng, (M,)), group.random(rng, (M,))
    # X_j such that the residual Log(Z⁻¹ X_i⁻¹ X_j) lands in the regime.
    xj = xi @ z @ sample(group, rng, regime)
    factor = between_factor(pairs(), z)
    r = factor.residual(xi, xj)
    np.testing.assert_allclose(r, (z.inverse() @ xi.inverse() @ xj).log(), atol=1e-12)
    assert_jacobians(factor, [xi, xj])
    noise = Information(np.eye(group.dim) * rng.uniform(1, 4, group.dim))
    assert_jacobians(between_factor(pairs(), z, noise), [xi, xj])


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
@pytest.mark.parametrize("noise", ["unit", "shared", "per edge"])
def test_the_fused_kernel_in_passes_equals_one_pass(rng, group, noise, monkeypatch):
    """The SE(d) array kernel runs in passes of ``EDGE_CHUNK`` edges; passes of 5 (the last one
    short) give what one pass gives."""
    use("arrays", monkeypatch)
    xi, xj, z = group.random(rng, (M,)), group.random(rng, (M,)), group.random(rng, (M,))
    diag = rng.uniform(1, 4, (M, group.dim))
    model = {
        "unit": None,
        "shared": Information(np.diag(diag[0])),
        "per edge": Information(diag[:, :, None] * np.eye(group.dim)),
    }[noise]
    factor = between_factor(pairs(), z) if model is None else between_factor(pairs(), z, model)
    r, (j_i, j_j) = factor.residual(xi, xj, jac=True)
    monkeypatch.setattr(_poses, "EDGE_CHUNK", 5)
    r5, (j_i5, j_j5) = factor.residual(xi, xj, jac=True)
    np.testing.assert_allclose(r5, r, rtol=0, atol=1e-15)
    np.testing.assert_allclose(j_i5, j_i, rtol=0, atol=1e-14)
    np.testing.assert_allclose(j_j5, j_j, rtol=0, atol=1e-14)
    np.testing.assert_allclose(factor.residual(xi, xj), r, rtol=0, atol=1e-15)
    assert j_i5.base is j_j5.base  # the two slots' halves of one array, as in one pass


def _exact(group: type[LieGroup], angle: float, m: int) -> LieGroup:
    """``m`` copies of a rotation by exactly ``angle`` (0 or π) about the first axis, no translation."""
    c = np.cos(angle).round()
    rotation = np.diag([1.0, c, c]) if group is SE3 else np.diag([c, c])
    matrix = np.eye(len(rotation) + 1)
    matrix[: len(rotation), : len(rotation)] = rotation
    return group.from_matrix(np.repeat(matrix[None], m, axis=0))


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
@pytest.mark.parametrize("regime", [*REGIMES, "identity", "pi"])
@pytest.mark.parametrize("m", [1, M, _kernels.VM_EDGES])
def test_native_code_and_the_virtual_machine_agree_with_the_array_kernel(rng, group, regime, m, monkeypatch):
    """Residuals and both slots' Jacobians in native code and (up to ``VM_EDGES`` edges) on
    CasADi's virtual machine agree with the array kernel to round-off, at the identity and at π
    exactly, with every noise model."""
    xi, z = group.random(rng, (m,)), group.random(rng, (m,))
    if regime in ("identity", "pi"):  # E = Z⁻¹ X_i⁻¹ X_j exactly the identity or a half turn
        xi, z = group.identity((m,)), group.identity((m,))
        xj = _exact(group, 0.0 if regime == "identity" else np.pi, m)
    else:
        xj = xi @ z @ sample(group, rng, regime, m)
    a = rng.standard_normal((m, group.dim, group.dim))
    omega = a @ np.swapaxes(a, 1, 2) + np.eye(group.dim)
    models = [None, Information(omega[0]), Information(omega)]
    for model in models:
        factor = between_factor(pairs(m), z) if model is None else between_factor(pairs(m), z, model)
        out = {}
        for path in PATHS:
            use(path, monkeypatch)
            out[path] = factor.residual(xi, xj, jac=True), factor.residual(xi, xj)
            monkeypatch.undo()
        arrays = out["arrays"]
        for path in PATHS[:2]:
            (r, jacobians), residual = out[path]
            np.testing.assert_allclose(r, arrays[0][0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(residual, arrays[1], rtol=0, atol=1e-12)
            for j, j_ref in zip(jacobians, arrays[0][1], strict=True):
                np.testing.assert_allclose(j, j_ref, rtol=0, atol=1e-11)
                assert np.isfinite(j).all()


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_one_information_given_per_edge_is_kept_once(rng, group):
    """Per-edge information matrices that are all one matrix whiten as the shared model does
    (the fused kernel keeps the one matrix); a single different edge keeps them per edge."""
    xi, xj, z = group.random(rng, (M,)), group.random(rng, (M,)), group.random(rng, (M,))
    a = rng.standard_normal((group.dim, group.dim))
    omega = a @ a.T + group.dim * np.eye(group.dim)
    shared = between_factor(pairs(), z, Information(omega)).residual(xi, xj, jac=True)
    repeated = np.repeat(omega[None], M, axis=0)
    per_edge = between_factor(pairs(), z, Information(repeated)).residual(xi, xj, jac=True)
    np.testing.assert_allclose(per_edge[0], shared[0], rtol=0, atol=1e-13)
    for j, j_ref in zip(per_edge[1], shared[1], strict=True):
        np.testing.assert_allclose(j, j_ref, rtol=0, atol=1e-13)
    repeated[3] *= 2.0  # edge 3's residual grows by √2, the others stay
    r = between_factor(pairs(), z, Information(repeated)).residual(xi, xj)
    np.testing.assert_allclose(np.linalg.norm(r, axis=1) ** 2,
                               np.linalg.norm(shared[0], axis=1) ** 2 * np.where(np.arange(M) == 3, 2.0, 1.0),
                               rtol=1e-12)  # fmt: skip


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
@pytest.mark.parametrize("regime", REGIMES)
def test_prior_jacobians(rng, group, regime):
    mean = group.random(rng, (M,))
    x = mean @ sample(group, rng, regime)
    factor = prior_factor(np.arange(M), mean, Isotropic(0.5, group.dim))
    np.testing.assert_allclose(factor.residual(x), 2.0 * x.rminus(mean), atol=1e-12)
    assert_jacobians(factor, [x])


def test_a_shared_measurement_broadcasts(rng):
    x, mean = SE3.random(rng, (5,)), SE3.random(rng)
    np.testing.assert_allclose(prior_factor(np.arange(5), mean).residual(x), x.rminus(mean.broadcast_to((5,))))


def test_vectors_as_rn_points(rng):
    """On ``Euclidean(d)`` blocks the points are plain arrays: ``Rn(d)`` measurements treat them as
    ``Rn(d)`` elements (``r = l_j − l_i − z``, ``J = ∓I``)."""
    li, lj, z = rng.standard_normal((M, 3)), rng.standard_normal((M, 3)), rng.standard_normal((M, 3))
    factor = between_factor(pairs(), Rn(3)(z))
    np.testing.assert_allclose(factor.residual(li, lj), lj - li - z, atol=1e-14)
    _, (j_i, j_j) = factor.residual(li, lj, jac=True)
    np.testing.assert_array_equal(j_i, -np.broadcast_to(np.eye(3), (M, 3, 3)))
    np.testing.assert_array_equal(j_j, np.broadcast_to(np.eye(3), (M, 3, 3)))
    assert_jacobians(factor, [li, lj])
    prior = prior_factor(np.arange(M), Rn(3)(z), Diagonal([1.0, 2.0, 4.0]))
    np.testing.assert_allclose(prior.residual(li), (li - z) / [1.0, 2.0, 4.0])
    assert_jacobians(prior, [li])


@pytest.mark.parametrize(("poses", "rotations"), [(SE2, SO2), (SE3, SO3)], ids=["2d", "3d"])
@pytest.mark.parametrize("regime", REGIMES)
def test_rotation_factor(rng, poses, rotations, regime):
    xi, z = poses.random(rng, (M,)), rotations.random(rng, (M,))
    rj = xi.rotation() @ z @ sample(rotations, rng, regime)
    xj = poses.from_rotation_translation(rj, rng.standard_normal((M, poses.point_dim)))
    factor = rotation_factor(pairs(), z, Isotropic(0.2, rotations.dim))
    # On poses: the between factor of the rotation parts, with zero translation columns.
    r, (j_i, j_j) = factor.residual(xi, xj, jac=True)
    r_rot, (k_i, k_j) = factor.residual(xi.rotation(), xj.rotation(), jac=True)
    between = between_factor(pairs(), z, Isotropic(0.2, rotations.dim))
    np.testing.assert_allclose(r, between.residual(xi.rotation(), xj.rotation()), atol=1e-12)
    np.testing.assert_array_equal(r, r_rot)
    d = poses.point_dim
    assert j_i.shape == (M, rotations.dim, poses.dim) and not j_i[:, :, :d].any() and not j_j[:, :, :d].any()
    np.testing.assert_array_equal(j_i[:, :, d:], k_i)
    np.testing.assert_array_equal(j_j[:, :, d:], k_j)
    assert_jacobians(factor, [xi, xj])
    assert_jacobians(factor, [xi.rotation(), xj.rotation()])


def test_agrees_with_the_geodesic_pose_graph_factor(rng):
    """``between_factor`` whitened by ``Information(Ω)`` is ``problems.costs.geodesic_factor`` with
    ``Lᵀ`` (``Ω = LLᵀ``): residuals and Jacobians to 1e-12, on 2-D and 3-D pose graphs."""
    from manopt_lie.problems import costs, synthetic

    for instance in (synthetic.grid2d(4, 5, seed=3), synthetic.cube(3, seed=4)):
        graph = instance.graph
        m, k = graph.edges.shape[0], graph.measurements.dim
        a = rng.standard_normal((m, k, k))
        omega = a @ np.swapaxes(a, 1, 2) + np.eye(k)
        group = type(graph.measurements)
        x = instance.truth.rplus(0.3 * rng.standard_normal((graph.n, group.dim)))
        ours = between_factor(graph.edges, graph.measurements, Information(omega))
        theirs = costs.geodesic_factor(graph.edges, graph.measurements, costs.information_sqrt(omega))
        xi, xj = x[graph.edges[:, 0]], x[graph.edges[:, 1]]
        r, jacobians = ours.residual(xi, xj, jac=True)
        r_ref, jacobians_ref = theirs.residual(xi, xj, jac=True)
        np.testing.assert_allclose(r, r_ref, rtol=0, atol=1e-12)
        for j, j_ref in zip(jacobians, jacobians_ref, strict=True):
            np.testing.assert_allclose(j, j_ref, rtol=0, atol=1e-12)
        cost = 0.5 * np.sum(r**2)
        assert np.isclose(cost, costs.geodesic_cost(x, graph.edges, graph.measurements, omega), rtol=1e-12)


def test_options_are_forwarded(rng):
    z = SE2.random(rng, (3,))
    factor = between_factor(np.c_[[0, 1, 2], [1, 2, 3]], z, loss="huber:0.5", name="odometry", blocks="poses")
    assert factor.robust_loss == Huber(0.5) and factor.name == "odometry" and factor.blocks == ("poses", "poses")


def test_bad_input(rng):
    z = SE2.random(rng, (3,))
    with pytest.raises(ValueError, match=r"between: variables must be a non-empty integer array of shape \(m, 2\)"):
        between_factor(np.zeros((3, 3), dtype=int), z)
    with pytest.raises(ValueError, match=r"measured must have batch shape \(4,\)"):
        between_factor(np.zeros((4, 2), dtype=int), z)
    with pytest.raises(TypeError, match="measured must be a Lie group element"):
        between_factor(np.zeros((3, 2), dtype=int), np.zeros((3, 3)))  # type: ignore[arg-type]
    factor = between_factor(np.zeros((3, 2), dtype=int), z)
    with pytest.raises(TypeError, match="expected SE2 elements, got SE3"):
        factor.residual(SE3.random(rng, (3,)), SE3.random(rng, (3,)))
    with pytest.raises(TypeError, match="expected SO3 rotations or poses with SO3 rotations, got SE2"):
        rotation_factor(np.zeros((3, 2), dtype=int), SO3.random(rng, (3,))).residual(z, z)
