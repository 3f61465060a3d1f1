"""Noise models: whitening gives ``rᵀΩr``, the models agree with each other, bad models are
refused naming the edge."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2
from manopt_lie.errors import IndefiniteMatrixError, NonFiniteError, ShapeError
from manopt_lie.factors import (
    Covariance,
    Diagonal,
    IndefiniteNoiseError,
    Information,
    Isotropic,
    NoiseModelError,
    NoiseShapeError,
    NonFiniteNoiseError,
    Unit,
    between_factor,
)


def spd(rng: np.random.Generator, m: int, k: int) -> np.ndarray:
    a = rng.standard_normal((m, k, k))
    return a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(k)


def test_whitening_is_the_mahalanobis_norm(rng):
    m, k = 7, 4
    omega, r, j = spd(rng, m, k), rng.standard_normal((m, k)), rng.standard_normal((m, k, 3))
    sigmas = rng.uniform(0.1, 2.0, (m, k))
    models = {
        "information": (Information(omega), omega),
        "shared information": (Information(omega[0]), np.broadcast_to(omega[0], omega.shape)),
        "covariance": (Covariance(np.linalg.inv(omega)), omega),
        "diagonal": (Diagonal(sigmas), np.einsum("ei,ij->eij", sigmas**-2, np.eye(k))),
        "shared diagonal": (Diagonal(sigmas[0]), np.broadcast_to(np.diag(sigmas[0] ** -2), omega.shape)),
        "isotropic": (Isotropic(sigmas[:, 0], k), np.einsum("e,ij->eij", sigmas[:, 0] ** -2, np.eye(k))),
        "shared isotropic": (Isotropic(0.5, k), np.broadcast_to(4.0 * np.eye(k), omega.shape)),
        "unit": (Unit(k), np.broadcast_to(np.eye(k), omega.shape)),
    }
    for what, (model, info) in models.items():
        w = model.whiten(r)
        np.testing.assert_allclose(np.einsum("ei,ei->e", w, w), np.einsum("ei,eij,ej->e", r, info, r), rtol=1e-12,
                                   err_msg=what)  # fmt: skip
        np.testing.assert_allclose(model.squared_mahalanobis(r), np.einsum("ei,eij,ej->e", r, info, r), rtol=1e-12)
        wj = model.whiten_jacobian(j)
        np.testing.assert_allclose(np.swapaxes(wj, 1, 2) @ wj, np.swapaxes(j, 1, 2) @ info @ j, rtol=1e-10,
                                   atol=1e-12, err_msg=what)  # fmt: skip
        np.testing.assert_allclose(np.broadcast_to(model.information, info.shape), info, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(
            np.broadcast_to(model.covariance, info.shape), np.linalg.inv(info), rtol=1e-8, atol=1e-12
        )
        r_sqrt = model.sqrt_information
        np.testing.assert_allclose(np.swapaxes(r_sqrt, -1, -2) @ r_sqrt, model.information, rtol=1e-12, atol=1e-14)


def test_one_matrix_repeated_per_edge_is_the_common_square_root(rng):
    """A per-edge model whose matrices are all one whitens as the shared model does, through
    that one matrix (``common_sqrt_information``); one different edge keeps them per edge."""
    omega = spd(rng, 1, 4)[0]
    r, j = rng.standard_normal((6, 4)), rng.standard_normal((6, 4, 3))
    shared, repeated = Information(omega), Information(np.repeat(omega[None], 6, axis=0))
    np.testing.assert_array_equal(repeated.common_sqrt_information, shared.sqrt_information)
    assert repeated.edges == 6 and repeated.sqrt_information.shape == (6, 4, 4)  # still a per-edge model
    np.testing.assert_allclose(repeated.whiten(r), shared.whiten(r), rtol=0, atol=1e-14)
    np.testing.assert_allclose(repeated.whiten_jacobian(j), shared.whiten_jacobian(j), rtol=0, atol=1e-14)
    varied = np.repeat(omega[None], 6, axis=0)
    varied[2] *= 2.0
    per_edge = Information(varied)
    assert per_edge.common_sqrt_information is None
    np.testing.assert_allclose(per_edge.squared_mahalanobis(r), np.einsum("ei,eij,ej->e", r, varied, r), rtol=1e-12)
    assert Unit(3).common_sqrt_information is not None and Diagonal(np.ones((6, 3))).common_sqrt_information is None


def test_information_of_the_inverse_is_the_covariance(rng):
    """``Information(Σ⁻¹) ≡ Covariance(Σ)``: same cost, gradient ``JᵀΩr`` and ``JᵀΩJ`` (the whitened
    residuals differ by an orthogonal factor: ``Lᵀ`` and ``C⁻¹`` are two square roots of ``Ω``)."""
    m, k = 9, 6
    sigma = spd(rng, m, k)
    r, j = rng.standard_normal((m, k)), rng.standard_normal((m, k, 6))
    a, b = Information(np.linalg.inv(sigma)), Covariance(sigma)
    ra, rb, ja, jb = a.whiten(r), b.whiten(r), a.whiten_jacobian(j), b.whiten_jacobian(j)
    np.testing.assert_allclose(np.einsum("ei,ei->e", ra, ra), np.einsum("ei,ei->e", rb, rb), rtol=1e-9)
    np.testing.assert_allclose(np.einsum("eik,ei->ek", ja, ra), np.einsum("eik,ei->ek", jb, rb), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(np.swapaxes(ja, 1, 2) @ ja, np.swapaxes(jb, 1, 2) @ jb, rtol=1e-8, atol=1e-10)
    q = b.sqrt_information @ np.linalg.inv(a.sqrt_information)  # orthogonal
    np.testing.assert_allclose(np.swapaxes(q, 1, 2) @ q, np.broadcast_to(np.eye(k), q.shape), atol=1e-9)
    # The diagonal models are the information models of their diagonal matrices.
    s = rng.uniform(0.1, 3.0, (m, k))
    np.testing.assert_allclose(Diagonal(s).whiten(r), Information(np.einsum("ei,ij->eij", s**-2, np.eye(k))).whiten(r),
                               rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose(Isotropic(s[:, 0], k).whiten(r), Diagonal(np.repeat(s[:, :1], k, axis=1)).whiten(r))
    np.testing.assert_array_equal(Diagonal(s).sigmas, s)
    np.testing.assert_array_equal(Isotropic(2.0, 3).sigmas, [2.0, 2.0, 2.0])


def test_information_is_whitened_by_its_cholesky_factor(rng):
    omega = spd(rng, 5, 3)
    lower = np.linalg.cholesky(omega)
    np.testing.assert_allclose(Information(omega).sqrt_information, np.swapaxes(lower, 1, 2), rtol=1e-14)


@pytest.mark.parametrize("model", [Information, Covariance])
def test_bad_matrices_are_refused_naming_the_edge(rng, model):
    good = spd(rng, 6, 3)
    indefinite = good.copy()
    indefinite[4] = np.diag([1.0, -1.0, 2.0])
    with pytest.raises(IndefiniteNoiseError, match="edge 4 is not positive definite") as info:
        model(indefinite)
    assert isinstance(info.value, IndefiniteMatrixError) and isinstance(info.value, ValueError)
    singular = good.copy()
    singular[2] = np.ones((3, 3))
    with pytest.raises(IndefiniteNoiseError, match="edge 2 "):
        model(singular)
    asymmetric = good.copy()
    asymmetric[1, 0, 2] += 0.5
    with pytest.raises(IndefiniteNoiseError, match="edge 1 is not symmetric"):
        model(asymmetric)
    infinite = good.copy()
    infinite[3, 1, 1] = np.inf
    infinite[5, 0, 0] = np.nan
    with pytest.raises(NonFiniteNoiseError, match="edges 3, 5") as info:
        model(infinite)
    assert isinstance(info.value, NonFiniteError)
    with pytest.raises(NoiseShapeError, match=r"\(k, k\) or \(m, k, k\)") as info:
        model(np.ones((3, 2)))
    assert isinstance(info.value, ShapeError)
    with pytest.raises(IndefiniteNoiseError, match="the shared model"):
        model(-np.eye(2))
    with pytest.raises(NoiseShapeError):
        model("information")


def test_matrices_near_the_float_range():
    """Entries near 1e308: refused or accepted by what they are, without overflow warnings."""
    with pytest.raises(IndefiniteNoiseError, match="not symmetric"):
        Information([[1e308, -1e308], [1e308, 1e308]])
    with pytest.raises(IndefiniteNoiseError, match="not positive definite"):
        Covariance([[1e308, 1e308], [1e308, 1e308]])
    np.testing.assert_allclose(Information(np.diag([1e308, 1e-308])).sqrt_information, np.diag([1e154, 1e-154]))
    np.testing.assert_allclose(Covariance(np.diag([1e308, 1e-308])).sqrt_information, np.diag([1e-154, 1e154]))


def test_round_off_asymmetry_is_accepted(rng):
    omega = spd(rng, 4, 3)
    omega[:, 0, 1] *= 1 + 1e-13
    assert Information(omega).dim == 3


def test_bad_sigmas_are_refused():
    with pytest.raises(IndefiniteNoiseError, match="sigmas must be positive; not so in edge 1"):
        Diagonal([[1.0, 2.0], [0.0, 1.0], [1.0, 1.0]])
    with pytest.raises(IndefiniteNoiseError, match="edges 0, 2"):
        Isotropic([-1.0, 1.0, -2.0], 3)
    with pytest.raises(NonFiniteNoiseError, match="edge 1"):
        Diagonal([[1.0, 2.0], [np.nan, 1.0]])
    with pytest.raises(NonFiniteNoiseError, match="overflows"):
        Diagonal([1e-320, 1.0])
    with pytest.raises(NoiseShapeError):
        Diagonal(np.ones((2, 2, 2)))
    with pytest.raises(NoiseShapeError, match="dim must be a positive integer"):
        Isotropic(1.0, 0)
    with pytest.raises(NoiseShapeError, match="scalar sigma or one per edge"):
        Isotropic(np.ones((2, 2)), 2)
    assert all(issubclass(e, NoiseModelError) and issubclass(e, ValueError)
               for e in (NoiseShapeError, NonFiniteNoiseError, IndefiniteNoiseError))  # fmt: skip


def test_a_factor_checks_its_noise_model(rng):
    z = SE2.random(rng, (4,))
    edges = np.c_[np.arange(4), np.arange(1, 5)]
    with pytest.raises(NoiseShapeError, match="between: a noise model of dimension 2 for residuals of dimension 3"):
        between_factor(edges, z, Diagonal([1.0, 1.0]))
    with pytest.raises(NoiseShapeError, match="a noise model for 5 edges on a factor of 4 edges"):
        between_factor(edges, z, Information(spd(rng, 5, 3)))
    with pytest.raises(TypeError, match="noise must be a NoiseModel"):
        between_factor(edges, z, np.eye(3))  # type: ignore[arg-type]
    assert between_factor(edges, z, Isotropic(0.1, 3)).variables.shape == (4, 2)
