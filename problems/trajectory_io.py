"""Trajectory files: TUM and KITTI (evo's formats), and the poses of g2o files.

- **TUM** (``t tx ty tz qx qy qz qw`` per line): a timestamp in seconds, the position and
  the orientation as a Hamilton quaternion, scalar last (TUM RGB-D benchmark; evo's ``tum``).
- **KITTI** (12 numbers per line): the top 3 × 4 of the pose matrix ``[R t]``, row-major;
  no timestamps (poses are matched by index; evo's ``kitti``).
- **g2o**: the ``VERTEX`` poses of a pose graph or of a landmark file (their ids serve as
  timestamps, so two g2o files are matched vertex by vertex); written back as a pose graph
  of the trajectory's odometry (:func:`to_pose_graph`).

Lines are separated by whitespace; ``#`` starts a comment; blank lines are skipped. A line
with the wrong number of fields, a field that is no finite number, a quaternion whose norm
is off 1 by more than ``quaternion_tol`` or a rotation block farther than ``rotation_tol``
from a rotation raises :class:`~manopt_lie.problems.g2o.ParseError` naming the file and the
line. Accepted quaternions are normalized and rotation blocks projected onto SO(3). Writers
print ``repr``-exact numbers and write atomically (:func:`manopt_lie.atomic.atomic_write`).

A :class:`Trajectory` holds SE(3) poses (SE(2) for planar g2o files; :meth:`Trajectory.lift`
puts them in the plane ``z = 0``).
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3, SO3
from manopt_lie.atomic import atomic_write
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

from . import g2o
from .g2o import ParseError
from .g2o._reader import QUATERNION_TOL
from .pose_graph import PoseGraph

FloatArray = NDArray[np.float64]
PathOrFile = str | os.PathLike[str] | IO[str]

FORMATS = ("tum", "kitti", "g2o")
"""The trajectory file formats :func:`read` and the command line know, by name."""
ROTATION_TOL = 1e-4
"""Largest ``‖RᵀR − I‖`` accepted (and projected away) in a KITTI rotation block: KITTI's
files print 7–9 significant digits, which leaves errors near 1e-7."""

__all__ = ["FORMATS", "Trajectory", "read", "sniff", "read_tum", "write_tum", "read_kitti", "write_kitti",
           "read_g2o", "write_g2o", "to_pose_graph", "ParseError"]  # fmt: skip


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Poses in time order.

    Attributes
    ----------
    poses : SE3 (or SE2) element, batch ``(n,)``
    stamps : ``(n,)`` or None
        Timestamps in seconds (TUM), vertex ids (g2o), or ``None`` (KITTI: matched by index).
    name : str
    """

    poses: LieGroup
    stamps: FloatArray | None = None
    name: str = "trajectory"

    def __post_init__(self) -> None:
        if not isinstance(self.poses, SE2 | SE3) or len(self.poses.batch_shape) != 1:
            raise ShapeError(f"{self.name}: poses must be SE2 or SE3 with batch shape (n,), got {self.poses!r}")
        if self.stamps is not None:
            stamps = np.asarray(self.stamps, dtype=np.float64)
            if stamps.shape != self.poses.batch_shape or not np.isfinite(stamps).all():
                raise ShapeError(f"{self.name}: stamps must be {self.poses.batch_shape[0]} finite numbers")
            object.__setattr__(self, "stamps", stamps)

    @property
    def n(self) -> int:
        """Number of poses."""
        return int(self.poses.batch_shape[0])

    @property
    def d(self) -> int:
        """The dimension of the positions, 2 or 3."""
        return int(self.poses.point_dim)  # type: ignore[attr-defined]

    @property
    def positions(self) -> FloatArray:
        """``(n, d)``."""
        return np.asarray(self.poses.as_matrix()[:, : self.d, self.d])

    def __len__(self) -> int:
        return self.n

    def subset(self, index: Any) -> Trajectory:
        """The poses (and stamps) at ``index`` (an integer array)."""
        index = np.asarray(index, dtype=np.int64)
        stamps = None if self.stamps is None else self.stamps[index]
        return Trajectory(self.poses[index], stamps, self.name)

    def lift(self) -> Trajectory:
        """The trajectory in 3-D: SE(2) poses become SE(3) poses in the plane ``z = 0``."""
        if self.d == 3:
            return self
        m = self.poses.as_matrix()
        out = np.zeros((self.n, 4, 4))
        out[:, :2, :2], out[:, :2, 3] = m[:, :2, :2], m[:, :2, 2]
        out[:, 2, 2] = out[:, 3, 3] = 1.0
        return Trajectory(SE3.from_matrix(out), self.stamps, self.name)


# ---- reading -------------------------------------------------------------------------------


def _source(path_or_file: PathOrFile) -> tuple[str, str, str]:
    """``(text, file name for messages, default name)``."""
    if isinstance(path_or_file, str | os.PathLike):
        path = Path(path_or_file)
        if path.is_dir():
            raise IsADirectoryError(f"{path} is a directory, not a trajectory file")
        return path.read_text(encoding="utf-8-sig"), str(path), path.stem
    name = getattr(path_or_file, "name", "<stream>")
    text = path_or_file.read()
    if isinstance(text, bytes):
        text = text.decode("utf-8-sig")
    return text.removeprefix("\ufeff"), str(name), Path(str(name)).stem


def _rows(text: str, fields: int, what: str, filename: str) -> tuple[FloatArray, NDArray[np.int64]]:
    """The numbers ``(k, fields)`` of the data lines and their 1-based line numbers."""
    rows, lines = [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        if len(tokens) != fields:
            raise ParseError(f"a {what} line needs {fields} numbers, got {len(tokens)}", filename, lineno)
        try:
            values = [float(t) for t in tokens]
        except ValueError:
            bad = next(t for t in tokens if not _is_float(t))
            raise ParseError(f"not a number: {bad!r}", filename, lineno) from None
        rows.append(values)
        lines.append(lineno)
    if not rows:
        raise ParseError(f"no {what} lines", filename, None)
    data, numbers = np.array(rows, dtype=np.float64), np.array(lines, dtype=np.int64)
    finite = np.isfinite(data).all(axis=1)
    if not finite.all():
        raise ParseError("a number that is not finite", filename, int(numbers[np.argmin(finite)]))
    return data, numbers


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def read_tum(
    path_or_file: PathOrFile, *, name: str | None = None, quaternion_tol: float = QUATERNION_TOL
) -> Trajectory:
    """Read a TUM trajectory (``t tx ty tz qx qy qz qw`` per line; see the module doc).

    Raises
    ------
    ParseError
        On the first malformed line, naming it.
    """
    text, filename, stem = _source(path_or_file)
    data, lines = _rows(text, 8, "TUM", filename)
    q = data[:, 4:]
    off = np.abs(np.linalg.norm(q, axis=1) - 1.0)
    if not (off <= quaternion_tol).all():
        k = int(np.argmax(~(off <= quaternion_tol)))
        raise ParseError(f"the quaternion's norm is {np.linalg.norm(q[k]):.6g}, not 1 (within {quaternion_tol:g})",
                         filename, int(lines[k]))  # fmt: skip
    poses = SE3.from_rotation_translation(SO3.from_quaternion(q, normalize=True), data[:, 1:4])
    return Trajectory(poses, data[:, 0], name if name is not None else stem)


def read_kitti(path_or_file: PathOrFile, *, name: str | None = None, rotation_tol: float = ROTATION_TOL) -> Trajectory:
    """Read a KITTI pose file (12 numbers per line, ``[R t]`` row-major; see the module doc).

    Raises
    ------
    ParseError
        On the first malformed line, naming it.
    """
    text, filename, stem = _source(path_or_file)
    data, lines = _rows(text, 12, "KITTI", filename)
    m = data.reshape(-1, 3, 4)
    r = m[:, :, :3]
    off = np.linalg.norm(np.swapaxes(r, 1, 2) @ r - np.eye(3), axis=(1, 2))
    bad = ~((off <= rotation_tol) & (np.linalg.det(r) > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise ParseError(f"the rotation block is not a rotation (‖RᵀR − I‖ = {off[k]:.3g}, det = "
                         f"{np.linalg.det(r[k]):.6g})", filename, int(lines[k]))  # fmt: skip
    rotations = SO3.from_matrix(r, project=True)
    return Trajectory(SE3.from_rotation_translation(rotations, m[:, :, 3]), None, name if name is not None else stem)


def read_g2o(path_or_file: PathOrFile, *, name: str | None = None) -> Trajectory:
    """The ``VERTEX`` poses of a g2o file (a pose graph, or the poses of a landmark file), in
    increasing id order, the ids as stamps.

    Raises
    ------
    ParseError
        For a malformed file.
    ValueError
        For a file without ``VERTEX`` poses.
    """
    graph = g2o.read(path_or_file) if name is None else g2o.read(path_or_file, name=name)
    poses = graph.pose_graph()
    if poses.poses is None:
        raise ValueError(f"{graph.name} has no VERTEX poses: there is no trajectory in it")
    return Trajectory(poses.poses, poses.ids.astype(np.float64), graph.name)


def sniff(path: str | os.PathLike[str]) -> str:
    """The format of a trajectory file: by its extension (``.g2o``, ``.tum``, ``.kitti``), else by
    the number of fields of its first data line (8: TUM, 12: KITTI), else ``g2o`` for a
    line starting with a g2o tag.

    Raises
    ------
    ValueError
        When it cannot tell.
    """
    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    if suffix in FORMATS:
        return suffix
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        for line in f:
            tokens = line.split("#", 1)[0].split()
            if not tokens:
                continue
            if tokens[0][:1].isalpha() and tokens[0].isupper():
                return "g2o"
            if len(tokens) in (8, 12):
                return "tum" if len(tokens) == 8 else "kitti"
            break
    raise ValueError(f"{path}: cannot tell the trajectory format (8 numbers a line: TUM, 12: KITTI); pass --format")


def read(path: str | os.PathLike[str], format: str | None = None, **options: Any) -> Trajectory:
    """Read a trajectory in ``format`` (:data:`FORMATS`; default :func:`sniff`)."""
    format = sniff(path) if format is None else format
    readers = {"tum": read_tum, "kitti": read_kitti, "g2o": read_g2o}
    if format not in readers:
        raise ValueError(f"format must be one of {FORMATS}, got {format!r}")
    return readers[format](path, **options)  # type: ignore[operator]


# ---- writing -------------------------------------------------------------------------------


def _write(path_or_file: PathOrFile, text: str) -> None:
    if isinstance(path_or_file, str | os.PathLike):
        with atomic_write(path_or_file, encoding="utf-8", newline="\n") as f:
            f.write(text)
    else:
        path_or_file.write(text)


def _lines(rows: FloatArray) -> str:
    out = io.StringIO()
    for row in rows.tolist():
        out.write(" ".join(map(repr, row)) + "\n")
    return out.getvalue()


def dumps_tum(trajectory: Trajectory) -> str:
    """The text :func:`write_tum` writes."""
    if trajectory.stamps is None:
        raise ValueError(f"{trajectory.name} has no timestamps; TUM files need them (write KITTI, or give stamps)")
    t = trajectory.lift()
    q = t.poses.rotation().as_quaternion()  # type: ignore[attr-defined]
    assert t.stamps is not None  # lifting keeps them
    return _lines(np.column_stack([t.stamps, t.positions, q]))


def write_tum(path_or_file: PathOrFile, trajectory: Trajectory) -> None:
    """Write ``t tx ty tz qx qy qz qw`` lines (planar trajectories at ``z = 0``; ``w ≥ 0``)."""
    _write(path_or_file, dumps_tum(trajectory))


def dumps_kitti(trajectory: Trajectory) -> str:
    """The text :func:`write_kitti` writes."""
    return _lines(trajectory.lift().poses.as_matrix()[:, :3, :].reshape(-1, 12))


def write_kitti(path_or_file: PathOrFile, trajectory: Trajectory) -> None:
    """Write the top 3 × 4 of each pose matrix, row-major (timestamps are dropped)."""
    _write(path_or_file, dumps_kitti(trajectory))


def to_pose_graph(trajectory: Trajectory, information: Any = None) -> PoseGraph:
    """The trajectory as a pose graph: its poses as vertex estimates (ids: the stamps when
    they are distinct integers, else ``0..n-1``) and one odometry edge ``(i, i+1)`` per step
    measuring ``X_i⁻¹ X_{i+1}``, with information ``information`` (``(k, k)``, default the
    identity) — what g2o needs to hold a trajectory."""
    x = trajectory.poses
    group = type(x)
    n = trajectory.n
    ids = np.arange(n, dtype=np.int64)
    stamps = trajectory.stamps
    if stamps is not None and np.array_equal(stamps, np.round(stamps)) and len(np.unique(stamps)) == n:
        ids = stamps.astype(np.int64)
    omega = np.eye(group.dim) if information is None else np.asarray(information, dtype=np.float64)
    if omega.shape != (group.dim, group.dim):
        raise ShapeError(f"information must have shape ({group.dim}, {group.dim}), got {omega.shape}")
    edges = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    measurements = x[edges[:, 0]].inverse() @ x[edges[:, 1]] if n > 1 else group.identity((0,))
    return PoseGraph(group, edges, measurements, np.broadcast_to(omega, (n - 1, *omega.shape)).copy(), ids=ids,
                     poses=x, name=trajectory.name)  # fmt: skip


def write_g2o(path_or_file: PathOrFile, trajectory: Trajectory, information: Any = None) -> None:
    """Write :func:`to_pose_graph` as a g2o file."""
    _write(path_or_file, g2o.dumps(to_pose_graph(trajectory, information)))
