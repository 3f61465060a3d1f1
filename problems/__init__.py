"""Applications built on :mod:`manopt_lie`: pose-graph optimization, rotation
averaging, g2o I/O and synthetic benchmark instances."""

from . import g2o, pose_graph, rotation_averaging, synthetic
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging

__all__ = ["PoseGraph", "RotationAveraging", "g2o", "pose_graph", "rotation_averaging", "synthetic"]
