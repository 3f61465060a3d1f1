"""Writing g2o files: :func:`write`, :func:`dumps` (exact numbers, a fixed point of write ∘ read)."""

from __future__ import annotations

import io
import os
from typing import IO, Any

import numpy as np

from manopt_lie.atomic import atomic_write

from ..graph import MeasurementGraph
from ..landmarks import LandmarkGraph
from ..pose_graph import PoseGraph
from ._format import edge_lines, fix_line, vertex_lines
from ._landmark_writer import landmark_text

__all__ = ["write", "dumps"]


def write(
    path_or_file: str | os.PathLike[str] | IO[str], graph: PoseGraph | LandmarkGraph, estimates: Any = None
) -> None:
    """Write ``graph`` as a g2o file.

    A :class:`PoseGraph` is written as ``VERTEX`` lines, one ``FIX`` line and ``EDGE``
    lines; a :class:`LandmarkGraph` as ``PARAMS_SE3OFFSET`` lines (3-D), the pose and the
    landmark ``VERTEX`` lines, ``FIX``, the pose ``EDGE`` lines, the observations and the
    priors (the package docstring has the tags).

    Parameters
    ----------
    path_or_file : path or text file object
    graph : PoseGraph or LandmarkGraph
    estimates : optional
        The vertex estimates to write. For a pose graph, poses (batch ``(n,)``), default
        ``graph.poses``; without any, only the edges (and ``FIX``) are written, which needs
        every vertex to have an edge. For a landmark graph, a
        :class:`~manopt_lie.manifolds.Values` ``(poses, landmarks)`` as
        :meth:`LandmarkGraph.initialize` or an optimizer return it; default the graph's
        own (``graph.poses.poses`` and ``graph.landmarks``, each written if present).

    Notes
    -----
    Vertices are written in increasing id order, with ``graph.ids`` (and
    ``graph.landmark_ids``); information matrices as their upper triangle (symmetric ones
    exactly). Numbers are written as ``repr(float)``, which reads back to the same float,
    so translations, points and information matrices survive :func:`read` exactly.
    Rotations are written as the angle ``atan2(R₁₀, R₀₀)`` (on a 2⁻⁵² grid) or a unit
    quaternion with ``w ≥ 0`` (on that grid), chosen so that ``write(read(write(graph)))``
    and ``write(graph)`` are the same text. Read back, a rotation matrix entry moves by
    ~1e-16 (SE2) or at most a few 1e-15 (SE3: the quaternion ↔ matrix conversions alone move
    entries by up to ~1.5e-15).

    A path is written atomically (:func:`manopt_lie.atomic.atomic_write`): whole, or not
    at all.
    """
    text = dumps(graph, estimates)
    if isinstance(path_or_file, str | os.PathLike):
        with atomic_write(path_or_file, encoding="utf-8", newline="\n") as f:
            f.write(text)
    else:
        path_or_file.write(text)


def dumps(graph: PoseGraph | LandmarkGraph, estimates: Any = None) -> str:
    """The text :func:`write` writes."""
    if not isinstance(graph, MeasurementGraph):  # poses and landmarks
        return landmark_text(graph, estimates)
    out = io.StringIO()
    poses = graph.poses if estimates is None else estimates
    if poses is not None:
        vertex_lines(out, graph, poses)
    else:
        lonely = np.setdiff1d(graph.ids, graph.ids[graph.edges])
        if lonely.size:
            raise ValueError(
                f"{graph.name}: vertices {lonely[:10].tolist()} have no edge and no pose; g2o needs poses to write them"
            )
    fix_line(out, graph)
    edge_lines(out, graph)
    return out.getvalue()
