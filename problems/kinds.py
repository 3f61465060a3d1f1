"""The problem kinds, by name, and how a graph read from a file becomes one of them.

The command line (``--problem``) and the benchmark catalogue (``problem = …``) turn a
graph into a problem through :func:`convert` and then only use the
:class:`~manopt_lie.problems.graph.Graph` interface: a new kind is a class plus one
entry here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from manopt_lie.lie.base import LieGroup

from . import rotation_averaging
from .graph import Graph
from .landmarks import LandmarkGraph
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging


@dataclass(frozen=True)
class Kind:
    """One problem kind.

    Attributes
    ----------
    name : str
        As the command line spells it (``"rotation-averaging"``).
    summary : str
        One line for help texts.
    graph : type
        The :class:`~manopt_lie.problems.graph.Graph` subclass; its ``costs`` are the
        costs the kind offers.
    bench_costs : tuple of str
        The costs a benchmark instance of this kind runs unless it says otherwise.
    from_graph : callable or None
        A graph of another kind → this kind (``None``: only graphs of this kind are).
    from_truth : callable
        The source's ground truth (e.g. a synthetic instance's poses) → this kind's variables.
    has_poses : bool
        Whether its graphs hold a pose graph (:meth:`~manopt_lie.problems.graph.Graph.pose_graph`),
        so that kinds made from a pose graph can be made from them.
    """

    name: str
    summary: str
    graph: type[Graph]
    bench_costs: tuple[str, ...]
    from_graph: Callable[[Graph], Graph] | None
    from_truth: Callable[[LieGroup], LieGroup]
    has_poses: bool = True


def _poses(graph: Graph) -> PoseGraph:
    return graph.pose_graph()


KINDS: dict[str, Kind] = {
    kind.name: kind
    for kind in (
        Kind(PoseGraph.kind, "SE(2)/SE(3) pose-graph optimization (of a landmark file: its poses only)",
             PoseGraph, ("chordal", "geodesic"), _poses, lambda x: x),
        Kind(RotationAveraging.kind, "rotation averaging of the graph's relative rotations (SO(2)/SO(3))",
             RotationAveraging, ("chordal",), lambda g: rotation_averaging.from_pose_graph(_poses(g)),
             lambda x: x.rotation(), has_poses=False),  # type: ignore[attr-defined]
        Kind(LandmarkGraph.kind, "poses, landmarks seen from them, and pose priors (landmark SLAM)",
             LandmarkGraph, ("geodesic",), None, lambda x: x),
    )
}  # fmt: skip
"""The problem kinds by the command line's ``--problem`` name: pose graphs, rotation
averaging and landmark SLAM, each with its costs and how a graph read from a file becomes one."""


def get_kind(name: str) -> Kind:
    """The kind called ``name``; an unknown name raises ``ValueError`` listing the choices."""
    if name not in KINDS:
        raise ValueError(f"problem must be one of {tuple(KINDS)}, got {name!r}")
    return KINDS[name]


def convertible(source: str, kind: str) -> bool:
    """Whether a graph of kind ``source`` can be solved as a ``kind`` problem."""
    return source == kind or (get_kind(source).has_poses and get_kind(kind).from_graph is not None)


def convert(graph: Graph, kind: str | None) -> Graph:
    """``graph`` as a problem of ``kind`` (``None``: as it is).

    Raises
    ------
    ValueError
        For an unknown kind, or one ``graph`` cannot be made into.
    """
    if kind is None or graph.kind == kind:
        return graph
    target = get_kind(kind)
    if target.from_graph is None:
        raise ValueError(f"{graph.name} is a {graph.kind} problem; it cannot be solved as a {kind} problem")
    return target.from_graph(graph)
