"""Applications built on the core of :mod:`manopt_lie`: pose-graph optimization, rotation
averaging, g2o I/O, synthetic benchmark instances and their catalogue.

Installed as ``manopt_lie.problems`` (the repository keeps it in the top-level folder
``problems/``). It imports only the core (``lie``, ``manifolds``, ``optim``, ``linalg``,
``casadi``).
"""

from . import checks, g2o, graph, kinds, landmarks, pose_graph, rotation_averaging, synthetic
from .checks import LintReport, lint
from .graph import Graph, MeasurementGraph
from .kinds import KINDS, get_kind
from .landmarks import LandmarkGraph
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging

__all__ = [
    "Graph",
    "MeasurementGraph",
    "LandmarkGraph",
    "PoseGraph",
    "RotationAveraging",
    "KINDS",
    "get_kind",
    "LintReport",
    "lint",
    "checks",
    "g2o",
    "graph",
    "kinds",
    "landmarks",
    "pose_graph",
    "rotation_averaging",
    "synthetic",
]
