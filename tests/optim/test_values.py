"""The optimizers' private value helpers: safe norms, value snapshots, result checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manopt_lie import SE2
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.manifolds import Euclidean, LieGroupManifold, Product, ProductVector, Sphere
from manopt_lie.optim._values import check_result, safe_norm, same_point, snapshot, structure


@pytest.mark.parametrize("scale", [1e-300, 1e-160, 1.0, 1e160, 1e300])
def test_safe_norm_neither_underflows_nor_overflows(scale):
    v = np.array([3.0, 4.0]) * scale
    assert safe_norm(Euclidean(2), None, v) == pytest.approx(5.0 * scale, rel=1e-15)


def test_safe_norm_of_products_and_special_values():
    m = Product(Euclidean(2), Euclidean(1))
    v = ProductVector((np.array([3e-300, 0.0]), np.array([4e-300])))
    assert safe_norm(m, (None, None), v) == pytest.approx(5e-300, rel=1e-15)
    e = Euclidean(2)
    assert safe_norm(e, None, np.zeros(2)) == 0.0
    assert safe_norm(e, None, np.array([np.inf, 1.0])) == math.inf
    assert math.isnan(safe_norm(e, None, np.array([np.nan, 1.0])))


def test_snapshots_compare_values_not_identities():
    x = np.array([1.0, 2.0])
    snap = snapshot(x)
    assert same_point(snap, x) and same_point(snap, x.copy())
    x[0] = 5.0
    assert not same_point(snap, x)
    g = SE2.exp(np.array([0.1, 0.2, 0.3]))
    snap = snapshot(g)
    assert same_point(snap, g) and same_point(snap, SE2.exp(np.array([0.1, 0.2, 0.3])))
    g.data.flags.writeable = True
    g.data[0, 2] += 1.0  # mutated in place: the same object, another point
    assert not same_point(snap, g)
    pair = (np.zeros(2), SE2.identity())
    assert same_point(snapshot(pair), (np.zeros(2), SE2.identity()))
    assert not same_point(snapshot(pair), (np.ones(2), SE2.identity()))
    assert not same_point(snapshot(np.zeros(3)), np.zeros(4)) and not same_point(snapshot(np.zeros(3)), pair)


def test_check_result_names_the_callback_and_both_shapes():
    x = np.array([1.0, 0.0, 0.0])
    expected = structure(Sphere(3).zero_vector(x))
    check_result("P", "egrad", np.ones(3), expected, "a tangent")
    with pytest.raises(ShapeError, match=r"P: egrad returned shape \(3, 3\) at x0; a tangent has shape \(3,\)"):
        check_result("P", "egrad", np.eye(3), expected, "a tangent")
    with pytest.raises(NonFiniteError, match="egrad"):
        check_result("P", "egrad", np.array([0.0, np.nan, 0.0]), expected, "a tangent")
    with pytest.raises(TypeError, match="real numbers"):
        check_result("P", "egrad", np.ones(3) * 1j, expected, "a tangent")
    lie = LieGroupManifold(SE2)
    assert structure(lie.to_ambient(SE2.identity(), lie.zero_vector(SE2.identity()))) == (3, 3)
