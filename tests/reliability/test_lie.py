"""Issue 13, item 4: Lie numerics over the whole float range (one regression test per audit defect).

RuntimeWarnings are errors in this suite (pyproject), so every test here also proves that no
overflow or invalid operation happens on the way.
"""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import S3, SE2, SE3, SE23, SO2, SO3, Bundle, NonFiniteError, NotInGroupError, Rn, Sim2, Sim3
from manopt_lie.lie import _se3, _so3

GROUPS = [SO2, SO3, SE2, SE3, Sim3, Sim2, SE23, S3, Rn(3), Bundle(SO3, Rn(3))]
ids = [g.__name__ for g in GROUPS]
ROTATION = {SO2: slice(0, 1), SO3: slice(0, 3), SE2: slice(2, 3), SE3: slice(3, 6), Sim3: slice(3, 6)}
ROTATION[SE23] = slice(6, 9)
ROTATION[Sim2] = slice(2, 3)
# Norms from the denormal range to the largest float, across every internal switch (1e20 …).
SCALES = [5e-324, 1e-300, 1e-160, 1e-20, 1e20, 1e25, 1e50, 1e100, 1e154, 1e160, 1e300, 1e308]


def _rotation_error(m: np.ndarray, d: int) -> float:
    r = m[..., :d, :d]
    return float(np.abs(np.swapaxes(r, -1, -2) @ r - np.eye(d)).max())


@pytest.mark.parametrize("group", GROUPS, ids=ids)
@pytest.mark.parametrize("scale", SCALES)
def test_exp_and_jacobians_are_finite_for_every_finite_tangent(group, scale, rng):
    """Audit: ``SO3.exp``/``SE3.exp`` of a tangent of norm > 1e154 returned all-nan elements (θ²
    overflowed); the Jacobians did too from θ ≈ 1e61 on (θ³…θ⁵ in the closed forms)."""
    tau = scale * rng.uniform(-1.0, 1.0, (64 if group not in (Sim3, Sim2) else 8, group.dim))
    if group in ROTATION and scale > 1e300:  # translations of 1e308 overflow Jr's ~|ρ|·θ entries honestly
        tau[..., np.arange(group.dim) < ROTATION[group].start] *= 1e300 / scale
    if group in (Sim3, Sim2):  # |σ| ≤ 700 (e^σ representable) and |ρ|·e^σ finite, else RangeError
        tau[..., -1] = np.clip(tau[..., -1], -50.0, 50.0)
        tau[..., : group.point_dim] = np.clip(tau[..., : group.point_dim], -1e250, 1e250)
    x = group.exp(tau)
    x.validate(tol=1e-12)  # finite and in the group: orthonormal rotation blocks, exact last row
    p = rng.standard_normal((len(tau), group.point_dim))
    for out in (x.data, x.log(), x.log(jac=True)[1], group.jr(tau), group.jl(tau), x.adjoint(), x.act(p)):
        assert np.isfinite(out).all()
    if group in ROTATION:
        d = group.point_dim
        r = x.rotation().as_matrix() if group in (Sim3, Sim2) else x.as_matrix()[..., :d, :d]
        assert _rotation_error(r, d) < 1e-14
        assert (np.linalg.norm(x.log()[..., ROTATION[group]], axis=-1) <= np.pi + 1e-15).all()


@pytest.mark.parametrize("group", [SO3, SE3], ids=["SO3", "SE3"])
def test_huge_angle_is_the_rotation_of_that_angle(group):
    """A huge angle is the rotation its floating-point value denotes: ``sin``/``cos`` of θ/2 reduce
    modulo the exact π. Cross-check at θ = 1e30 (beyond the switch 1e20) with an independent route:
    the angle reduced exactly in rational arithmetic (``fractions``) against 2π to 60 digits."""
    from fractions import Fraction

    theta = 1e30
    two_pi = Fraction(
        "6.283185307179586476925286766559005768394338798750211641949889184615632812572417997256069650684234136"
    )
    reduced = float(Fraction(theta) - (Fraction(theta) // two_pi) * two_pi)
    axis = np.array([2.0, -1.0, 2.0]) / 3.0
    tau = theta * axis if group is SO3 else np.r_[0.0, 0.0, 0.0, theta * axis]
    ref = SO3.exp(reduced * axis).as_matrix()
    np.testing.assert_allclose(group.exp(tau).as_matrix()[:3, :3], ref, atol=1e-14)


def test_se3_translation_of_a_huge_angle_is_exact_not_reduced():
    """SE(3)'s translation ``Jl(θ)ρ`` depends on θ itself, not on θ mod 2π, so it is not reduced: it is
    computed exactly, ``ρ + (1 − cos θ)/θ u×ρ + (1 − sin θ/θ) u×(u×ρ) → u uᵀρ`` as θ → ∞."""
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    rho = np.array([1.0, -2.0, 0.5])
    for theta in (1e20, 1e100, 1e300):
        t = SE3.exp(np.r_[rho, theta * axis]).translation()
        np.testing.assert_allclose(t, axis * (axis @ rho), atol=1e-15)
    # Continuity across the switch at θ = 1e20 (the generic and the scale-safe forms agree).
    below, above = np.nextafter(1e20, 0.0), 1e20
    for a, b in [(SE3.exp(np.r_[rho, below * axis]), SE3.exp(np.r_[rho, above * axis]))]:
        np.testing.assert_allclose(a.translation(), b.translation(), atol=1e-15)


def test_scale_safe_forms_agree_with_the_closed_forms(rng):
    """The forms used beyond 1e20 are exact rewrites: at ordinary angles they match the closed forms."""
    for angle in (0.5, 3.0, 5.0, 40.0, 1e3):
        w = angle * rng.standard_normal((20, 3)) / np.sqrt(3.0)
        v = rng.standard_normal((20, 3))
        np.testing.assert_allclose(_so3._exp_huge(w), _so3.exp.__wrapped__(w), atol=1e-15)
        np.testing.assert_allclose(_so3._jr_huge(w), _so3.jr.__wrapped__(w), atol=1e-15)
        ji = _so3.jr_inv.__wrapped__(w)
        np.testing.assert_allclose(_so3._jr_inv_huge(w), ji, atol=1e-14 * np.abs(ji).max())
        np.testing.assert_allclose(_so3._jl_apply_huge(w, v), _so3.jl_apply.__wrapped__(w, v), atol=1e-14)
        jv = _so3.jl_inv_apply.__wrapped__(w, v)
        np.testing.assert_allclose(_so3._jl_inv_apply_huge(w, v), jv, atol=1e-14 * np.abs(jv).max())
        np.testing.assert_allclose(_se3._q_matrix_huge(v, w), _se3.q_matrix.__wrapped__(v, w), atol=1e-14)


def test_mixed_batch_keeps_ordinary_rows_bit_for_bit(rng):
    """Only the huge rows take the scale-safe path; the others are computed exactly as before."""
    tau = rng.standard_normal((10, 6))
    plain = SE3.exp(tau).data.copy(), SE3.jr(tau).copy()
    mixed = tau.copy()
    mixed[3, 3:] *= 1e200
    x, j = SE3.exp(mixed), SE3.jr(mixed)
    keep = np.arange(10) != 3
    np.testing.assert_array_equal(x.data[keep], plain[0][keep])
    np.testing.assert_array_equal(j[keep], plain[1][keep])
    assert np.isfinite(x.data).all() and np.isfinite(j).all()


def test_so2_and_se2_huge_angles(rng):
    """sin/cos of a huge angle are finite (exact argument reduction) but meaningless beyond ~1e16."""
    theta = np.array([1e16, 1e100, 1e300, 1.7e308])
    x = SO2.from_angle(theta)
    np.testing.assert_allclose(x.as_matrix()[..., 0, 0], np.cos(theta), rtol=0, atol=0)
    y = SE2.exp(np.stack([np.ones(4), -np.ones(4), theta], axis=-1))
    assert np.isfinite(y.data).all() and np.isfinite(SE2.jr(y.log())).all()
    # V(θ)ρ = O(|ρ|/θ): the translation of a huge angle vanishes.
    assert np.abs(y.translation()[1:]).max() < 1e-15


def test_non_finite_elements_are_refused_by_validation():
    """Audit: an all-nan element (from the old exp) passed ``check_point``. ``from_matrix`` and the
    element constructor refuse nan/inf with NonFiniteError, and ``validate`` (which a manifold's
    ``check_point`` can call) checks an element that was wrapped without checks."""
    for group in (SO2, SO3, SE2, SE3, Rn(3)):
        m = np.array(group.identity().as_matrix())
        m[0, -1] = np.nan
        with pytest.raises(NonFiniteError):
            group.from_matrix(m)
        with pytest.raises(NonFiniteError):
            group.from_matrix(m, project=True)
        bad = group._wrap(np.full(group.identity().data.shape, np.nan))
        with pytest.raises(NonFiniteError, match="non-finite"):
            bad.validate()
        assert group.identity().validate() is not None
    off = SO3._wrap(np.diag([1.0, 1.0, 2.0]))
    with pytest.raises(NotInGroupError, match="not orthonormal"):
        off.validate(name="x")


@pytest.mark.parametrize("scale", [1e-300, 1e-200, 1e-160, 1e-100, 1e100, 1e200, 1e300, 1e308])
def test_from_quaternion_normalizes_at_any_scale(scale, rng):
    """Audit: ``from_quaternion(q, normalize=True)`` of a tiny quaternion (|q| = 1e-160: the squares
    underflow) gave RᵀR − I = 2e-5; a huge one (1e200) overflowed to the identity."""
    q = rng.standard_normal((50, 4))
    q /= np.abs(q).max(axis=-1, keepdims=True)
    r = SO3.from_quaternion(scale * q, normalize=True)
    assert _rotation_error(r.as_matrix(), 3) < 4e-15
    np.testing.assert_allclose(r.as_matrix(), SO3.from_quaternion(q, normalize=True).as_matrix(), atol=1e-15)
    with pytest.raises(NotInGroupError, match="not unit"):
        SO3.from_quaternion(scale * q)  # without normalize=True a non-unit quaternion is refused


def test_zero_quaternion_is_refused_naming_it():
    q = np.ones((3, 4))
    q[2] = 0.0
    for normalize in (True, False):
        with pytest.raises(NotInGroupError, match=r"batch index \(2,\) is zero"):
            SO3.from_quaternion(q, normalize=normalize)
    with pytest.raises(NotInGroupError, match="zero"):
        SO3.from_quaternion([0.0, 0.0, 0.0, 5e-324 * 0], normalize=True)
    # The smallest subnormal is not zero: it normalizes.
    assert _rotation_error(SO3.from_quaternion([0.0, 0.0, 0.0, 5e-324], normalize=True).as_matrix(), 3) == 0.0


@pytest.mark.parametrize("group", [SO2, SO3, SE2, SE3], ids=["SO2", "SO3", "SE2", "SE3"])
@pytest.mark.parametrize("scale", [1e-300, 1e300, 1.7e308])
def test_project_extreme_matrices(group, scale, rng):
    """``from_matrix(project=True)`` of matrices with entries ±1e300 (or denormal-sized) gives rotations."""
    m = scale * rng.choice([-1.0, 1.0], size=(20, *group.storage_shape))
    d = group.point_dim
    if group in (SE2, SE3):
        m[..., d, :] = 0.0
        m[..., d, d] = 1.0
    x = group.from_matrix(m, project=True)
    assert np.isfinite(x.data).all() and _rotation_error(x.as_matrix(), d) < 1e-14
    zero = group.from_matrix(np.zeros(group.storage_shape) + np.eye(group.storage_shape[0]) * 0.0, project=True)
    assert _rotation_error(zero.as_matrix(), d) < 4e-15


def test_sim3_unrepresentable_results_are_refused():
    """|σ| > 700, or a translation |ρ|·e^σ beyond the float range: RangeError naming the row."""
    from manopt_lie import RangeError

    tau = np.zeros((3, 7))
    tau[2, :3], tau[2, 6] = 1e300, 600.0
    with pytest.raises(RangeError, match=r"batch index \(2,\) overflows"):
        Sim3.exp(tau)
    tau[2] = 0.0
    tau[1, 6] = -750.0
    with pytest.raises(RangeError, match=r"σ = -750"):
        Sim3.exp(tau)


@pytest.mark.parametrize("group", [Sim3, Sim2, SE23, S3, Bundle(SO3, Rn(3))], ids=lambda g: g.__name__)
@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_project_extreme_matrices_new_groups(group, scale, rng):
    """The new groups' ``from_matrix(project=True)`` at entries ~1e±300: finite elements, finite Log."""
    m = np.array(group.random(rng, (10,)).as_matrix())
    d = 2 if group is Sim2 else 3
    m[..., :d, :d] = scale * (m[..., :d, :d] + 0.1 * rng.standard_normal((10, d, d)))
    x = group.from_matrix(m, project=True)
    x.validate()
    assert np.isfinite(x.data).all() and np.isfinite(x.log()).all()


def test_sim3_projection_refuses_scales_beyond_the_float_range(rng):
    from manopt_lie import RangeError

    m = np.array(Sim3.identity((2,)).as_matrix())
    m[1, :3, :3] = 1.7e308 * np.array([[1.0, 1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, -1.0]])  # s ≈ 1.6 × 1.7e308
    with pytest.raises((RangeError, NotInGroupError), match=r"batch index \(1,\)"):
        Sim3.from_matrix(m, project=True)
