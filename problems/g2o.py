"""g2o pose-graph files: :func:`read`, :func:`write`, :func:`lint`.

Supported lines (fields separated by whitespace, one record per line)::

    VERTEX_SE2       id x y θ
    EDGE_SE2         i j x y θ  I11 I12 I13 I22 I23 I33
    VERTEX_SE3:QUAT  id x y z qx qy qz qw
    EDGE_SE3:QUAT    i j x y z qx qy qz qw  I11 I12 … I16 I22 … I66
    FIX              id [id …]

An edge ``i j`` carries the measured relative pose ``X_i⁻¹ X_j`` and the upper
triangle, row by row, of its information matrix in g2o's tangent order
``(ρ, θ)``, translation first (CONVENTIONS §2). Quaternions are Hamilton,
scalar last. ``#`` starts a comment that runs to the end of the line; blank
lines are skipped.

The reader is strict: any other tag (``VERTEX_XY``, ``PARAMS_SE3OFFSET``, …),
a wrong number of fields, a field that is not a number (or, for ids, not an
integer), a non-finite number, a quaternion whose norm is not 1 within
``quaternion_tol``, 2-D and 3-D records in one file, duplicate vertex ids,
self-loops, edges or ``FIX`` lines naming a vertex that the file does not
define raise :class:`ParseError` with the file name and line number.
Information matrices that are not positive definite are accepted (real data
has them); :func:`lint` reports them, with duplicate edges, vertices without
edges and vertices not connected to the anchor.

:func:`write` puts out ``repr``-exact numbers and the original ids, such that
``write ∘ read ∘ write = write`` (the text is a fixed point) and translations
and information matrices read back bit for bit.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.lie.base import LieGroup

from . import checks
from .checks import LintReport
from .graph import MeasurementGraph
from .pose_graph import PoseGraph

__all__ = ["ParseError", "LintReport", "read", "loads", "write", "dumps", "lint"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
PathOrFile = str | os.PathLike[str] | IO[str] | IO[bytes]


class ParseError(ValueError):
    """A malformed g2o line, as ``"intel.g2o:123: EDGE_SE2 needs 11 fields, got 9"``.

    Attributes
    ----------
    filename : str
        The file (or the ``name`` given to :func:`loads`).
    lineno : int or None
        1-based line number; ``None`` for a problem with the file as a whole.
    reason : str
        The message without the location.
    """

    def __init__(self, reason: str, filename: str, lineno: int | None) -> None:
        self.reason = reason
        self.filename = filename
        self.lineno = lineno
        where = f"{filename}:{lineno}" if lineno is not None else filename
        super().__init__(f"{where}: {reason}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.reason, self.filename, self.lineno))


class _Record(NamedTuple):
    """The layout of one tag: ``ids`` integer ids, ``pose`` numbers, ``info`` upper-triangle
    entries, ``fields`` their total."""

    group: type[LieGroup]
    ids: int
    pose: int
    info: int
    fields: int


_RECORDS = {
    "VERTEX_SE2": _Record(SE2, 1, 3, 0, 4),
    "EDGE_SE2": _Record(SE2, 2, 3, 6, 11),
    "VERTEX_SE3:QUAT": _Record(SE3, 1, 7, 0, 8),
    "EDGE_SE3:QUAT": _Record(SE3, 2, 7, 21, 30),
}
_TAGS: dict[type[LieGroup], tuple[str, str]] = {
    SE2: ("VERTEX_SE2", "EDGE_SE2"),
    SE3: ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT"),
}

# Angles and quaternion components are written as multiples of 2⁻⁵² (an ulp of 1):
# fine enough to move a rotation matrix entry by no more than conversions do anyway,
# coarse enough that reading and re-writing lands on the same value (see ``_stable``).
_GRID = 2.0**52


# ---- reading ---------------------------------------------------------------------------


def read(path_or_file: PathOrFile, *, name: str | None = None, quaternion_tol: float = 1e-6) -> PoseGraph:
    """Read a g2o pose graph (see the module docstring for the accepted lines).

    Parameters
    ----------
    path_or_file : path or text/binary file object
    name : str, optional
        The graph's name; default the file's stem (``"intel"``).
    quaternion_tol : float
        Largest accepted ``| ‖q‖ − 1 |``; accepted quaternions are normalized.

    Returns
    -------
    PoseGraph
        Vertices are renumbered ``0..n-1`` in increasing id order; ``graph.ids`` keeps
        the file's ids. ``graph.poses`` holds the ``VERTEX`` estimates, or is ``None``
        for a file with edges only (its vertex ids are then those the edges name).
        ``graph.fixed`` lists the ``FIX``-ed vertices in file order.

    Raises
    ------
    ParseError
        On the earliest malformed line (see the module docstring), with ``filename``
        and ``lineno``.
    """
    if isinstance(path_or_file, str | os.PathLike):
        filename = os.fspath(path_or_file)
        with open(filename, encoding="utf-8", errors="replace") as f:
            text = f.read()
        default = Path(filename).stem
    else:
        data = path_or_file.read()
        text = data.decode("utf-8", errors="replace") if isinstance(data, bytes) else data
        filename = str(getattr(path_or_file, "name", "<stream>"))
        default = Path(filename).stem if hasattr(path_or_file, "name") else "g2o"
    return _parse(text, filename, name if name is not None else default, quaternion_tol)


def loads(text: str, *, name: str = "<string>", quaternion_tol: float = 1e-6) -> PoseGraph:
    """:func:`read` from a string; ``name`` is the graph's name and the file name in errors."""
    return _parse(text, name, name, quaternion_tol)


class _Block:
    """The lines of one tag: their numbers and fields (tag excluded)."""

    __slots__ = ("linenos", "rows")

    def __init__(self) -> None:
        self.linenos: list[int] = []
        self.rows: list[list[str]] = []


def _parse(text: str, filename: str, name: str, quaternion_tol: float) -> PoseGraph:
    def error(reason: str, lineno: int | None) -> ParseError:
        return ParseError(reason, filename, lineno)

    # One pass over the lines: syntax only; numbers are converted per tag below.
    blocks = {tag: _Block() for tag in _RECORDS}
    fix_lines: list[tuple[int, list[str]]] = []
    group: type[LieGroup] | None = None
    first: tuple[int, str] = (0, "")
    for lineno, line in enumerate(text.split("\n"), 1):
        if "#" in line:
            line = line[: line.index("#")]
        parts = line.split()
        if not parts:
            continue
        tag = parts[0]
        record = _RECORDS.get(tag)
        if record is None:
            if tag == "FIX":
                if len(parts) == 1:
                    raise error("FIX needs at least 1 vertex id", lineno)
                fix_lines.append((lineno, parts[1:]))
                continue
            raise error(f"unknown tag {tag!r} (supported: {', '.join(_RECORDS)}, FIX)", lineno)
        if len(parts) - 1 != record.fields:
            raise error(f"{tag} needs {record.fields} fields, got {len(parts) - 1}", lineno)
        if group is None:
            group, first = record.group, (lineno, tag)
        elif record.group is not group:
            raise error(f"{tag} in a file of {_dims(group)} records (line {first[0]} is {first[1]})", lineno)
        block = blocks[tag]
        block.linenos.append(lineno)
        block.rows.append(parts[1:])
    if group is None:
        _fix_ids(fix_lines, error)  # a bad FIX line is the more precise error
        raise error("no VERTEX or EDGE lines", None)

    # Numbers, one conversion per tag; the earliest bad line of any tag is reported.
    vertex_tag, edge_tag = _TAGS[group]
    vertices, edges = blocks[vertex_tag], blocks[edge_tag]
    failures: list[ParseError] = []
    try:
        fixed_ids, fixed_lines = _fix_ids(fix_lines, error)
    except ParseError as e:
        failures.append(e)
    try:
        v_ids, v_vals = _numbers(vertices, _RECORDS[vertex_tag], vertex_tag, error)
    except ParseError as e:
        failures.append(e)
    try:
        e_ids, e_vals = _numbers(edges, _RECORDS[edge_tag], edge_tag, error)
    except ParseError as e:
        failures.append(e)
    if failures:
        raise min(failures, key=lambda e: e.lineno or 0)
    v_lines, e_lines = np.asarray(vertices.linenos), np.asarray(edges.linenos)

    # Semantic checks: report the earliest offending line over all of them.
    problems: list[tuple[int, str]] = []
    loops = np.flatnonzero(e_ids[:, 0] == e_ids[:, 1])
    if loops.size:
        problems.append((int(e_lines[loops[0]]), f"self-loop edge {e_ids[loops[0], 0]} → {e_ids[loops[0], 0]}"))
    if group is SE3:
        for vals, lines, what in ((v_vals, v_lines, "vertex"), (e_vals, e_lines, "edge")):
            norm = np.linalg.norm(vals[:, 3:7], axis=1)
            bad = np.flatnonzero(~(np.abs(norm - 1.0) <= quaternion_tol))
            if bad.size:
                reason = (
                    f"{what} quaternion norm {float(norm[bad[0]])!r} is not 1 within quaternion_tol={quaternion_tol:g}"
                )
                problems.append((int(lines[bad[0]]), reason))
    if v_ids.size:
        order = np.argsort(v_ids[:, 0], kind="stable")
        ids = v_ids[order, 0]
        dup = np.flatnonzero(ids[1:] == ids[:-1]) + 1
        if dup.size:
            row = int(order[dup].min())  # the duplicate that comes last in the file, earliest such line
            first_row = int(np.flatnonzero(v_ids[:, 0] == v_ids[row, 0])[0])
            reason = f"duplicate vertex id {v_ids[row, 0]} (first on line {v_lines[first_row]})"
            problems.append((int(v_lines[row]), reason))
            ids = np.unique(ids)
        known = np.isin(e_ids, ids)
        missing = np.flatnonzero(~known.all(axis=1))
        if missing.size:
            row = int(missing[0])
            absent = e_ids[row][~known[row]][0]
            reason = f"edge {e_ids[row, 0]} → {e_ids[row, 1]} names vertex {absent}, which has no VERTEX line"
            problems.append((int(e_lines[row]), reason))
    else:
        ids = np.unique(e_ids)
    unknown = np.flatnonzero(~np.isin(fixed_ids, ids))
    if unknown.size:
        problems.append((int(fixed_lines[unknown[0]]), f"FIX names vertex {fixed_ids[unknown[0]]}, not defined"))
    if problems:
        lineno, reason = min(problems)
        raise error(reason, lineno)

    poses = None
    if v_ids.size:
        poses = _elements(group, v_vals[order])
    _, first_fix = np.unique(fixed_ids, return_index=True)
    fixed = np.searchsorted(ids, fixed_ids[np.sort(first_fix)])
    k = group.dim
    upper = np.triu_indices(k)
    information = np.zeros((len(e_vals), k, k))
    information[:, upper[0], upper[1]] = e_vals[:, _RECORDS[edge_tag].pose :]
    information[:, upper[1], upper[0]] = e_vals[:, _RECORDS[edge_tag].pose :]
    return PoseGraph(
        group=group,
        edges=np.searchsorted(ids, e_ids),
        measurements=_elements(group, e_vals),
        information=information,
        ids=ids,
        poses=poses,
        fixed=fixed,
        name=name,
    )


def _dims(group: type[LieGroup]) -> str:
    return "2-D" if group is SE2 else "3-D"


def _numbers(
    block: _Block, record: _Record, tag: str, error: Callable[[str, int | None], ParseError]
) -> tuple[IntArray, FloatArray]:
    """The ids ``(m, ids)`` and finite numbers ``(m, pose + info)`` of a tag's lines, converted
    with one NumPy call each; a line-by-line pass runs only to locate a bad field."""
    k = record.ids
    if not block.rows:
        return np.zeros((0, k), dtype=np.int64), np.zeros((0, record.pose + record.info))
    try:
        ids = np.array([row[:k] for row in block.rows], dtype=np.int64)
        vals = np.array([row[k:] for row in block.rows], dtype=np.float64)
        if np.isfinite(vals).all():
            return ids, vals
    except (ValueError, OverflowError):
        pass
    for lineno, row in zip(block.linenos, block.rows, strict=True):
        for col, text in enumerate(row):
            try:
                value = np.array(text, dtype=np.int64 if col < k else np.float64)
            except OverflowError:
                raise error(f"{tag} field {col + 1} is {text!r}, out of the 64-bit id range", lineno) from None
            except ValueError:
                what = "an integer id" if col < k else "a number"
                raise error(f"{tag} field {col + 1} is {text!r}, not {what}", lineno) from None
            if not np.isfinite(value):
                raise error(f"{tag} field {col + 1} is {text!r}, not a finite number", lineno)
    raise AssertionError("the line-by-line pass accepted what the bulk conversion rejected")  # pragma: no cover


def _fix_ids(
    lines: list[tuple[int, list[str]]], error: Callable[[str, int | None], ParseError]
) -> tuple[IntArray, IntArray]:
    """The ``FIX``-ed ids in file order, and each one's line number."""
    ids: list[int] = []
    linenos: list[int] = []
    for lineno, fields in lines:  # FIX lines are few: plain Python
        for text in fields:
            try:
                ids.append(int(text))
                np.int64(ids[-1])  # out of range: OverflowError
            except (ValueError, OverflowError):
                raise error(f"FIX field {text!r} is not an integer id", lineno) from None
            linenos.append(lineno)
    return np.array(ids, dtype=np.int64), np.array(linenos, dtype=np.int64)


def _elements(group: type[LieGroup], vals: FloatArray) -> LieGroup:
    """Group elements from the pose fields ``x y θ`` or ``x y z qx qy qz qw`` (leading columns of ``vals``)."""
    if group is SE2:
        return SE2.from_rotation_translation(SO2.from_angle(vals[:, 2]), vals[:, :2])
    # The norm was checked against quaternion_tol already.
    return SE3.from_translation_quaternion(vals[:, :3], vals[:, 3:7], normalize=True)


# ---- writing ---------------------------------------------------------------------------


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
    """
    text = dumps(graph, poses)
    if isinstance(path_or_file, str | os.PathLike):
        with open(path_or_file, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
    else:
        path_or_file.write(text)


def dumps(graph: PoseGraph, poses: LieGroup | None = None) -> str:
    """The text :func:`write` writes."""
    group = graph.group
    vertex_tag, edge_tag = _TAGS[group]
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


# ---- linting ---------------------------------------------------------------------------


def lint(graph_or_path: MeasurementGraph | str | os.PathLike[str]) -> LintReport:
    """:func:`manopt_lie.problems.checks.lint` of a graph, or of a g2o file read with :func:`read`."""
    graph = read(graph_or_path) if isinstance(graph_or_path, str | os.PathLike) else graph_or_path
    return checks.lint(graph)
