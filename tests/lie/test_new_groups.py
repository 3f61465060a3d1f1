"""Sim3, SE23, Bundle (issue 18) beyond the battery; ad, BCH, distances, integrate, frames of covariances."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm, logm

from manopt_lie import (
    S3,
    SE3,
    SE23,
    SO2,
    SO3,
    Bundle,
    LieGroup,
    RangeError,
    Rn,
    Sim2,
    Sim3,
    angular_distance,
    chordal_distance,
    double_geodesic_distance,
    integrate,
    left_to_right_covariance,
    quaternion_distance,
    right_to_left_covariance,
)
from manopt_lie.lie.base import LieGroup as _Base

from .helpers import GROUPS, assert_same, group_id

groups = pytest.mark.parametrize("group", GROUPS, ids=group_id)


@pytest.mark.parametrize("group", [Sim3, Sim2, SE23], ids=group_id)
def test_exp_log_against_matrix_exponential(group, rng):
    """The closed forms are ``expm``/``logm`` of the Lie algebra matrices (hat of CONVENTIONS §2)."""
    for _ in range(20):
        tau = rng.standard_normal(group.dim)
        x = group.exp(tau)
        np.testing.assert_allclose(x.as_matrix(), expm(group.hat(tau)), atol=1e-13 * np.abs(x.as_matrix()).max())
        tau = 0.5 * rng.standard_normal(group.dim)  # principal logarithm (angle < π)
        np.testing.assert_allclose(group.vee(np.real(logm(group.exp(tau).as_matrix()))), tau, atol=1e-11)
        np.testing.assert_allclose(group.exp(tau).log(), tau, atol=1e-14)


def test_sim3_reduces_to_se3_at_unit_scale(rng):
    tau = rng.standard_normal((50, 6))
    tau7 = np.concatenate([tau, np.zeros((50, 1))], axis=-1)
    np.testing.assert_allclose(Sim3.exp(tau7).as_matrix(), SE3.exp(tau).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(Sim3.jr(tau7)[..., :6, :6], SE3.jr(tau), atol=1e-13)
    np.testing.assert_allclose(Sim3.exp(tau7).log()[..., :6], SE3.exp(tau).log(), atol=1e-13)
    np.testing.assert_allclose(Sim3.exp(tau7).adjoint()[..., :6, :6], SE3.exp(tau).adjoint(), atol=1e-14)


def test_sim2_is_sim3_in_the_plane_and_se2_at_unit_scale(rng):
    from manopt_lie import SE2

    tau = rng.standard_normal((50, 4))
    plane = np.zeros((50, 7))
    plane[:, [0, 1, 5, 6]] = tau
    keep = [0, 1, 3]
    np.testing.assert_allclose(Sim3.exp(plane).as_matrix()[:, keep][:, :, keep], Sim2.exp(tau).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(Sim3.jr(plane)[:, [0, 1, 5, 6]][:, :, [0, 1, 5, 6]], Sim2.jr(tau), atol=1e-12)
    tau[:, 3] = 0.0
    np.testing.assert_allclose(Sim2.exp(tau).as_matrix(), SE2.exp(tau[:, :3]).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(Sim2.jr(tau)[:, :3, :3], SE2.jr(tau[:, :3]), atol=1e-13)


def test_se23_with_zero_velocity_is_se3(rng):
    tau = rng.standard_normal((50, 6))
    tau9 = np.concatenate([tau[:, :3], np.zeros((50, 3)), tau[:, 3:]], axis=-1)
    x = SE23.exp(tau9)
    np.testing.assert_allclose(x.position(), SE3.exp(tau).translation(), atol=1e-15)
    assert np.abs(x.velocity()).max() == 0.0
    keep = np.r_[0:3, 6:9]
    np.testing.assert_allclose(SE23.jr(tau9)[:, keep][:, :, keep], SE3.jr(tau), atol=1e-15)
    np.testing.assert_allclose(x.act(tau[:, :3]), SE3.exp(tau).act(tau[:, :3]), atol=1e-14)


@pytest.mark.parametrize("sigma", [-700.0, -300.0, -50.0, -1.0, -1e-9, 0.0, 1e-9, 1.0, 50.0, 300.0, 700.0])
def test_sim3_large_and_tiny_log_scales(sigma, rng):
    """|σ| up to 700: finite, round trips relative to the size of the element; Jr·Jr⁻¹ = I."""
    tau = rng.standard_normal((20, 7))
    tau[:, 6] = sigma
    x = Sim3.exp(tau)
    x.validate()
    np.testing.assert_allclose(x.scale(), np.exp(sigma), rtol=1e-14)
    back = x.log()
    np.testing.assert_allclose(back[:, 3:], tau[:, 3:], atol=1e-12 * max(1.0, abs(sigma)))
    np.testing.assert_allclose(back[:, :3], tau[:, :3], rtol=1e-10, atol=1e-10)
    if abs(sigma) <= 50:  # the doubling's Ad products reach e^{±|σ|}: Jr is exact to ~1e-16·e^|σ|
        jr, ji = Sim3.jr(tau), Sim3.jr_inv(tau)
        assert np.isfinite(jr).all() and np.isfinite(ji).all()
        np.testing.assert_allclose(ji @ jr, np.broadcast_to(np.eye(7), jr.shape), atol=1e-9)


def test_sim3_refuses_unrepresentable_scales():
    with pytest.raises(RangeError, match=r"σ = 710 at batch index \(1,\)"):
        Sim3.exp(np.array([np.zeros(7), np.r_[np.zeros(6), 710.0]]))
    assert issubclass(RangeError, ValueError)


def test_sim3_from_matrix_and_projection(rng):
    x = Sim3.random(rng, (5,))
    assert_same(Sim3.from_matrix(x.as_matrix()), x)
    noisy = x.as_matrix().copy()
    noisy[..., :3, :3] += 1e-4 * rng.standard_normal((5, 3, 3)) * x.scale()[:, None, None]
    snapped = Sim3.from_matrix(noisy, project=True)
    np.testing.assert_allclose(snapped.scale(), x.scale(), rtol=1e-3)
    assert angular_distance(snapped, x).max() < 1e-3
    bad = x.as_matrix().copy()
    bad[0, :3, :3] = np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError):
        Sim3.from_matrix(bad)


def test_bundle_parts_and_identities(rng):
    b = Bundle(SO3, Rn(3), SE23)
    assert b is Bundle(SO3, Rn(3), SE23) and b.dim == 15 and b.point_dim == 9
    r, v, e = SO3.random(rng, (4,)), Rn(3).random(rng, (4,)), SE23.random(rng, (4,))
    x = b.from_parts(r, v, e)
    parts = x.split()
    assert_same(parts[0], r) and assert_same(parts[2], e)
    tau = rng.standard_normal((4, 15))
    y = x.rplus(tau)
    assert_same(y.split()[0], r.rplus(tau[:, :3]))
    np.testing.assert_allclose(y.split()[1].data, v.data + tau[:, 3:6])
    assert_same(y.split()[2], e.rplus(tau[:, 6:]))
    assert_same(b.from_matrix(x.as_matrix()), x)
    with pytest.raises(TypeError):
        Bundle()
    with pytest.raises(TypeError):
        Bundle(SO3, 3)


@pytest.mark.parametrize("group", [Bundle(SO3, Rn(3)), Sim3, Sim2, SE23, S3], ids=group_id)
def test_lie_group_manifold_optimizes_the_new_groups(group):
    """``LieGroupManifold(G)`` with a trust-region solve of the chordal cost ``½‖X − T‖_F²``."""
    from manopt_lie.manifolds.lie_group import LieGroupManifold
    from manopt_lie.optim import Problem, StoppingCriteria, get_optimizer

    target = group.random(1)
    t = target.as_matrix()
    problem = Problem(
        LieGroupManifold(group),
        cost=lambda x: 0.5 * np.sum((x.as_matrix() - t) ** 2),
        egrad=lambda x: x.as_matrix() - t,
    )
    res = get_optimizer("tr").make(StoppingCriteria(grad_rtol=1e-10)).solve(problem, group.identity())
    assert np.abs(res.x.rminus(target)).max() < 1e-9


# ---- ad and BCH ---------------------------------------------------------------------------


@groups
def test_ad_is_the_commutator_and_the_derivative_of_Ad(group, rng):
    tau, sigma = rng.standard_normal((2, 6, group.dim))
    comm = group.hat(tau) @ group.hat(sigma) - group.hat(sigma) @ group.hat(tau)
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", group.ad(tau), sigma), group.vee(comm), atol=1e-13)
    np.testing.assert_allclose(group.ad(tau), _Base._ad.__func__(group, tau), atol=1e-14)
    h = 1e-6
    fd = (group.exp(h * tau).adjoint() - group.exp(-h * tau).adjoint()) / (2 * h)
    np.testing.assert_allclose(fd, group.ad(tau), atol=1e-8 * max(1.0, np.abs(fd).max()))


@groups
def test_bch_orders(group, rng):
    """``Log(Exp(ετ)Exp(εσ)) − bch`` shrinks like ε^{order+1}."""
    tau, sigma = rng.standard_normal((2, group.dim))
    errs = {}
    for order in (1, 2, 3):
        errs[order] = []
        for eps in (1e-2, 1e-3):
            exact = (group.exp(eps * tau) @ group.exp(eps * sigma)).log()
            errs[order].append(np.abs(exact - group.bch(eps * tau, eps * sigma, order=order)).max())
    for order in (1, 2, 3):
        small, tiny = errs[order]
        if small > 1e-13:  # commutative groups: exact from order 1 on
            assert tiny < small * 10.0 ** (-order - 1) * 3, (order, errs)
    with pytest.raises(ValueError, match="order"):
        group.bch(tau, sigma, order=4)


# ---- frames of covariances -----------------------------------------------------------------


@groups
def test_right_to_left_covariance_for_every_group(group, rng):
    """``X ⊕ τ = (Ad_X τ) ⊕ X``, so a right covariance P is ``Ad P Adᵀ`` on the left; round trip."""
    x = group.random(rng, (3,))
    tau = rng.standard_normal((3, group.dim))
    assert_same(x.rplus(tau), x.lplus(np.einsum("...ij,...j->...i", x.adjoint(), tau)), tol=1e-9)
    a = rng.standard_normal((group.dim, group.dim))
    p = a @ a.T + np.eye(group.dim)
    left = right_to_left_covariance(x, p)
    np.testing.assert_allclose(left, x.adjoint() @ p @ np.swapaxes(x.adjoint(), -1, -2))
    np.testing.assert_allclose(left_to_right_covariance(x, left), np.broadcast_to(p, left.shape), atol=1e-8)


# ---- distances (VNAV notes §2.8) ------------------------------------------------------------


def test_rotation_distances_and_their_relations(rng):
    ra, rb = SO3.random(rng, (500,)), SO3.random(rng, (500,))
    theta = angular_distance(ra, rb)
    np.testing.assert_allclose(theta, ra.dist(rb), atol=1e-14)  # geodesic = |Log(RaᵀRb)| (2.68)
    assert (theta >= 0).all() and (theta <= np.pi + 1e-15).all()
    np.testing.assert_allclose(chordal_distance(ra, rb), 2 * np.sqrt(2) * np.sin(theta / 2), atol=1e-14)  # (2.74)
    dq = quaternion_distance(ra, rb)
    np.testing.assert_allclose(dq, 2 * np.sin(theta / 4), atol=1e-14)
    assert (dq <= theta / 2 + 1e-15).all() and (theta / np.pi <= dq + 1e-15).all()
    # q and −q are the same rotation (2.78–2.79).
    np.testing.assert_allclose(quaternion_distance(ra.as_quaternion(), -rb.as_quaternion()), dq, atol=1e-15)
    rc = SO3.random(rng, (500,))  # bi-invariance (2.69, 2.76) and the triangle inequality (2.66)
    np.testing.assert_allclose(angular_distance(rc @ ra, rc @ rb), theta, atol=1e-12)
    np.testing.assert_allclose(chordal_distance(ra @ rc, rb @ rc), chordal_distance(ra, rb), atol=1e-14)
    assert (angular_distance(ra, rc) <= theta + angular_distance(rb, rc) + 1e-12).all()
    # Small angles: chordal ≈ √2 · geodesic (2.75).
    near = ra.rplus(1e-5 * rng.standard_normal((500, 3)))
    np.testing.assert_allclose(chordal_distance(ra, near), np.sqrt(2) * angular_distance(ra, near), rtol=1e-9)
    a2, b2 = SO2.random(rng, (100,)), SO2.random(rng, (100,))
    np.testing.assert_allclose(
        chordal_distance(a2, b2), 2 * np.sqrt(2) * np.sin(angular_distance(a2, b2) / 2), atol=1e-14
    )


def test_pose_distances_and_their_relations(rng):
    ta, tb, tc = SE3.random(rng, (300,)), SE3.random(rng, (300,)), SE3.random(rng, (300,))
    dt = np.linalg.norm(tb.translation() - ta.translation(), axis=-1)
    theta = angular_distance(ta, tb)
    np.testing.assert_allclose(double_geodesic_distance(ta, tb), np.hypot(theta, dt), atol=1e-14)  # (2.81)
    np.testing.assert_allclose(double_geodesic_distance(ta, tb, weight=2.0), np.hypot(theta, 2 * dt), atol=1e-14)
    np.testing.assert_allclose(ta.chordal_dist(tb), np.hypot(chordal_distance(ta, tb), dt), atol=1e-13)  # (2.85)
    # Left invariance (2.82, 2.83, 2.86).
    np.testing.assert_allclose(double_geodesic_distance(tc @ ta, tc @ tb), double_geodesic_distance(ta, tb), atol=1e-12)
    np.testing.assert_allclose((tc @ ta).dist(tc @ tb), ta.dist(tb), atol=1e-11)
    np.testing.assert_allclose((tc @ ta).chordal_dist(tc @ tb), ta.chordal_dist(tb), atol=1e-12)
    with pytest.raises(TypeError):
        double_geodesic_distance(ta, SO3.identity())


# ---- integrate ---------------------------------------------------------------------------


@pytest.mark.parametrize("group", [SE3, SE23, Sim3, Bundle(SO3, Rn(3))], ids=group_id)
@pytest.mark.parametrize("frame", ["right", "left"])
@pytest.mark.parametrize("n", [1, 2, 7, 16])
def test_integrate_is_the_sequential_product(group, frame, n, rng):
    x0 = group.random(rng, (2,))
    u = 0.3 * rng.standard_normal((n, 2, group.dim))
    traj = integrate(x0, u, frame=frame)
    assert traj.batch_shape == (n + 1, 2)
    x = x0
    assert_same(traj[0], x0)
    for k in range(n):
        x = x.rplus(u[k]) if frame == "right" else x.lplus(u[k])
        assert_same(traj[k + 1], x, tol=1e-12 * max(1.0, np.abs(x.as_matrix()).max()))


@pytest.mark.parametrize("frame", ["right", "left"])
def test_integrate_covariances_against_monte_carlo(frame):
    """Sampled increments, integrated: the sample covariance of ``X_n ⊖ X̄_n`` is P_n; the mean
    Mahalanobis norm is dim within 5 of its standard deviations (fixed seed)."""
    rng = np.random.default_rng(7)
    group, n, samples = SE3, 20, 4000
    x0 = group.random(rng)
    u = 0.3 * rng.standard_normal((n, group.dim))
    q = np.diag([1e-4, 1e-4, 2e-4, 4e-5, 4e-5, 1e-5])
    p0 = 1e-5 * np.eye(group.dim)
    traj, p = integrate(x0, u, q, frame=frame, initial_covariance=p0)
    assert p.shape == (n + 1, 6, 6)
    start = x0.rplus(rng.multivariate_normal(np.zeros(6), p0, size=samples))
    noise = rng.multivariate_normal(np.zeros(6), q, size=(n, samples))
    runs = integrate(start, u[:, None, :] + noise, frame=frame)
    d = runs[-1].rminus(traj[-1])
    maha = np.einsum("ni,ij,nj->n", d, np.linalg.inv(p[-1]), d).mean()
    assert abs(maha - group.dim) < 5 * np.sqrt(2 * group.dim / samples)
    sample_cov = d.T @ d / samples
    sd = np.sqrt((np.outer(np.diag(p[-1]), np.diag(p[-1])) + p[-1] ** 2) / samples)  # std of each entry
    assert (np.abs(sample_cov - p[-1]) < 5 * sd).all()


def test_integrate_bad_input():
    with pytest.raises(ValueError, match="frame"):
        integrate(SE3.identity(), np.zeros((3, 6)), frame="global")
    with pytest.raises(ValueError):
        integrate(SE3.identity(), np.zeros(6))


def test_left_group_exports():
    assert all(isinstance(g, type) and issubclass(g, LieGroup) for g in (Sim3, SE23, Bundle(SO3)))


# ---- S3 ------------------------------------------------------------------------------------


def test_s3_is_a_double_cover_of_so3(rng):
    tau = 2.0 * rng.standard_normal((200, 3))
    q = S3.exp(tau)
    np.testing.assert_allclose(q.as_matrix(), SO3.exp(tau).as_matrix(), atol=1e-14)  # the same rotation
    np.testing.assert_allclose(np.linalg.norm(q.data, axis=-1), 1.0, atol=1e-15)
    minus = S3(-q.data)
    np.testing.assert_allclose(minus.log(), q.log(), atol=1e-14)  # Log takes the shorter of ±q
    assert (np.linalg.norm(q.log(), axis=-1) <= np.pi + 1e-15).all()
    np.testing.assert_allclose(q.log(), SO3.exp(tau).log(), atol=1e-12)
    # Exp(θ) for |θ| ∈ (2π, 4π) is −Exp(θ − 2π u): the cover, seen in the stored quaternions.
    u = tau / np.linalg.norm(tau, axis=-1, keepdims=True)
    np.testing.assert_allclose(S3.exp(tau + 2 * np.pi * u).data, -q.data, atol=1e-13)
    # A homomorphism onto SO3: R(q₁ ⊗ q₂) = R(q₁) R(q₂); conversions both ways.
    p = S3.random(rng, (200,))
    np.testing.assert_allclose((q @ p).as_matrix(), q.as_matrix() @ p.as_matrix(), atol=1e-14)
    assert_same(S3.from_rotation(q.to_rotation()), q)
    np.testing.assert_allclose(S3.from_matrix(q.as_matrix()).data[..., 3] >= 0, True)
    np.testing.assert_allclose(
        quaternion_distance(q.as_quaternion(), p.as_quaternion()),
        quaternion_distance(q.to_rotation(), p.to_rotation()),
        atol=1e-14,
    )
    x = p.act(tau)
    np.testing.assert_allclose(x, p.to_rotation().act(tau), atol=1e-14)


def test_s3_validation():
    from manopt_lie import NotInGroupError

    with pytest.raises(NotInGroupError, match="not unit"):
        S3([0.0, 0.0, 0.0, 2.0])
    np.testing.assert_allclose(S3.from_matrix(np.diag([1.0, -1.0, -1.0])).data, [1.0, 0.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(S3._project(np.array([0.0, 0.0, 1e-200, 1e-200])), [0, 0, 2**-0.5, 2**-0.5])
