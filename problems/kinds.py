"""The problem kinds a g2o pose graph can be read as, by name.

The command line (``--problem``) and the benchmark catalogue (``problem = …``) turn a
pose graph into a problem through this table and then only use the
:class:`~manopt_lie.problems.graph.MeasurementGraph` interface: a new kind is a class
plus one entry here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from manopt_lie.lie.base import LieGroup

from . import rotation_averaging
from .graph import MeasurementGraph
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging


@dataclass(frozen=True)
class Kind:
    """How to make one problem kind from a pose graph.

    Attributes
    ----------
    name : str
        As the command line spells it (``"rotation-averaging"``).
    summary : str
        One line for help texts.
    graph : type
        The :class:`~manopt_lie.problems.graph.MeasurementGraph` subclass; its ``costs``
        are the costs the kind offers.
    bench_costs : tuple of str
        The costs a benchmark instance of this kind runs unless it says otherwise.
    from_pose_graph : callable
        ``PoseGraph → MeasurementGraph``.
    from_poses : callable
        Poses of the pose graph (e.g. a synthetic ground truth) → this kind's variables.
    """

    name: str
    summary: str
    graph: type[MeasurementGraph]
    bench_costs: tuple[str, ...]
    from_pose_graph: Callable[[PoseGraph], MeasurementGraph]
    from_poses: Callable[[LieGroup], LieGroup]


KINDS: dict[str, Kind] = {
    kind.name: kind
    for kind in (
        Kind(PoseGraph.kind, "SE(2)/SE(3) pose-graph optimization", PoseGraph, ("chordal", "geodesic"),
             lambda g: g, lambda x: x),
        Kind(RotationAveraging.kind, "rotation averaging of the graph's relative rotations (SO(2)/SO(3))",
             RotationAveraging, ("chordal",), rotation_averaging.from_pose_graph,
             lambda x: x.rotation()),  # type: ignore[attr-defined]
    )
}  # fmt: skip


def get_kind(name: str) -> Kind:
    """The kind called ``name``; an unknown name raises ``ValueError`` listing the choices."""
    if name not in KINDS:
        raise ValueError(f"problem must be one of {tuple(KINDS)}, got {name!r}")
    return KINDS[name]
