"""Problem and the derivative / retraction checkers of ``manopt_lie.check``."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

from manopt_lie import SO3
from manopt_lie.check import CheckReport, check_gradient, check_hessian, check_retraction
from manopt_lie.manifolds import Euclidean, LieGroupManifold, Manifold, Sphere
from manopt_lie.optim import Problem

matplotlib.use("Agg")

N = 5
_A = np.random.default_rng(0).standard_normal((N, N))
A = _A + _A.T  # the cost xᵀAx, symmetric


def cost(x: np.ndarray) -> float:
    return float(x @ A @ x)


def egrad(x: np.ndarray) -> np.ndarray:
    return 2 * A @ x


def ehess(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    return 2 * A @ u


def sphere_problem(**derivatives: object) -> Problem:
    return Problem(Sphere(N), cost, **derivatives)  # type: ignore[arg-type]


class _FirstOrderSphere(Sphere):
    """``R_x(v) = (x + v + ‖v‖² a)/‖·‖`` with ``a = proj_x(w)``: a retraction whose
    second-order term has a tangential part, so it is only first order."""

    w = np.linspace(1.0, 2.0, N)

    def retr(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        y = x + v + np.sum(v * v, axis=-1, keepdims=True) * self.proj(x, self.w)
        return y / np.linalg.norm(y, axis=-1, keepdims=True)


class _NotARetraction(Sphere):
    """``(x + 2v)/‖x + 2v‖``: its velocity at 0 is ``2v``."""

    def retr(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        return super().retr(x, 2 * v)


class _SphereWithoutDist(Sphere):
    def dist(self, x: np.ndarray, y: np.ndarray) -> object:
        return Manifold.dist(self, x, y)  # raises MissingOperationError


# ---- Problem -------------------------------------------------------------------------


def test_problem_gradient_from_egrad_and_rgrad(rng: np.random.Generator) -> None:
    S = Sphere(N)
    x = S.random_point(rng)
    expected = S.proj(x, egrad(x))
    np.testing.assert_allclose(sphere_problem(egrad=egrad).grad(x), expected)
    np.testing.assert_allclose(sphere_problem(rgrad=lambda y: S.proj(y, egrad(y))).grad(x), expected)
    assert sphere_problem(egrad=egrad).cost(x) == pytest.approx(cost(x))


def test_problem_hessian_from_ehess_and_rhess(rng: np.random.Generator) -> None:
    S = Sphere(N)
    x = S.random_point(rng)
    v = S.random_tangent(x, rng)
    expected = S.proj(x, 2 * A @ v) - (x @ egrad(x)) * v
    np.testing.assert_allclose(sphere_problem(egrad=egrad, ehess=ehess).hess(x, v), expected)
    rhess = lambda y, u: S.ehess2rhess(y, egrad(y), ehess(y, u), u)
    np.testing.assert_allclose(sphere_problem(rgrad=lambda y: S.proj(y, egrad(y)), rhess=rhess).hess(x, v), expected)


def test_problem_flags_and_missing_derivatives(rng: np.random.Generator) -> None:
    x = Sphere(N).random_point(rng)
    bare = sphere_problem()
    assert not bare.has_gradient and not bare.has_hessian
    assert sphere_problem(egrad=egrad, ehess=ehess).has_hessian
    with pytest.raises(NotImplementedError, match="egrad"):
        bare.grad(x)
    with pytest.raises(NotImplementedError, match="ehess"):
        sphere_problem(egrad=egrad).hess(x, x)


@pytest.mark.parametrize(
    ("derivatives", "match"),
    [
        ({"egrad": egrad, "rgrad": egrad}, "not both"),
        ({"egrad": egrad, "ehess": ehess, "rhess": ehess}, "not both"),
        ({"ehess": ehess}, "needs egrad"),
        ({"rgrad": egrad, "ehess": ehess}, "needs egrad"),
        ({"rhess": ehess}, "needs a gradient"),
    ],
)
def test_problem_rejects_inconsistent_derivatives(derivatives: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        sphere_problem(**derivatives)


def test_problem_rejects_non_callables() -> None:
    with pytest.raises(TypeError, match="egrad"):
        sphere_problem(egrad=np.ones(N))
    with pytest.raises(TypeError, match="manifold"):
        Problem("sphere", cost)  # type: ignore[arg-type]


# ---- gradient and Hessian checks --------------------------------------------------------


def test_correct_gradient_passes_with_slope_two() -> None:
    report = check_gradient(sphere_problem(egrad=egrad), rng=1)
    assert report.passed, report
    assert report.slope == pytest.approx(2.0, abs=0.1)
    assert report.details["tangent_error"] < 1e-12
    i, j = report.window
    assert j - i >= 8 and report.t.shape == report.error.shape == (51,)


@pytest.mark.parametrize("factor", [1.3, -1.0])
def test_wrong_gradient_fails_with_slope_one(factor: float) -> None:
    report = check_gradient(sphere_problem(egrad=lambda x: factor * egrad(x)), rng=1)
    assert not report.passed
    assert report.slope == pytest.approx(1.0, abs=0.1)
    assert "gradient is probably wrong" in report.message


def test_non_tangent_gradient_fails() -> None:
    report = check_gradient(sphere_problem(rgrad=egrad), rng=1)  # the unprojected Euclidean gradient
    assert report.slope == pytest.approx(2.0, abs=0.1)  # ⟨∇f, d⟩ = ⟨grad f, d⟩ for tangent d
    assert not report.passed and "not a tangent vector" in report.message


def test_correct_hessian_passes_with_slope_three() -> None:
    report = check_hessian(sphere_problem(egrad=egrad, ehess=ehess), rng=1)
    assert report.passed, report
    assert report.slope == pytest.approx(3.0, abs=0.1)
    assert report.details["symmetry_error"] < 1e-12


def test_wrong_hessian_fails_with_slope_two() -> None:
    report = check_hessian(sphere_problem(egrad=egrad, ehess=lambda x, u: 1.3 * ehess(x, u)), rng=1)
    assert not report.passed
    assert report.slope == pytest.approx(2.0, abs=0.1)


def test_round_off_is_measured_not_assumed() -> None:
    """``f = 60 + εx³ − x⁴`` at 0 along 1: the remainder ``εt³ − t⁴`` is cubic only for
    ``t ≪ ε``; the assumed floor ``10⁻¹²|f|`` left only the bending stretch (slope 2.86),
    the measured round-off (``~10⁻¹⁵|f|``) leaves the cubic one."""
    eps = 0.05
    problem = Problem(
        Euclidean(1),
        lambda x: float(60.0 + eps * x[0] ** 3 - x[0] ** 4),
        egrad=lambda x: 3 * eps * x**2 - 4 * x**3,
        ehess=lambda x, u: (6 * eps * x - 12 * x**2) * u,
    )
    report = check_hessian(problem, np.zeros(1), np.ones(1))
    assert report.passed, report
    assert report.slope == pytest.approx(3.0, abs=0.05)
    assert report.t[report.window[0]] < 1e-3  # below where 10⁻¹²|f| cut it off


def test_asymmetric_hessian_fails() -> None:
    S, M = Sphere(N), np.triu(A)
    problem = sphere_problem(egrad=egrad, rhess=lambda x, v: S.proj(x, M @ v))
    report = check_hessian(problem, rng=1)
    assert report.details["symmetry_error"] > 1e-3
    assert not report.passed and "not symmetric" in report.message


def test_exact_model_passes_at_machine_precision(rng: np.random.Generator) -> None:
    E = Euclidean(N)
    report = check_hessian(Problem(E, cost, egrad=egrad, ehess=ehess), rng=rng)
    assert report.passed and np.isnan(report.slope)
    assert report.window == (0, 0)
    assert "machine precision" in report.message


def test_lie_group_gradient_and_hessian() -> None:
    B = np.random.default_rng(2).standard_normal((3, 3))
    problem = Problem(
        LieGroupManifold(SO3),
        lambda X: np.sum(B * X.as_matrix()) ** 2,
        egrad=lambda X: 2 * np.sum(B * X.as_matrix()) * B,
        ehess=lambda X, U: 2 * np.sum(B * U) * B,
    )
    assert check_gradient(problem, rng=3).passed
    report = check_hessian(problem, rng=3)
    assert report.passed and report.slope == pytest.approx(3.0, abs=0.1)


def test_given_point_and_direction_and_seeds(rng: np.random.Generator) -> None:
    S, problem = Sphere(N), sphere_problem(egrad=egrad)
    x = S.random_point(rng)
    d = 0.5 * S.random_tangent(x, rng)
    assert check_gradient(problem, x, d).passed
    np.testing.assert_array_equal(check_gradient(problem, rng=7).error, check_gradient(problem, rng=7).error)
    with pytest.raises(ValueError, match="nonzero"):
        check_gradient(problem, x, S.zero_vector(x))
    with pytest.raises(ValueError, match="not a point"):
        check_gradient(problem, 2 * x)


# ---- retraction check --------------------------------------------------------------------


def test_normalization_retraction_is_second_order() -> None:
    report = check_retraction(Sphere(N), rng=1)
    assert report.passed, report
    assert report.slope == pytest.approx(3.0, abs=0.1)
    assert report.details["second_order"] == 1.0
    assert report.details["retraction_order"] == pytest.approx(2.0, abs=0.1)
    assert report.details["zero_error"] < 1e-12 and report.details["derivative_error"] < 1e-6


@pytest.mark.parametrize("manifold", [_FirstOrderSphere(N), _SphereWithoutDist(N)])
def test_first_order_retraction_and_frobenius_fallback(manifold: Sphere) -> None:
    report = check_retraction(manifold, rng=1)
    assert report.passed, report
    first = isinstance(manifold, _FirstOrderSphere)
    assert report.slope == pytest.approx(2.0 if first else 3.0, abs=0.1)
    assert report.details["second_order"] == (0.0 if first else 1.0)


def test_not_a_retraction_fails() -> None:
    report = check_retraction(_NotARetraction(N), rng=1)
    assert not report.passed
    assert report.details["derivative_error"] == pytest.approx(1.0)
    assert "≠ v" in report.message


def test_lie_group_retraction_is_the_exponential() -> None:
    report = check_retraction(LieGroupManifold(SO3), rng=1)  # R = Exp: compared through log
    assert report.passed and np.isnan(report.slope)
    assert report.details["retraction_order"] == np.inf
    assert report.details["derivative_error"] < 1e-6


# ---- report ------------------------------------------------------------------------------


def test_report_is_frozen_and_printable() -> None:
    report = check_gradient(sphere_problem(egrad=egrad), rng=1)
    assert isinstance(report, CheckReport)
    with pytest.raises(AttributeError):
        report.passed = False  # type: ignore[misc]
    text = str(report)
    assert text.startswith("gradient check passed") and f"slope {report.slope:.2f}" in text
    assert "tangent_error" in text


def test_plot_draws_error_fit_and_reference() -> None:
    import matplotlib.pyplot as plt

    fitted = check_hessian(sphere_problem(egrad=egrad, ehess=ehess), rng=1)
    fig = fitted.plot()
    assert isinstance(fig, Figure) and len(fig.axes[0].lines) == 3  # errors, fitted stretch, reference
    plt.close(fig)
    exact = check_hessian(Problem(Euclidean(N), cost, egrad=egrad, ehess=ehess), rng=1)
    fig, ax = plt.subplots()
    assert exact.plot(ax) is fig and len(ax.lines) >= 1  # nothing fitted: no highlighted stretch
    plt.close(fig)
