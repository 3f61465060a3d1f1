"""Property tests for every manifold (hypothesis-driven seeds): projections,
retractions, gradients and Hessians against finite differences, powers vs factors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie import SE2, SE3, SO2, SO3, LieGroup, NonFiniteError, NotOnManifoldError, Rn, ShapeError, _kernels
from manopt_lie.lie import RnGroup
from manopt_lie.manifolds import (
    Blocks,
    Euclidean,
    Grassmann,
    LieGroupManifold,
    Manifold,
    MissingOperationError,
    Power,
    Product,
    ProductVector,
    SpecialOrthogonal,
    Sphere,
    Stiefel,
)

from ..kernel_paths import PATHS, use

# (manifold, Hessian check): "gradient" differentiates the Riemannian gradient along a
# retraction curve and projects (Levi-Civita Hessian of embedded manifolds); "pullback"
# takes mixed second differences of f(R_x(·)), exact for Lie groups (CONVENTIONS §6)
# and for second-order retractions.
CASES: list[tuple[Manifold, str]] = [
    (Euclidean(3), "gradient"),
    (Euclidean(2, 3), "gradient"),
    (Sphere(4), "gradient"),
    (Stiefel(5, 2), "gradient"),
    (Stiefel(4, 3, retraction="polar"), "gradient"),
    (Grassmann(5, 2, retraction="polar"), "pullback"),
    (SpecialOrthogonal(2), "gradient"),
    (SpecialOrthogonal(3), "gradient"),
    (SpecialOrthogonal(4), "gradient"),
    *[(LieGroupManifold(g), "pullback") for g in (SO2, SO3, SE2, SE3, Rn(3))],
    (LieGroupManifold(SE2, geometry="product"), "pullback"),
    (LieGroupManifold(SE3, geometry="product"), "pullback"),
    (LieGroupManifold(SE2, geometry="decoupled"), "pullback"),
    (LieGroupManifold(SE3, geometry="decoupled"), "pullback"),
    (Power(LieGroupManifold(SE3, geometry="decoupled"), 3), "pullback"),
    (Power(Sphere(3), 4), "gradient"),
    (Power(LieGroupManifold(SO3), 5), "pullback"),
    (Power(LieGroupManifold(SE3), (2, 3)), "pullback"),
    (Product(Sphere(3), LieGroupManifold(SE3)), "pullback"),
    (Power(Product(LieGroupManifold(SE2), Euclidean(2)), 3), "pullback"),
    (Blocks({"poses": Power(LieGroupManifold(SE3), 3), "points": Power(Euclidean(3), 4)}), "pullback"),
]
cases = pytest.mark.parametrize("manifold, hessian_check", CASES, ids=[repr(m) for m, _ in CASES])
seeds = given(seed=st.integers(0, 2**32 - 1))


# ---- tree helpers: points/tangents may be arrays, group elements or tuples --------


def leaves(a):
    if isinstance(a, tuple):
        return [leaf for part in a for leaf in leaves(part)]
    return [ambient(a)]


def rebuild(template, flat):
    """A tree shaped like ``template`` with leaves taken from the iterator ``flat``."""
    if isinstance(template, tuple):
        return tuple(rebuild(t, flat) for t in template)
    return next(flat)


def ambient(x):
    """The embedding-space array(s) of a point: matrices for groups (vectors for Rⁿ)."""
    if isinstance(x, tuple):
        return tuple(ambient(p) for p in x)
    if isinstance(x, RnGroup):
        return x.data
    if isinstance(x, LieGroup):
        return x.as_matrix()
    return np.asarray(x)


def frob(a, b):
    return sum(float(np.sum(p * q)) for p, q in zip(leaves(a), leaves(b), strict=True))


class Cost:
    """``f(a) = Σ ⟨C, a⟩ + ½⟨a, S a⟩ + sin⟨B, a⟩`` over the ambient leaves, with exact derivatives."""

    def __init__(self, x, rng):
        self.params = []
        for leaf in leaves(ambient(x)):
            n = leaf.size
            s = rng.standard_normal((n, n))
            self.params.append((rng.standard_normal(leaf.shape), (s + s.T) / n, rng.standard_normal(leaf.shape)))

    def _zip(self, x):
        return zip(leaves(ambient(x)), self.params, strict=True)

    def __call__(self, x):
        return sum(
            np.sum(c * a) + 0.5 * a.ravel() @ s @ a.ravel() + np.sin(np.sum(b * a)) for a, (c, s, b) in self._zip(x)
        )

    def egrad(self, x):
        g = [c + (s @ a.ravel()).reshape(a.shape) + np.cos(np.sum(b * a)) * b for a, (c, s, b) in self._zip(x)]
        return rebuild(ambient(x), iter(g))

    def ehess(self, x, u):
        h = [
            (s @ du.ravel()).reshape(a.shape) - np.sin(np.sum(b * a)) * np.sum(b * du) * b
            for (a, (c, s, b)), du in zip(self._zip(x), leaves(u), strict=True)
        ]
        return rebuild(ambient(x), iter(h))


def setup(manifold, seed):
    rng = np.random.default_rng(seed)
    x = manifold.random_point(rng)
    return rng, x, manifold.random_tangent(x, rng), manifold.random_tangent(x, rng)


def assert_close_tree(a, b, tol):
    for p, q in zip(leaves(a), leaves(b), strict=True):
        assert p.shape == q.shape
        scale = max(1.0, np.abs(q).max(initial=0.0))
        assert np.abs(p - q).max(initial=0.0) <= tol * scale, np.abs(p - q).max()


# ---- the battery ------------------------------------------------------------------


@cases
@seeds
def test_random_point_and_tangent(manifold, hessian_check, seed):
    _, x, v, _ = setup(manifold, seed)
    manifold.check_point(x)
    np.testing.assert_allclose(manifold.norm(x, v), 1.0, rtol=1e-12)
    assert_close_tree(manifold.proj(x, manifold.to_ambient(x, v)), v, 1e-12)
    zero = manifold.zero_vector(x)
    assert manifold.norm(x, zero) == 0.0
    assert_close_tree(manifold.retr(x, zero), x, 1e-14)


@cases
@seeds
def test_total_inner_is_the_metric_summed_over_the_batch(manifold, hessian_check, seed):
    """The optimizers' scalar product (one ``np.vdot`` where the metric is that of the stored
    coordinates) agrees with :meth:`inner`, for one point and for a batch of them."""
    _, x, v, w = setup(manifold, seed)
    value = manifold.total_inner(x, v, w)
    assert isinstance(value, float)
    np.testing.assert_allclose(value, float(np.sum(manifold.inner(x, v, w))), rtol=1e-12, atol=1e-15)
    if manifold.batch_shape_of(x) == () and not isinstance(manifold, Blocks):  # Blocks: no batch axes
        xs = manifold._random_point(np.random.default_rng(seed), (2, 3))
        us = manifold.proj(xs, rebuild(ambient(xs), iter(np.ones(a.shape) for a in leaves(ambient(xs)))))
        np.testing.assert_allclose(
            manifold.total_inner(xs, us, us), float(np.sum(manifold.inner(xs, us, us))), rtol=1e-12
        )


@cases
@seeds
def test_proj_is_an_orthogonal_idempotent_projection(manifold, hessian_check, seed):
    rng, x, _, w = setup(manifold, seed)
    u = rebuild(ambient(x), iter(rng.standard_normal(a.shape) for a in leaves(ambient(x))))
    v = manifold.proj(x, u)
    assert_close_tree(manifold.proj(x, manifold.to_ambient(x, v)), v, 1e-12)
    # The residual is Frobenius-orthogonal to every tangent vector.
    residual = rebuild(u, iter(a - b for a, b in zip(leaves(u), leaves(manifold.to_ambient(x, v)), strict=True)))
    assert abs(frob(residual, manifold.to_ambient(x, w))) < 1e-12 * (1 + frob(u, u))


@cases
@seeds
def test_retraction_is_first_order(manifold, hessian_check, seed):
    """``d/dt R_x(t v)|₀ = v``, as central differences of the ambient arrays."""
    _, x, v, _ = setup(manifold, seed)
    h = 1e-6
    plus, minus = ambient(manifold.retr(x, h * v)), ambient(manifold.retr(x, -h * v))
    fd = rebuild(plus, iter((a - b) / (2 * h) for a, b in zip(leaves(plus), leaves(minus), strict=True)))
    assert_close_tree(fd, manifold.to_ambient(x, v), 1e-7)
    manifold.check_point(manifold.retr(x, 0.3 * v))


@cases
@seeds
def test_gradient_matches_directional_derivatives(manifold, hessian_check, seed):
    rng, x, v, _ = setup(manifold, seed)
    f = Cost(x, rng)
    g = manifold.egrad2rgrad(x, f.egrad(x))
    h = 1e-6
    fd = (f(manifold.retr(x, h * v)) - f(manifold.retr(x, -h * v))) / (2 * h)
    assert abs(manifold.inner(x, g, v) - fd) < 1e-6 * max(1.0, abs(fd))
    assert_close_tree(manifold.proj(x, manifold.to_ambient(x, g)), g, 1e-10)


@cases
@seeds
def test_hessian_matches_finite_differences(manifold, hessian_check, seed):
    rng, x, v, w = setup(manifold, seed)
    f = Cost(x, rng)
    hv = manifold.ehess2rhess(x, f.egrad(x), f.ehess(x, manifold.to_ambient(x, v)), v)
    hw = manifold.ehess2rhess(x, f.egrad(x), f.ehess(x, manifold.to_ambient(x, w)), w)
    assert abs(manifold.inner(x, hv, w) - manifold.inner(x, v, hw)) < 1e-10 * (1 + manifold.norm(x, hv))
    if hessian_check == "gradient":
        # Hess f(x)[v] = proj_x(D grad f(x)[v]) along the curve t ↦ R_x(t v).
        def grad(t):
            y = manifold.retr(x, t * v)
            return manifold.egrad2rgrad(y, f.egrad(y))

        h = 1e-6
        fd = manifold.proj(x, (grad(h) - grad(-h)) / (2 * h))
        assert_close_tree(fd, hv, 1e-6)
    else:
        h = 1e-4

        def at(a, b):
            return f(manifold.retr(x, a * v + b * w))

        mixed = (at(h, h) - at(h, -h) - at(-h, h) + at(-h, -h)) / (4 * h * h)
        assert abs(manifold.inner(x, hv, w) - mixed) < 1e-5 * max(1.0, abs(mixed))


@cases
@seeds
def test_exp_log_dist_transp_where_available(manifold, hessian_check, seed):
    _, x, v, w = setup(manifold, seed)
    v = 0.5 * v
    try:
        y = manifold.exp(x, v)
    except MissingOperationError:
        y = manifold.retr(x, v)
    else:
        manifold.check_point(y)
    try:
        back = manifold.log(x, y)
    except MissingOperationError:
        pass
    else:
        assert_close_tree(back, v, 1e-9)
        np.testing.assert_allclose(manifold.dist(x, y), manifold.norm(x, v), rtol=1e-9)
    t = manifold.transp(x, y, w)
    assert_close_tree(manifold.proj(y, manifold.to_ambient(y, t)), t, 1e-10)


# ---- powers and products ----------------------------------------------------------


def _factor(p, i):
    if isinstance(p, tuple):
        return tuple(_factor(q, i) for q in p)
    return p[i]


POWERS = [
    Power(LieGroupManifold(SO3), 6),
    Power(LieGroupManifold(SE3, geometry="product"), 4),
    Power(Sphere(5), 3),
    Power(Stiefel(4, 2, retraction="polar"), 3),
    Power(Product(LieGroupManifold(SE2), Euclidean(2)), 3),
]


@pytest.mark.parametrize("power", POWERS, ids=repr)
@seeds
def test_power_equals_per_factor(power, seed):
    rng, x, v, w = setup(power, seed)
    base = power.manifold
    f = Cost(x, rng)
    g, y = power.egrad2rgrad(x, f.egrad(x)), power.retr(x, v)
    u = rebuild(ambient(x), iter(rng.standard_normal(a.shape) for a in leaves(ambient(x))))
    proj = power.proj(x, u)
    for i in range(power.shape[0]):
        xi, vi = _factor(x, i), _factor(v, i)
        assert_close_tree(_factor(y, i), base.retr(xi, vi), 1e-14)
        assert_close_tree(_factor(g, i), base.egrad2rgrad(xi, _factor(f.egrad(x), i)), 1e-14)
        assert_close_tree(_factor(proj, i), base.proj(xi, _factor(u, i)), 1e-14)
    total = sum(base.inner(_factor(x, i), _factor(v, i), _factor(w, i)) for i in range(power.shape[0]))
    np.testing.assert_allclose(power.inner(x, v, w), total, rtol=1e-12)
    assert power.dim == power.shape[0] * base.dim


def test_power_of_lie_group_is_one_batched_element():
    power = Power(LieGroupManifold(SO3), 1000)
    x = power.random_point(0)
    assert isinstance(x, SO3) and x.data.shape == (1000, 3, 3)
    assert power.random_tangent(x, 1).shape == (1000, 3)
    assert Power(power, 2).shape == (2, 1000)
    power.check_point(x)
    with pytest.raises(ShapeError, match="batch shape"):
        power.check_point(x[:10])


def test_product_vectors_do_arithmetic():
    u = ProductVector((np.ones(2), np.full(3, 2.0)))
    v = 2.0 * u - u / 2 + np.float64(3.0) * u
    assert isinstance(v, ProductVector)
    np.testing.assert_allclose(v[1], 2.0 * (2.0 - 0.5 + 3.0))
    assert isinstance(-u + u, ProductVector)


# ---- specific geometry ------------------------------------------------------------


@seeds
def test_seed_example_gradient_on_so3(seed):
    """``f(R) = xᵀRᵀARx``: grad f(R) = x^ Rᵀ(A + Aᵀ) R x (the lecture notes' closed form)."""
    rng = np.random.default_rng(seed)
    manifold = LieGroupManifold(SO3)
    r = manifold.random_point(rng)
    x, a = rng.standard_normal(3), rng.standard_normal((3, 3))
    m = r.as_matrix()
    egrad = np.outer((a + a.T) @ m @ x, x)  # ∂/∂R of xᵀRᵀARx
    closed = SO3.hat(x) @ m.T @ (a + a.T) @ m @ x
    np.testing.assert_allclose(manifold.egrad2rgrad(r, egrad), closed, atol=1e-12)
    # ... which is vee(RᵀG − GᵀR), CONVENTIONS §6.
    np.testing.assert_allclose(closed, 2 * SO3.vee(m.T @ egrad), atol=1e-12)


@seeds
def test_special_orthogonal_agrees_with_so2_so3(seed):
    rng = np.random.default_rng(seed)
    for group, n in ((SO2, 2), (SO3, 3)):
        matrix, coords = SpecialOrthogonal(n), LieGroupManifold(group)
        r = group.random(rng)
        omega = rng.uniform(-1.0, 1.0, group.dim)  # |ω| < π: inside the injectivity radius
        tangent = r.as_matrix() @ group.hat(omega)
        np.testing.assert_allclose(matrix.retr(r.as_matrix(), tangent), r.rplus(omega).as_matrix(), atol=1e-14)
        np.testing.assert_allclose(matrix.log(r.as_matrix(), r.rplus(omega).as_matrix()), tangent, atol=1e-12)
        g = rng.standard_normal((n, n))
        # Same directional derivatives; the coordinate metric is half the Frobenius one.
        np.testing.assert_allclose(
            matrix.inner(r.as_matrix(), matrix.egrad2rgrad(r.as_matrix(), g), tangent),
            coords.inner(r, coords.egrad2rgrad(r, g), omega),
            atol=1e-12,
        )


def test_special_orthogonal_random_is_a_rotation():
    x = SpecialOrthogonal(5)._random_point(np.random.default_rng(0), (200,))
    assert (np.linalg.det(x) > 0).all()
    np.testing.assert_allclose(np.swapaxes(x, -1, -2) @ x, np.broadcast_to(np.eye(5), x.shape), atol=1e-14)


def test_geometries_of_se3_differ_only_in_the_translation_frame():
    group, product = LieGroupManifold(SE3), LieGroupManifold(SE3, geometry="product")
    x = SE3.random(0)
    v = np.r_[1.0, 2.0, 3.0, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(group.retr(x, v).translation(), x.translation() + x.rotation().act(v[:3]))
    np.testing.assert_allclose(product.retr(x, v).translation(), x.translation() + v[:3])
    w = np.r_[0.0, 0.0, 0.0, 0.1, -0.2, 0.3]
    np.testing.assert_allclose(group.retr(x, w).as_matrix(), product.retr(x, w).as_matrix(), atol=1e-15)


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_the_decoupled_retraction_moves_positions_along_straight_lines(group):
    """``(R Exp(θ), t + Rρ)``: the group's coordinates to first order (every right Jacobian
    applies), the translation moved by ``Rρ`` whatever the rotation step, and ``log`` its inverse."""
    decoupled, plain = LieGroupManifold(group, geometry="decoupled"), LieGroupManifold(group)
    x = group.random(0)
    d = group.point_dim
    v = np.random.default_rng(1).standard_normal(group.dim)
    v[:d] *= 10.0  # a long step, the rotation below π (so that log inverts it)
    v[d:] *= 2.5 / np.linalg.norm(v[d:])
    y = decoupled.retr(x, v)
    np.testing.assert_allclose(y.translation(), x.translation() + x.rotation().act(v[:d]), atol=1e-12)
    np.testing.assert_allclose(y.rotation().as_matrix(), x.rotation().rplus(v[d:]).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(decoupled.log(x, y), v, atol=1e-10)
    for h in (1e-4, 1e-5):  # the same curve as X·Exp(τ) to first order
        gap = decoupled.retr(x, h * v).as_matrix() - plain.retr(x, h * v).as_matrix()
        assert np.abs(gap).max() < 10 * h * h * np.dot(v, v)
    assert repr(decoupled) == f"LieGroupManifold({group.__name__}, geometry='decoupled')"


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
@pytest.mark.parametrize("n", [2, 9, _kernels.VM_POINTS, _kernels.VM_POINTS + 1])
@pytest.mark.parametrize("path", PATHS[:2])
def test_batches_retract_in_native_code_and_on_the_virtual_machine_as_the_group_does(group, n, path, monkeypatch):
    """SE(2)/SE(3) batches retract in native code or (up to ``VM_POINTS`` elements) on CasADi's
    virtual machine: ``X·Exp(τ)`` to round-off, at ``τ = 0``, small and half-turn steps; a
    non-finite step raises as ``rplus`` does, and a huge one goes through the scale-safe kernels."""
    use(path, monkeypatch)
    manifold = Power(LieGroupManifold(group), n)
    rng = np.random.default_rng(n)
    x = group.random(rng, (n,))
    v = rng.standard_normal((n, group.dim))
    v[0] = 0.0
    v[1, group.point_dim :] *= 1e-9
    v[-1, group.point_dim :] *= np.pi / np.linalg.norm(v[-1, group.point_dim :])
    np.testing.assert_allclose(manifold.retr(x, v).as_matrix(), x.rplus(v).as_matrix(), rtol=0, atol=1e-14)
    v[1, -1] = 1e25
    np.testing.assert_array_equal(manifold.retr(x, v).as_matrix(), x.rplus(v).as_matrix())
    v[1, -1] = np.nan
    with pytest.raises(NonFiniteError, match="tau"):
        manifold.retr(x, v)


def test_landmark_graphs_retract_poses_decoupled():
    from manopt_lie.problems import synthetic

    graph = synthetic.landmark_world(20, 5, seed=0).graph
    assert "geometry='decoupled'" in repr(graph.manifold)


# ---- errors -----------------------------------------------------------------------


def test_check_point_rejects_bad_points():
    with pytest.raises(NotOnManifoldError, match="Sphere"):
        Sphere(3).check_point(np.array([1.0, 1.0, 0.0]))
    with pytest.raises(ShapeError):
        Sphere(3).check_point(np.zeros(4))
    with pytest.raises(NonFiniteError):
        Stiefel(3, 2).check_point(np.full((3, 2), np.nan))
    with pytest.raises(NotOnManifoldError, match="det"):
        SpecialOrthogonal(3).check_point(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ShapeError, match="SO3"):
        LieGroupManifold(SO3).check_point(np.eye(3))
    with pytest.raises(ValueError):
        Product(Sphere(3), Euclidean(2)).check_point((np.array([1.0, 0.0, 0.0]),))


def test_constructor_errors_and_missing_operations():
    for bad in (
        lambda: Stiefel(2, 3),
        lambda: Stiefel(3, 2, retraction="cayley"),
        lambda: Sphere(1),
        lambda: Euclidean(0),
        lambda: Power(Sphere(3), 0),
        lambda: LieGroupManifold(SO3, geometry="product"),
        lambda: LieGroupManifold(SO3, geometry="decoupled"),
        lambda: LieGroupManifold(SE3, geometry="x"),
    ):
        with pytest.raises(ValueError):
            bad()
    with pytest.raises(TypeError):
        LieGroupManifold(np.eye(3))
    with pytest.raises(MissingOperationError, match="log"):
        Stiefel(4, 2).log(np.eye(4)[:, :2], np.eye(4)[:, :2])
