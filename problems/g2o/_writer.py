"""Writing g2o files: :func:`write`, :func:`dumps` (exact numbers, a fixed point of write ∘ read)."""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from typing import IO

import numpy as np

from manopt_lie import SE2, SO2, SO3
from manopt_lie.atomic import atomic_write
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.lie.base import LieGroup

from ..pose_graph import PoseGraph
from ._records import TAGS, FloatArray, IntArray

__all__ = ["write", "dumps"]

# Angles and quaternion components are written as multiples of 2⁻⁵² (an ulp of 1):
# fine enough to move a rotation matrix entry by no more than conversions do anyway,
# coarse enough that reading and re-writing lands on the same value (see ``_stable``).
_GRID = 2.0**52


def write(path_or_file: str | os.PathLike[str] | IO[str], graph: PoseGraph, poses: LieGroup | None = None) -> None:
    """Write ``graph`` as a g2o file: ``VERTEX`` lines, one ``FIX`` line, ``EDGE`` lines.

    Parameters
    ----------
    path_or_file : path or text file object
    graph : PoseGraph
    poses : group element, batch ``(n,)``, optional
        Vertex estimates to write; default ``graph.poses``. With neither, only the
        edges (and ``FIX``) are written, which needs every vertex to have an edge.

    Notes
    -----
    Vertices carry ``graph.ids``; information matrices are written as their upper
    triangle (symmetric ones exactly). Numbers are written as ``repr(float)``, which
    reads back to the same float, so translations and information matrices survive
    :func:`read` exactly. Rotations are written as the angle ``atan2(R₁₀, R₀₀)`` (on
    a 2⁻⁵² grid) or a unit quaternion with ``w ≥ 0`` (on that grid), chosen so that
    ``write(read(write(graph)))`` and ``write(graph)`` are the same text. Read back, a
    rotation matrix entry moves by ~1e-16 (SE2) or at most a few 1e-15 (SE3: the
    quaternion ↔ matrix conversions alone move entries by up to ~1.5e-15).

    A path is written atomically (:func:`manopt_lie.atomic.atomic_write`): whole, or not
    at all.
    """
    text = dumps(graph, poses)
    if isinstance(path_or_file, str | os.PathLike):
        with atomic_write(path_or_file, encoding="utf-8", newline="\n") as f:
            f.write(text)
    else:
        path_or_file.write(text)


def dumps(graph: PoseGraph, poses: LieGroup | None = None) -> str:
    """The text :func:`write` writes."""
    group = graph.group
    vertex_tag, edge_tag = TAGS[group]
    ids: IntArray = graph.ids  # type: ignore[assignment]
    poses = graph.poses if poses is None else poses
    out = io.StringIO()
    if poses is not None:
        if not isinstance(poses, group) or poses.batch_shape != (graph.n,):
            raise ShapeError(f"{graph.name}: poses must be {group.__name__} with batch shape ({graph.n},)")
        vals = _pose_fields(poses)
        _check_finite(vals, f"{graph.name}: non-finite poses at vertex ids", ids)
        _lines(out, vertex_tag, ids[:, None], vals)
    else:
        lonely = np.setdiff1d(ids, ids[graph.edges])
        if lonely.size:
            raise ValueError(
                f"{graph.name}: vertices {lonely[:10].tolist()} have no edge and no pose; g2o needs poses to write them"
            )
    if graph.fixed.size:
        out.write("FIX " + " ".join(map(str, ids[graph.fixed].tolist())) + "\n")
    k = group.dim
    upper = np.triu_indices(k)
    vals = np.concatenate([_pose_fields(graph.measurements), graph.information[:, upper[0], upper[1]]], axis=1)
    _check_finite(vals, f"{graph.name}: non-finite measurements on edges", ids[graph.edges])
    _lines(out, edge_tag, ids[graph.edges], vals)
    return out.getvalue()


def _lines(out: io.StringIO, tag: str, ids: IntArray, vals: FloatArray) -> None:
    """``tag ids… vals…`` per row; ``repr`` is the shortest text that reads back exactly."""
    for row_ids, row in zip(ids.tolist(), vals.tolist(), strict=True):
        out.write(f"{tag} {' '.join(map(str, row_ids))} {' '.join(map(repr, row))}\n")


def _check_finite(vals: FloatArray, message: str, ids: IntArray) -> None:
    bad = np.flatnonzero(~np.isfinite(vals).all(axis=1))
    if bad.size:
        raise NonFiniteError(f"{message} {ids[bad[:10]].tolist()}")


def _pose_fields(x: LieGroup) -> FloatArray:
    """``(n, 3)`` rows ``x y θ`` or ``(n, 7)`` rows ``x y z qx qy qz qw`` for elements of batch ``(n,)``."""
    t = x.translation()  # type: ignore[attr-defined]
    r = x.rotation()  # type: ignore[attr-defined]
    if isinstance(x, SE2):
        angle = _stable(_round_angle(r.angle()[:, None]), _angle_step)
        return np.concatenate([t, angle], axis=1)
    q = _stable(_round_quaternion(r.as_quaternion()), _quaternion_step)
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


def _stable(start: FloatArray, step: Callable[[FloatArray], FloatArray], iterations: int = 24) -> FloatArray:
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
