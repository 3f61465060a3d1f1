"""Samplers and central finite differences shared by the Lie-group tests."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from manopt_lie import S3, SE2, SE3, SE23, SO2, SO3, Bundle, LieGroup, Rn, Sim2, Sim3

GROUPS: list[type[LieGroup]] = [SO2, SO3, SE2, SE3, Sim3, Sim2, SE23, S3, Rn(3), Bundle(SO3, Rn(3))]
BATCH_SHAPES: list[tuple[int, ...]] = [(), (1,), (3, 1, 2)]
REGIMES = ["identity", "tiny", "random", "uniform", "near_pi"]
# Regimes of one group only: Sim(3) with a large log-scale |σ| = 6 (s = e^±6 ≈ 400^±1; products and
# quotients of two such elements reach e^±12). Larger |σ| (to ±700): tests/lie/test_new_groups.py.
EXTRA_REGIMES: dict[type[LieGroup], list[str]] = {Sim3: ["large_scale"], Sim2: ["large_scale"]}
FRAMES = ["right", "left"]

# Slice of the rotation coordinates inside each group's tangent vector.
ROTATION_PART = {SO2: slice(0, 1), SO3: slice(0, 3), SE2: slice(2, 3), SE3: slice(3, 6), Sim3: slice(3, 6)}
ROTATION_PART[SE23] = slice(6, 9)
ROTATION_PART[S3] = slice(0, 3)
ROTATION_PART[Sim2] = slice(2, 3)
ROTATION_PART[Bundle(SO3, Rn(3))] = slice(0, 3)
# Slice of the log-scale σ (Sim(3)): 0 in the near-π regime (σ = 0 with θ ≈ π, a hard point).
SCALE_PART = {Sim3: slice(6, 7), Sim2: slice(3, 4)}


def cases(groups: list[type[LieGroup]] | None = None) -> list[Any]:
    """``(group, regime)`` parameters: every group × :data:`REGIMES`, plus its :data:`EXTRA_REGIMES`."""
    import pytest

    return [
        pytest.param(g, r, id=f"{group_id(g)}-{r}")
        for g in (GROUPS if groups is None else groups)
        for r in REGIMES + EXTRA_REGIMES.get(g, [])
    ]


def group_id(g: type[LieGroup]) -> str:
    return g.__name__


def tangent(g: type[LieGroup], regime: str, batch: tuple[int, ...], rng: np.random.Generator, pi_gap: float = 1e-9):
    """Tangent vectors of a sampling regime; ``near_pi`` puts the rotation angle in
    ``[π − pi_gap, π − pi_gap/2]`` (for Rⁿ: vectors of norm ~30, Sophus's hard case)."""
    shape = batch + (g.dim,)
    if regime == "identity":
        return np.zeros(shape)
    if regime == "tiny":
        return 1e-8 * rng.standard_normal(shape)
    tau = rng.standard_normal(shape)
    if regime in ("random", "uniform"):
        return tau
    if regime == "large_scale":
        tau[..., SCALE_PART[g]] = 6.0 * np.sign(tau[..., SCALE_PART[g]])
        return tau
    if g not in ROTATION_PART:
        return 30.0 * tau / np.linalg.norm(tau, axis=-1, keepdims=True)
    part = ROTATION_PART[g]
    rot = tau[..., part]
    angle = np.pi - pi_gap * rng.uniform(0.5, 1.0, batch + (1,))
    tau[..., part] = rot / np.linalg.norm(rot, axis=-1, keepdims=True) * angle
    if g in SCALE_PART:
        tau[..., SCALE_PART[g]] = 0.0
    return tau


def element(g: type[LieGroup], regime: str, batch: tuple[int, ...], rng: np.random.Generator, pi_gap: float = 1e-9):
    if regime == "identity":
        return g.identity(batch)
    if regime == "uniform":
        return g.random(rng, batch)
    return g.exp(tangent(g, regime, batch, rng, pi_gap))


def rotation_angle(g: type[LieGroup], tau: np.ndarray) -> np.ndarray:
    if g not in ROTATION_PART:
        return np.zeros(tau.shape[:-1])
    return np.linalg.norm(tau[..., ROTATION_PART[g]], axis=-1)


def numerical_jacobian(
    f: Callable[..., Any], args: list[Any], wrt: int, frame: str = "right", h: float = 1e-6
) -> np.ndarray:
    """Central-difference Jacobian of ``f(*args)`` wrt ``args[wrt]``, batched.

    Group-valued inputs are perturbed by ``x ⊕ (±h e_k)`` (``frame="left"``:
    ``(±h e_k) ⊕ x``) and group-valued outputs compared with ``⊖`` of the same
    frame at ``f(x)``; array inputs and outputs use ``+`` and ``−``. All ``2·dim``
    perturbations go through ``f`` at once, on a new leading batch axis (``f`` must
    broadcast, as every group operation does).
    """
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    x = args[wrt]
    y0 = f(*args)
    group = isinstance(x, LieGroup)
    dim = x.dim if group else np.shape(x)[-1]
    batch_ndim = len(x.batch_shape) if group else np.ndim(x) - 1
    steps = (h * np.concatenate([np.eye(dim), -np.eye(dim)])).reshape((2 * dim,) + (1,) * batch_ndim + (dim,))
    a = list(args)
    if group:
        a[wrt] = x.rplus(steps) if frame == "right" else x.lplus(steps)
    else:
        a[wrt] = x + steps
    y = f(*a)
    if isinstance(y, LieGroup):
        y = y.rminus(y0) if frame == "right" else y.lminus(y0)
    return np.moveaxis((y[:dim] - y[dim:]) / (2 * h), 0, -1)


def assert_jacobian(j: np.ndarray, j_num: np.ndarray, tol: float = 1e-6) -> None:
    """``|J − J_fd| ≤ tol·max(1, |J|)`` entrywise, with matching shapes."""
    assert j.shape == j_num.shape, (j.shape, j_num.shape)
    scale = np.maximum(1.0, np.abs(j).max(initial=0.0))
    err = np.abs(j - j_num).max(initial=0.0)
    assert err <= tol * scale, f"Jacobian differs from finite differences by {err:.3g}"


def size(x: LieGroup) -> float:
    """``max(1, max |entry|)`` of the matrix form: the scale of an element's round-off."""
    return max(1.0, float(np.abs(x.as_matrix()).max(initial=0.0)))


def assert_same(x: LieGroup, y: LieGroup, tol: float = 1e-12) -> None:
    """Equal matrix forms, relative to their size."""
    a, b = x.as_matrix(), y.as_matrix()
    assert a.shape == b.shape, (a.shape, b.shape)
    scale = max(1.0, np.abs(a).max(initial=0.0))
    assert np.abs(a - b).max(initial=0.0) <= tol * scale
