"""Applications built on the core of :mod:`manopt_lie`: pose-graph optimization, rotation
averaging, g2o I/O, synthetic benchmark instances and their catalogue.

Installed as ``manopt_lie.problems`` (the repository keeps it in the top-level folder
``problems/``). It imports only the core (``lie``, ``manifolds``, ``optim``, ``linalg``,
``casadi``).
"""

from . import checks, g2o, graph, kinds, pose_graph, rotation_averaging, synthetic
from .checks import LintReport, lint
from .graph import MeasurementGraph
from .kinds import KINDS, get_kind
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging

__all__ = [
    "MeasurementGraph",
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
    "pose_graph",
    "rotation_averaging",
    "synthetic",
]
