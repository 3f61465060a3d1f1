"""What every factor constructor shares: checking its edges and measurements, reading the
points of its slots, and wrapping a raw residual kernel into a whitened
:class:`~manopt_lie.optim.Factor`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import NonFiniteError, ShapeError
from ..lie import SE2, SE3, LieGroup, RnGroup
from ..optim import Factor
from ..optim.losses import RobustLoss
from .noise import NoiseModel, as_noise_model

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Loss = RobustLoss | str | None
Blocks = tuple[str, ...] | str | None
# kernel(*points, jac) -> r (m, k) | (r, [J_s (m, k, d_s)])
Kernel = Callable[..., Any]

POSE_GROUPS: dict[int, type[LieGroup]] = {2: SE2, 3: SE3}


def edges(variables: ArrayLike, arity: int, name: str) -> IntArray:
    """``variables`` as an integer array ``(m, arity)`` (a unary factor also takes ``(m,)``)."""
    v = np.asarray(variables)
    if v.ndim == 1 and arity == 1:
        v = v[:, None]
    if v.ndim != 2 or v.shape[1] != arity or v.shape[0] == 0 or not np.issubdtype(v.dtype, np.integer):
        raise ShapeError(
            f"{name}: variables must be a non-empty integer array of shape (m, {arity}), got {v.dtype} {v.shape}"
        )
    return v.astype(np.int64)


def measurements(value: ArrayLike, trailing: tuple[int, ...], m: int, name: str, what: str) -> FloatArray:
    """A float array ``(m, *trailing)``, finite; one shared value of shape ``trailing`` is
    broadcast to every edge."""
    a = np.array(value, dtype=np.float64)
    if a.shape == trailing:
        a = np.array(np.broadcast_to(a, (m, *trailing)))
    if a.shape != (m, *trailing):
        want = ", ".join(str(s) for s in (m, *trailing))
        raise ShapeError(f"{name}: {what} must have shape ({want}) (one per edge), got {a.shape}")
    bad = ~np.isfinite(a.reshape(m, -1)).all(axis=1)
    if bad.any():
        raise NonFiniteError(f"{name}: non-finite {what} at edge {int(np.argmax(bad))}")
    a.flags.writeable = False
    return a


def group_measurements(value: Any, m: int, name: str, what: str = "measured") -> LieGroup:
    """A group element of batch shape ``(m,)``; one element of batch shape ``()`` is
    broadcast to every edge."""
    if not isinstance(value, LieGroup):
        raise TypeError(f"{name}: {what} must be a Lie group element (SE3, SO2, Rn(3), …), got {type(value).__name__}")
    if value.batch_shape == ():
        value = value.broadcast_to((m,))
    if value.batch_shape != (m,):
        raise ShapeError(f"{name}: {what} must have batch shape ({m},) (one per edge) or (), got {value.batch_shape}")
    return value


def as_group(x: Any, group: type[LieGroup], name: str) -> LieGroup:
    """A slot's points as elements of ``group``: elements pass through; vectors ``(m, n)``
    (points of ``Euclidean(n)``) become ``Rn(n)`` elements."""
    if isinstance(x, group):
        return x
    if issubclass(group, RnGroup) and not isinstance(x, LieGroup):
        return group(x)
    raise TypeError(f"{name}: expected {group.__name__} elements, got {type(x).__name__}")


def pose_parts(x: Any, d: int, name: str) -> tuple[FloatArray, FloatArray]:
    """``(R, t)`` of poses in SE(d): ``(m, d, d)`` and ``(m, d)``."""
    group = POSE_GROUPS[d]
    if not isinstance(x, group):
        raise TypeError(f"{name}: expected {group.__name__} poses, got {type(x).__name__}")
    h = x.as_matrix()
    return h[..., :d, :d], h[..., :d, d]


def vectors(x: Any, d: int, name: str) -> FloatArray:
    """A slot's points as vectors ``(m, d)``: arrays (``Euclidean(d)``) or ``Rn(d)``
    elements (``.data``)."""
    if isinstance(x, RnGroup):
        a = x.data
    elif isinstance(x, LieGroup):
        raise TypeError(f"{name}: expected points in R^{d} (arrays or Rn({d}) elements), got {type(x).__name__}")
    else:
        a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != d:
        raise ShapeError(f"{name}: expected points of shape (m, {d}), got {a.shape}")
    return a


def whitened_factor(
    variables: IntArray,
    kernel: Kernel,
    dim: int,
    noise: NoiseModel | None,
    loss: Loss,
    name: str,
    blocks: Blocks,
) -> Factor:
    """The :class:`Factor` of a raw residual ``kernel`` (``dim`` entries per edge), whitened by ``noise``."""
    model = as_noise_model(noise, variables.shape[0], dim, name)

    def residual(*points: Any, jac: bool = False) -> Any:
        if not jac:
            return model.whiten(kernel(*points, jac=False))
        r, jacobians = kernel(*points, jac=True)
        return model.whiten(r), [model.whiten_jacobian(j) for j in jacobians]

    return Factor(variables, residual, loss=loss, name=name, blocks=blocks, residual_dim=dim)
