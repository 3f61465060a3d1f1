"""What both writers share: ``repr``-exact numbers, rotations rounded stably, the pose lines.

Angles and quaternion components are written as multiples of 2⁻⁵² (an ulp of 1): fine
enough to move a rotation matrix entry by no more than conversions do anyway, coarse enough
that reading and re-writing lands on the same value (see :func:`stable`).
"""

from __future__ import annotations

import io
from collections.abc import Callable

import numpy as np

from manopt_lie import SE2, SO2, SO3
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.lie.base import LieGroup

from ..pose_graph import PoseGraph
from ._records import TAGS, FloatArray, IntArray

__all__ = ["check_finite", "edge_lines", "fix_line", "lines", "pose_fields", "stable", "upper", "vertex_lines"]

_GRID = 2.0**52


def upper(information: FloatArray) -> FloatArray:
    """The upper triangles, row by row, of ``(r, k, k)`` matrices: ``(r, k(k+1)/2)``."""
    rows, cols = np.triu_indices(information.shape[-1])
    return information[:, rows, cols]


def lines(out: io.StringIO, tag: str, ids: IntArray, vals: FloatArray) -> None:
    """``tag ids… vals…`` per row; ``repr`` is the shortest text that reads back exactly."""
    for row_ids, row in zip(ids.tolist(), vals.tolist(), strict=True):
        out.write(f"{tag} {' '.join(map(str, row_ids))} {' '.join(map(repr, row))}\n")


def check_finite(vals: FloatArray, message: str, ids: IntArray) -> None:
    """Raise :class:`NonFiniteError` ``message`` with the ``ids`` of the rows of ``vals`` that are not finite."""
    bad = np.flatnonzero(~np.isfinite(vals).all(axis=1))
    if bad.size:
        raise NonFiniteError(f"{message} {ids[bad[:10]].tolist()}")


def vertex_lines(out: io.StringIO, graph: PoseGraph, poses: LieGroup, what: str = "poses") -> None:
    """The pose ``VERTEX`` lines of ``graph`` with ``poses`` (checked), in increasing id order."""
    group, ids = graph.group, graph.ids
    if not isinstance(poses, group) or poses.batch_shape != (graph.n,):
        raise ShapeError(f"{graph.name}: {what} must be {group.__name__} with batch shape ({graph.n},)")
    vals = pose_fields(poses)
    check_finite(vals, f"{graph.name}: non-finite poses at vertex ids", ids)
    order = np.argsort(ids, kind="stable")
    lines(out, TAGS[group][0], ids[order, None], vals[order])


def fix_line(out: io.StringIO, graph: PoseGraph) -> None:
    """The ``FIX`` line, if any vertex is fixed."""
    if graph.fixed.size:
        out.write("FIX " + " ".join(map(str, graph.ids[graph.fixed].tolist())) + "\n")


def edge_lines(out: io.StringIO, graph: PoseGraph) -> None:
    """The relative-pose ``EDGE`` lines of ``graph``."""
    ids: IntArray = graph.ids[graph.edges]
    vals = np.concatenate([pose_fields(graph.measurements), upper(graph.information)], axis=1)
    check_finite(vals, f"{graph.name}: non-finite measurements on edges", ids)
    lines(out, TAGS[graph.group][1], ids, vals)


def pose_fields(x: LieGroup) -> FloatArray:
    """``(n, 3)`` rows ``x y θ`` or ``(n, 7)`` rows ``x y z qx qy qz qw`` for elements of batch ``(n,)``."""
    t = x.translation()  # type: ignore[attr-defined]
    r = x.rotation()  # type: ignore[attr-defined]
    if isinstance(x, SE2):
        angle = stable(_round_angle(r.angle()[:, None]), _angle_step)
        return np.concatenate([t, angle], axis=1)
    q = stable(_round_quaternion(r.as_quaternion()), _quaternion_step)
    return np.concatenate([t, q], axis=1)


def _round_angle(theta: FloatArray) -> FloatArray:
    # ``+ 0.0`` turns -0.0 into 0.0, so equal values print equally.
    return np.round(theta * _GRID) / _GRID + 0.0


def _angle_step(theta: FloatArray) -> FloatArray:
    """Write ∘ read of angles ``(r, 1)``: the angle of the rotation :func:`read` builds, rounded."""
    return _round_angle(SO2.from_angle(theta[:, 0]).angle()[:, None])


def _round_quaternion(q: FloatArray) -> FloatArray:
    """Unit quaternions ``(r, 4)`` with ``w ≥ 0``, three components on the grid and the
    largest one ``±√(1 − Σ others²)``, so the norm is 1 to an ulp (normalization on
    reading then barely moves them)."""
    rows = np.arange(len(q))
    q = q * np.where(q[:, 3:] < 0.0, -1.0, 1.0)
    big = np.argmax(np.abs(q), axis=1)
    out = np.round(q * _GRID) / _GRID
    out[rows, big] = 0.0
    out[rows, big] = np.copysign(np.sqrt(np.maximum(1.0 - np.sum(out * out, axis=1), 0.0)), q[rows, big])
    return out + 0.0


def _quaternion_step(q: FloatArray) -> FloatArray:
    """Write ∘ read of quaternions ``(r, 4)``, as :func:`read` builds the rotation."""
    return _round_quaternion(SO3.from_quaternion(q, normalize=True).as_quaternion())


def stable(start: FloatArray, step: Callable[[FloatArray], FloatArray], iterations: int = 24) -> FloatArray:
    """Representations ``(r, p)`` that writing reproduces after a read: ``W ∘ read ∘ W = W``.

    Writing rounds a rotation to ``start``; ``step`` is write ∘ read on representations.
    Almost every ``start`` is a fixed point, ``step(c) == c``. The others are iterated
    into a cycle (of up to 4 members; none longer has been seen), represented by its
    lexicographically least member ``a``. Re-writing the rotation read from ``a`` starts
    at ``step(a)``, on the same cycle, so it ends at ``a`` again.
    """
    nxt = step(start)
    moving = np.flatnonzero((nxt != start).any(axis=1))
    if not moving.size:
        return start
    out = start.copy()
    path = [start[moving], nxt[moving]]
    for _ in range(iterations):
        path.append(step(path[-1]))
    trail = np.stack(path)  # (iterations + 2, r, p)
    last = trail[-1]
    result = last.copy()
    undecided = np.ones(len(moving), dtype=bool)
    for period in range(1, 5):
        rows = np.flatnonzero(undecided & (trail[-1 - period] == last).all(axis=1))
        best = last[rows]
        for member in trail[len(trail) - period : -1, rows]:
            differ = member != best
            col = np.argmax(differ, axis=1)
            at = np.arange(len(rows))
            less = differ.any(axis=1) & (member[at, col] < best[at, col])
            best = np.where(less[:, None], member, best)
        result[rows] = best
        undecided[rows] = False
    out[moving] = result  # rows still drifting keep their last value (never seen in tests)
    return out
