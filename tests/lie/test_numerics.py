"""Accuracy at and near the singular angles 0 and π, hand-picked hard cases, SciPy cross-checks."""

from __future__ import annotations

from fractions import Fraction
from math import comb, factorial

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.lie import _matrix, _series

from .helpers import GROUPS, ROTATION_PART, SCALE_PART, assert_same, group_id

# Angles that stress every branch: exact zero, denormal-squared, both sides of the
# series threshold, π and its neighbours, and values past π (wrapping).
HARD_ANGLES = np.array(
    [
        0.0,
        1e-300,
        1e-160,
        1e-20,
        1e-8,
        1e-4,
        0.3 - 1e-12,
        0.3,
        0.5,
        0.7 + 1e-12,
        1.0,
        np.pi / 2,
        np.pi - 1e-6,
        np.pi - 1e-9,
        np.pi - 1e-12,
        np.pi,
        np.pi + 1e-9,
        4.0,
        2 * np.pi - 1e-3,
        30.0,
    ]
)


def _bernoulli(n: int) -> list[Fraction]:
    """``B_0 … B_n`` exactly (``B_1 = −½``), by ``Σ_{k<m+1} C(m+1, k) B_k = 0``."""
    b = [Fraction(1)]
    for m in range(1, n + 1):
        b.append(-sum(comb(m + 1, k) * b[k] for k in range(m)) / (m + 1))
    return b


_B = _bernoulli(82)
# ``(θ/2)cot(θ/2) = Σ_j (−1)^j B_2j θ^2j / (2j)!`` (radius 2π), hence ``jinv_coef = (1 − half_cot)/θ²``.
_HALF_COT = [(-1) ** j * _B[2 * j] / factorial(2 * j) for j in range(41)]

# Power-series terms in ``t = θ²`` (``x²`` for atan_ratio) of every coefficient of ``_series``.
TERMS = {
    "sinc": lambda j: Fraction((-1) ** j, factorial(2 * j + 1)),
    "cosc": lambda j: Fraction((-1) ** j, factorial(2 * j + 2)),
    "sinc3": lambda j: Fraction((-1) ** j, factorial(2 * j + 3)),
    "q_coef2": lambda j: Fraction((-1) ** j, factorial(2 * j + 4)),
    "q_coef3": lambda j: Fraction((-1) ** j * (j + 1), factorial(2 * j + 5)),
    "jinv_coef": lambda j: -_HALF_COT[j + 1],
    "half_cot": lambda j: _HALF_COT[j],
    "sinc_half": lambda j: Fraction((-1) ** j, factorial(2 * j + 1) * 2 ** (2 * j + 1)),
    "cos_half": lambda j: Fraction((-1) ** j, factorial(2 * j) * 4**j),
    "atan_ratio": lambda j: Fraction((-1) ** j, 2 * j + 1),
    "emoment0": lambda j: Fraction(1, factorial(2 * j + 1)),
    "emoment1": lambda j: Fraction(j + 1, factorial(2 * j + 3)),
    "emoment2": lambda j: Fraction(1, 4 * (2 * j + 3) * factorial(2 * j)),
}


def _reference(name: str, theta: float) -> float:
    """40 terms of the power series summed in rational arithmetic (exact to double precision where used)."""
    t = Fraction(theta) ** 2
    return float(sum(TERMS[name](j) * t**j for j in range(40)))


def _numpy(name: str, theta: np.ndarray) -> np.ndarray:
    coef = next(c for c in _series.COEFFICIENTS if c.name == name)
    return _series.evaluate(coef, theta * theta, theta)


@pytest.mark.parametrize("name", sorted(TERMS))
def test_series_coefficients_match_exact_reference(name):
    """Exact rational evaluation of the full power series vs both branches, including each
    threshold and its neighbour below (up to θ = 3; atan_ratio up to x = 0.5, its series' domain)."""
    top = 0.5 if name == "atan_ratio" else 3.0
    thresholds = np.array([c.threshold for c in _series.COEFFICIENTS])
    theta = np.concatenate([np.linspace(0.0, top, 61), thresholds, np.nextafter(thresholds, 0), [1e-8, 1e-5]])
    theta = theta[theta <= top]
    ref = np.array([_reference(name, x) for x in theta])
    np.testing.assert_allclose(_numpy(name, theta), ref, rtol=1e-13, atol=0)


@pytest.mark.parametrize("coef", _series.COEFFICIENTS, ids=lambda c: c.name)
def test_series_data_are_the_taylor_coefficients(coef):
    """The stored series is the exact Taylor series (to rounding), and the public numpy
    function of the angle is :func:`_series.evaluate` of the data, even in θ."""
    exact = np.array([float(TERMS[coef.name](j)) for j in range(len(coef.series))])
    np.testing.assert_allclose(coef.series, exact, rtol=1e-15, atol=0)
    theta = np.array([0.0, 1e-9, 0.5 * coef.threshold, coef.threshold, 0.8, 2.0, 3.0])
    f = getattr(_series, coef.name, None)
    if f is not None:
        np.testing.assert_array_equal(f(theta), _series.evaluate(coef, theta * theta, theta))
        np.testing.assert_allclose(f(-theta), f(theta), rtol=1e-15, atol=0)
    np.testing.assert_array_equal(_series.evaluate(coef, theta * theta), _series.evaluate(coef, theta * theta, theta))


def test_jinv_coefficient():
    """``θ² g(θ) = 1 − (θ/2)cot(θ/2)``, checked on both sides of the switch and at π."""
    theta = np.concatenate([np.linspace(1e-3, 6.0, 200), [0.3, np.nextafter(0.3, 0)]])
    ref = (1.0 - 0.5 * theta / np.tan(0.5 * theta)) / theta**2
    np.testing.assert_allclose(_series.jinv_coef(theta)[theta > 0.05], ref[theta > 0.05], rtol=1e-12)
    assert _series.jinv_coef(np.array([np.pi]))[0] == pytest.approx(1 / np.pi**2, rel=1e-15)
    assert _series.jinv_coef(np.array([0.0]))[0] == 1 / 12


def test_half_cot_is_accurate_relative_to_its_value_up_to_2pi():
    """``(θ/2)cot(θ/2)``: relative accuracy also at its zero π, where ``1 − θ² jinv_coef`` cancels."""
    theta = np.concatenate([np.linspace(1e-3, 2 * np.pi - 1e-3, 300), [np.pi, np.pi - 1e-9, 0.3, np.nextafter(0.3, 0)]])
    ref = 0.5 * theta / np.tan(0.5 * theta)
    np.testing.assert_allclose(_series.half_cot(theta), ref, rtol=1e-13, atol=1e-300)
    np.testing.assert_allclose(_series.half_cot(theta), 1.0 - theta**2 * _series.jinv_coef(theta), atol=1e-12)
    assert abs(_series.half_cot(np.array([np.pi]))[0]) < 1e-16


def test_atan2_ratio():
    """``atan2(s, c)/s`` for ``s ≥ 0`` and any ``c``: the series only where ``c > 0`` and ``s/c < 1e-3``."""
    phi = np.concatenate([np.linspace(0.0, np.pi, 181), [1e-3, np.nextafter(1e-3, 0), 1e-9, np.pi - 1e-9]])
    for scale in (1.0, 0.5, 3.0):  # matrix residuals carry c = (tr R − 1)/2 and a = sin θ u
        s, c = scale * np.sin(phi), scale * np.cos(phi)
        ratio = _series.atan2_ratio(s * s, c)
        ref = np.where(s > 0, np.arctan2(s, c) / np.where(s > 0, s, 1.0), 1.0 / scale)
        np.testing.assert_allclose(ratio, ref, rtol=1e-15, atol=0)
    # s = 0 with c ≤ 0 (a rotation by exactly π given as a matrix): finite, no division by zero.
    assert np.isfinite(_series.atan2_ratio(np.zeros(2), np.array([-1.0, 0.0]))).all()


@pytest.mark.parametrize("group", GROUPS, ids=group_id)
def test_no_nan_anywhere(group, rng):
    """Every operation is finite for rotation angles across the whole domain
    (the inverse Jacobians up to, not including, their singularity at 2π)."""
    tau = rng.standard_normal((len(HARD_ANGLES), 4, group.dim))
    if group in ROTATION_PART:
        part = ROTATION_PART[group]
        axis = tau[..., part] / np.linalg.norm(tau[..., part], axis=-1, keepdims=True)
        tau[..., part] = axis * HARD_ANGLES[:, None, None]
    x = group.exp(tau)
    outputs = [x.as_matrix(), x.log(), group.jr(tau), group.jl(tau), x.adjoint(), x.log(jac=True)[1]]
    inside = np.linalg.norm(tau[..., ROTATION_PART.get(group, slice(0, 0))], axis=-1) < 2 * np.pi - 1e-4
    outputs += [group.jr_inv(tau[inside]), group.jl_inv(tau[inside])]
    for out in outputs:
        assert np.isfinite(out).all()
    assert_same(group.exp(x.log()), x, tol=1e-11)


@pytest.mark.parametrize("group", GROUPS, ids=group_id)
@given(log_scale=st.floats(-12, -1), seed=st.integers(0, 2**32 - 1))
def test_small_tangents_keep_relative_precision(group, log_scale, seed):
    """Optimizer increments are tiny: ``Log(Exp(τ))`` must be accurate relative to ``|τ|``."""
    tau = 10.0**log_scale * np.random.default_rng(seed).standard_normal((8, group.dim))
    back = group.exp(tau).log()
    if group in SCALE_PART:
        # Sim(3) stores s·R: σ = log s is held by entries ≈ 1, so its precision is absolute (~1e-16).
        assert np.abs(back - tau)[..., SCALE_PART[group]].max() <= 1e-15
        back[..., SCALE_PART[group]] = tau[..., SCALE_PART[group]]
    assert np.abs(back - tau).max() <= 1e-12 * np.abs(tau).max()


def test_rotations_by_exactly_pi():
    axes = np.vstack([np.eye(3), -np.eye(3), np.ones((1, 3)) / np.sqrt(3)])
    x = SO3.exp(np.pi * axes)
    w = x.log()
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), np.pi, atol=1e-15)
    assert_same(SO3.exp(w), x)
    # An exact π rotation matrix (no rounding from exp): diag(1, −1, −1).
    r = SO3(np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_allclose(np.abs(r.log()), [np.pi, 0, 0], atol=1e-15)
    assert_same(SO2.from_angle(np.pi), SO2.exp(SO2.from_angle(np.pi).log()))
    assert SO2.from_angle(np.pi).angle() == pytest.approx(np.pi)


def test_quaternion_with_tiny_scalar_part():
    """Sophus's hard case: ``w = 1e-12`` is an angle of π − 2e-12."""
    q = np.array([0.6, 0.0, 0.8, 1e-12])
    x = SO3.from_quaternion(q, normalize=True)
    w = x.log()
    np.testing.assert_allclose(np.linalg.norm(w), np.pi - 2e-12, rtol=0, atol=1e-15)
    np.testing.assert_allclose(w / np.linalg.norm(w), [0.6, 0.0, 0.8], atol=1e-15)
    np.testing.assert_allclose(x.as_quaternion(), q / np.linalg.norm(q), atol=1e-15)


@pytest.mark.parametrize("group", [SO2, SO3, SE2, SE3], ids=group_id)
def test_large_tangents_wrap(group, rng):
    """``|θ| = 30``: Log returns an equivalent tangent with angle in [0, π] (SO2/SE2: (−π, π])."""
    tau = rng.standard_normal((100, group.dim))
    part = ROTATION_PART[group]
    tau[..., part] *= 30.0 / np.linalg.norm(tau[..., part], axis=-1, keepdims=True)
    x = group.exp(tau)
    back = x.log()
    assert (np.linalg.norm(back[..., part], axis=-1) <= np.pi + 1e-15).all()
    assert_same(group.exp(back), x, tol=1e-12)


def test_pure_translations():
    rho = np.array([1.0, -2.0, 3.0])
    np.testing.assert_array_equal(SE3.exp(np.r_[rho, 0, 0, 0]).translation(), rho)
    np.testing.assert_array_equal(SE2.exp([1.0, -2.0, 0.0]).translation(), [1.0, -2.0])
    np.testing.assert_allclose(SE3.exp(np.r_[rho, 1e-9, 0, 0]).log(), np.r_[rho, 1e-9, 0, 0], rtol=1e-14, atol=1e-22)


def test_seed_example_rotation_action_jacobian(rng):
    """The lecture notes' example: ``D(R·p)/DR = −R [p]×`` and ``D(R·p)/Dp = R``."""
    r = SO3.random(rng, (10,))
    p = rng.standard_normal((10, 3))
    _, j_r, j_p = r.act(p, jac=True)
    np.testing.assert_allclose(j_r, -r.as_matrix() @ SO3.hat(p), atol=1e-15)
    np.testing.assert_array_equal(j_p, r.as_matrix())


class TestAgainstScipy:
    """SO(3) against ``scipy.spatial.transform.Rotation`` on uniform rotations."""

    @pytest.fixture
    def rotations(self, rng):
        x = SO3.random(rng, (2000,))
        return x, Rotation.from_matrix(x.as_matrix())

    def test_exp(self, rng):
        w = 2.0 * rng.standard_normal((2000, 3))
        np.testing.assert_allclose(SO3.exp(w).as_matrix(), Rotation.from_rotvec(w).as_matrix(), atol=1e-14)

    def test_log(self, rotations):
        x, r = rotations
        np.testing.assert_allclose(x.log(), r.as_rotvec(), atol=1e-12)

    def test_quaternions(self, rotations, rng):
        x, r = rotations
        np.testing.assert_allclose(x.as_quaternion(), r.as_quat(canonical=True), atol=1e-14)
        q = rng.standard_normal((100, 4))
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        np.testing.assert_allclose(SO3.from_quaternion(q).as_matrix(), Rotation.from_quat(q).as_matrix(), atol=1e-14)

    def test_act_and_compose(self, rotations, rng):
        x, r = rotations
        p = rng.standard_normal((2000, 3))
        np.testing.assert_allclose(x.act(p), r.apply(p), atol=1e-13)
        np.testing.assert_allclose((x @ x[::-1]).as_matrix(), (r * r[::-1]).as_matrix(), atol=1e-14)


@pytest.mark.parametrize("d", [2, 3, 4])
@pytest.mark.parametrize("batch", [(), (1,), (3, 1, 2), (700,)], ids=str)
def test_rotation_error_written_out_is_numpys(d, batch, rng):
    """``max |RᵀR − I|`` from the column products and ``det R`` written out (d ≤ 3) agree with
    NumPy's batched product and LAPACK's determinant, for matrices near and far from SO(d)."""
    r = rng.standard_normal(batch + (d, d))
    near = np.linalg.qr(r)[0] + 1e-9 * rng.standard_normal(batch + (d, d))
    for m in (r, near, np.swapaxes(r, -1, -2)):  # a transposed view: not contiguous
        err, det = _matrix.rotation_error(m)
        expected = np.abs(np.swapaxes(m, -1, -2) @ m - np.eye(d)).max(axis=(-2, -1))
        assert err.shape == det.shape == batch
        np.testing.assert_allclose(err, expected, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(det, np.linalg.det(m), rtol=1e-12, atol=1e-14)


@given(
    d=st.sampled_from([2, 3]),
    seed=st.integers(0, 2**32 - 1),
    log_scale=st.floats(-300, 300),
    shape=st.sampled_from(["random", "near rotation", "reflection", "rank one", "nearly singular"]),
)
def test_projection_onto_rotations_maximizes_the_trace(d, seed, log_scale, shape):
    """``project_rotation`` (2×2 in closed form, 3×3 by Newton's polar iteration, the rest by the
    SVD) returns a rotation whose ``tr(RᵀM)`` is the SVD projection's — the maximum over SO(n) —
    for matrices of any scale, reflections and (nearly) singular ones included, where the
    nearest rotation need not be unique; where it is, both agree entrywise."""
    rng = np.random.default_rng(seed)
    m = rng.standard_normal((300, d, d))  # above POLAR_BATCH: the 3×3 path is Newton's
    if shape == "near rotation":
        m = _matrix.project_rotation(m) + 1e-2 * m
    elif shape == "reflection":
        m[:, :, 0] *= np.where(np.linalg.det(m) > 0, -1.0, 1.0)[:, None]
    elif shape == "rank one":
        m = m[:, :, :1] * m[:, :1, :]
    elif shape == "nearly singular":
        m[:, :, -1] = m[:, :, 0] + 1e-9 * m[:, :, -1]
    m = m * 10.0**log_scale
    r, reference = _matrix.project_rotation(m), _matrix._project_svd(m / np.abs(m).max(axis=(1, 2), keepdims=True))
    assert np.abs(np.swapaxes(r, 1, 2) @ r - np.eye(d)).max() < 1e-13 and (np.linalg.det(r) > 0).all()
    unit = m / np.abs(m).max(axis=(1, 2), keepdims=True)
    np.testing.assert_allclose(np.einsum("nij,nij->n", r, unit), np.einsum("nij,nij->n", reference, unit), atol=1e-12)
    s = np.linalg.svd(unit, compute_uv=False)
    unique = (s[:, -2] + s[:, -1] * np.sign(np.linalg.det(unit)) > 1e-6) if d == 3 else (s.sum(axis=1) > 1e-6)
    np.testing.assert_allclose(r[unique], reference[unique], atol=1e-9)


def test_projection_onto_rotations_at_the_edges():
    """The zero matrix and exact rotations, reflections of 2×2 and 3×3, an empty batch."""
    for d in (2, 3):
        np.testing.assert_array_equal(_matrix.project_rotation(np.zeros((d, d))), np.eye(d))
        rotations = _matrix.project_rotation(np.random.default_rng(d).standard_normal((5, d, d)))
        np.testing.assert_allclose(_matrix.project_rotation(rotations), rotations, rtol=0, atol=1e-15)
        assert _matrix.project_rotation(np.zeros((0, d, d))).shape == (0, d, d)
    with pytest.raises(np.linalg.LinAlgError):  # not finite: the SVD's error, as before
        _matrix.project_rotation(np.full((2, 3, 3), np.nan))
    with pytest.raises(np.linalg.LinAlgError):
        _matrix.project_rotation(np.full((2, 2, 2), np.nan))
