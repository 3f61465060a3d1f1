"""Construction, batching, broadcasting, conversions and error handling."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

from manopt_lie import (
    SE2,
    SE3,
    SO2,
    SO3,
    NonFiniteError,
    NotInGroupError,
    Rn,
    ShapeError,
)

from .helpers import GROUPS, assert_same, group_id

groups = pytest.mark.parametrize("group", GROUPS, ids=group_id)


# ---- errors -----------------------------------------------------------------------


@groups
def test_wrong_tangent_shape_names_expected_and_actual(group):
    with pytest.raises(ShapeError, match=rf"expected shape \(\.\.\., {group.dim}\), got \(4, {group.dim + 1}\)"):
        group.exp(np.zeros((4, group.dim + 1)))
    with pytest.raises(ShapeError):
        group.identity().rplus(np.zeros(group.dim + 2))
    with pytest.raises(ShapeError, match="got"):
        group.identity().act(np.zeros(group.point_dim + 1))
    with pytest.raises(ShapeError):
        group.jr(np.zeros(()))


@groups
def test_non_finite_input_is_rejected(group):
    tau = np.zeros((2, group.dim))
    tau[1, 0] = np.nan
    with pytest.raises(NonFiniteError, match=r"index \(1, 0\)"):
        group.exp(tau)
    with pytest.raises(NonFiniteError):
        group.identity().act(np.full(group.point_dim, np.inf))
    m = np.array(group.identity().as_matrix())
    m[0, 0] = np.inf
    with pytest.raises(NonFiniteError):
        group.from_matrix(m)


@groups
def test_errors_are_value_errors(group):
    with pytest.raises(ValueError):
        group.exp(np.zeros(group.dim + 1))


@pytest.mark.parametrize("group", [SO2, SO3, SE2, SE3], ids=group_id)
def test_from_matrix_validates_and_projects(group, rng):
    x = group.random(rng, (5,))
    noisy = (
        x.as_matrix()
        + 1e-3
        * rng.standard_normal(x.as_matrix().shape)
        * (np.arange(group.storage_shape[0]) < group.point_dim)[:, None]
    )
    with pytest.raises(NotInGroupError, match=r"not orthonormal.*project=True"):
        group.from_matrix(noisy)
    snapped = group.from_matrix(noisy, project=True)
    group.from_matrix(snapped.as_matrix(), tol=1e-12)
    assert x.chordal_dist(snapped).max() < 1e-2
    accepted = group.from_matrix(noisy, tol=0.1)  # a looser tolerance accepts it, polished onto the group
    group.from_matrix(accepted.as_matrix(), tol=1e-14)
    assert accepted.chordal_dist(snapped).max() < 1e-9  # the polar factor is the nearest rotation

    reflection = np.array(x.as_matrix())
    reflection[..., 0, :] *= -1
    reflection[..., 0, -1] *= -1 if group in (SE2, SE3) else 1  # keep the translation
    with pytest.raises(NotInGroupError, match="reflection"):
        group.from_matrix(reflection)
    with pytest.raises(NotInGroupError):
        group(reflection)  # the constructor validates too
    fixed = group.from_matrix(reflection, project=True)
    assert (np.linalg.det(fixed.as_matrix()[..., : group.point_dim, : group.point_dim]) > 0).all()


@pytest.mark.parametrize("group", [SE2, SE3], ids=group_id)
def test_homogeneous_last_row_is_checked(group):
    m = np.eye(group.point_dim + 1)
    m[-1, 0] = 0.5
    with pytest.raises(NotInGroupError, match="last row"):
        group.from_matrix(m)
    np.testing.assert_array_equal(group.from_matrix(m, project=True).as_matrix(), np.eye(group.point_dim + 1))


def test_quaternion_validation():
    with pytest.raises(NotInGroupError, match="not unit"):
        SO3.from_quaternion([0.0, 0.0, 0.0, 2.0])
    np.testing.assert_allclose(SO3.from_quaternion([0.0, 0.0, 0.0, 2.0], normalize=True).as_matrix(), np.eye(3))
    with pytest.raises(NotInGroupError, match="zero"):
        SO3.from_quaternion(np.zeros(4), normalize=True)
    with pytest.raises(ShapeError):
        SO3.from_quaternion(np.zeros(3))


def test_mixing_groups_is_a_type_error(rng):
    with pytest.raises(TypeError, match="SO3"):
        SO3.identity().compose(SE3.identity())
    with pytest.raises(TypeError):
        SO3.identity().rminus(SO2.identity())


def test_rn_factory():
    assert Rn(3) is Rn(3) is Rn(np.int64(3))
    assert Rn(3) is not Rn(4)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError):
            Rn(bad)
    x = Rn(3)([1.0, 2.0, 3.0])
    assert isinstance(x, Rn(3))
    np.testing.assert_array_equal(x.as_matrix()[:3, 3], [1, 2, 3])
    np.testing.assert_array_equal(Rn(3).from_matrix(x.as_matrix()).data, x.data)
    with pytest.raises(NotInGroupError):
        Rn(3).from_matrix(2 * np.eye(4))


# ---- batching ---------------------------------------------------------------------


@groups
def test_broadcasting_rules(group, rng):
    x = group.random(rng, (3, 1))
    y = group.random(rng, (2,))
    z, j_x, j_y = x.compose(y, jac=True)
    assert z.batch_shape == (3, 2)
    assert j_x.shape == j_y.shape == (3, 2, group.dim, group.dim)
    assert_same(z[1, 0], x[1, 0] @ y[0])
    tau = rng.standard_normal((4, 1, 1, group.dim))
    w, j_x, j_t = x.rplus(tau, jac=True)
    assert w.batch_shape == (4, 3, 1)
    assert j_x.shape == j_t.shape == (4, 3, 1, group.dim, group.dim)
    p = rng.standard_normal((5, 1, 1, group.point_dim))
    q, j_x, j_p = y.act(p, jac=True)
    assert q.shape == (5, 1, 2, group.point_dim)
    assert j_x.shape == (5, 1, 2, group.point_dim, group.dim)
    assert j_p.shape == (5, 1, 2, group.point_dim, group.point_dim)
    np.testing.assert_allclose(q[4, 0, 1], y[1].act(p[4, 0, 0]), atol=1e-14)
    assert x.rminus(y).shape == (3, 2, group.dim)
    with pytest.raises(ShapeError, match="do not broadcast"):
        group.random(rng, (3,)).compose(group.random(rng, (2,)))
    with pytest.raises(ShapeError):
        group.random(rng, (3,)).act(np.zeros((2, group.point_dim)))
    with pytest.raises(ShapeError):
        group.random(rng, (3,)).rplus(np.zeros((2, group.dim)))


@groups
def test_indexing_and_slicing(group, rng):
    x = group.random(rng, (4, 3))
    assert x[3].batch_shape == (3,)
    assert x[:, 0].batch_shape == (4,)
    assert x[..., 1].batch_shape == (4,)
    assert x[1:3].batch_shape == (2, 3)
    assert x[None].batch_shape == (1, 4, 3)
    assert x[x.log()[..., 0] > 0].batch_shape[0] == int((x.log()[..., 0] > 0).sum())
    assert_same(x[2, 1], group(x.data[2, 1]))
    with pytest.raises(IndexError):
        x[0, 0, 0]
    with pytest.raises(IndexError):
        group.identity()[0]
    assert len(x) == 4
    with pytest.raises(TypeError):
        len(group.identity())


@groups
@pytest.mark.parametrize("dtype", [np.intp, np.int32, np.uint16])
def test_an_integer_array_gathers_along_the_first_batch_axis(group, rng, dtype):
    x = group.random(rng, (4, 3))
    index = np.array([3, 0, 3], dtype=dtype)
    assert_same(x[index], group(x.data[index.astype(np.intp)]))  # the fast path: as the array indexes
    assert x[index].batch_shape == (3, 3)
    assert x[index.reshape(3, 1)].batch_shape == (3, 1, 3)
    with pytest.raises(IndexError):
        x[np.array([4], dtype=dtype)]
    with pytest.raises(IndexError):
        group.identity()[np.array([0], dtype=dtype)]  # no batch axis to index


@groups
def test_stack_concatenate_reshape(group, rng):
    a, b = group.random(rng, (2, 3)), group.random(rng, (2, 3))
    s = group.stack([a, b])
    assert s.batch_shape == (2, 2, 3)
    assert_same(s[1], b)
    assert group.stack([a, b], axis=-1).batch_shape == (2, 3, 2)
    assert_same(group.stack([a, b], axis=-1)[..., 1], b)
    c = group.concatenate([a, b], axis=-1)
    assert c.batch_shape == (2, 6)
    assert_same(c[:, 3:], b)
    assert group.concatenate([a, b]).batch_shape == (4, 3)
    assert a.reshape((3, 2)).batch_shape == (3, 2)
    assert group.identity().broadcast_to((5, 2)).batch_shape == (5, 2)
    with pytest.raises(ShapeError):
        group.stack([a, group.random(rng, (3,))])
    with pytest.raises(ShapeError):
        group.concatenate([group.identity(), group.identity()])


@groups
def test_elements_are_immutable_and_picklable(group, rng):
    x = group.random(rng, (3,))
    with pytest.raises(ValueError):
        x.data[0] = 0.0
    with pytest.raises(AttributeError):
        x.foo = 1
    assert_same(pickle.loads(pickle.dumps(x)), x)
    source = np.array(x.data)
    y = group(source)
    source[...] = 0.0  # the constructor copied
    assert_same(y, x)
    assert group.__name__ in repr(x) and "batch_shape=(3,)" in repr(x)


@groups
def test_identity_and_random(group):
    e = group.identity((2, 3))
    assert e.batch_shape == (2, 3)
    np.testing.assert_array_equal(e.log(), 0.0)
    assert_same(group.random(7, (4,)), group.random(np.random.default_rng(7), (4,)))


def test_so3_random_is_haar_uniform():
    """The angle of a Haar rotation has CDF (θ − sin θ)/π; the matrix mean is 0."""
    x = SO3.random(np.random.default_rng(0), (20000,))
    angle = np.linalg.norm(x.log(), axis=-1)
    assert stats.kstest(angle, lambda t: (t - np.sin(t)) / np.pi).pvalue > 1e-3
    assert np.abs(x.data.mean(axis=0)).max() < 0.02
    # Left-invariance: R0·X has the same angle distribution.
    shifted = np.linalg.norm((SO3.exp([0.3, -1.0, 2.0]) @ x).log(), axis=-1)
    assert stats.ks_2samp(angle, shifted).pvalue > 1e-3


# ---- conversions and distances ----------------------------------------------------


@given(theta=st.floats(-10, 10))
def test_so2_angle(theta):
    x = SO2.from_angle(theta)
    assert np.isclose(np.cos(x.angle()), np.cos(theta)) and np.isclose(np.sin(x.angle()), np.sin(theta))
    assert -np.pi < x.angle() <= np.pi


def test_rotation_translation_parts(rng):
    for group, rot_group in ((SE2, SO2), (SE3, SO3)):
        r = rot_group.random(rng, (4,))
        t = rng.standard_normal((4, group.point_dim))
        x = group.from_rotation_translation(r, t)
        assert_same(x.rotation(), r)
        np.testing.assert_array_equal(x.translation(), t)
        p = rng.standard_normal(group.point_dim)
        np.testing.assert_allclose(x.act(p), r.act(p) + t, atol=1e-14)
        with pytest.raises(TypeError):
            group.from_rotation_translation(x, t)
    q = SO3.random(rng, (4,)).as_quaternion()
    x = SE3.from_translation_quaternion(t, q)
    np.testing.assert_allclose(x.rotation().as_quaternion(), q, atol=1e-14)


def test_quaternion_round_trip_and_sign(rng):
    x = SO3.random(rng, (1000,))
    q = x.as_quaternion()
    assert (q[..., 3] >= 0).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)
    assert_same(SO3.from_quaternion(q), x)
    assert_same(SO3.from_quaternion(-q), x)  # q and −q are the same rotation


@groups
def test_distances(group, rng):
    x, y = group.random(rng, (50,)), group.random(rng, (50,))
    np.testing.assert_allclose(x.dist(y), np.linalg.norm(y.rminus(x), axis=-1))
    np.testing.assert_allclose(x.chordal_dist(y), y.chordal_dist(x))
    np.testing.assert_allclose(x.dist(x), 0.0, atol=1e-12)
    mid = x.interpolate(y, 0.5)
    np.testing.assert_allclose(x.dist(mid), 0.5 * x.dist(y), atol=1e-9)
    path = x[0].interpolate(y[0], np.linspace(0, 1, 5))
    assert path.batch_shape == (5,)


def test_so3_chordal_and_geodesic_distance():
    """``‖R₁ − R₂‖_F = 2√2 |sin(θ/2)|`` with θ the geodesic distance."""
    theta = np.linspace(0, np.pi, 7)
    x = SO3.exp(theta[:, None] * np.array([0.0, 0.6, 0.8]))
    e = SO3.identity()
    np.testing.assert_allclose(e.dist(x), theta, atol=1e-14)
    np.testing.assert_allclose(e.chordal_dist(x), 2 * np.sqrt(2) * np.abs(np.sin(theta / 2)), atol=1e-14)


@groups
def test_hat_vee(group, rng):
    tau = rng.standard_normal((3, group.dim))
    np.testing.assert_allclose(group.vee(group.hat(tau)), tau, atol=1e-15)
    with pytest.raises(ShapeError):
        group.vee(np.zeros((2, 2, 5)))
