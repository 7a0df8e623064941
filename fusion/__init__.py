"""CoLD fusion: collective lane detection from an ego and a cooperative vehicle.

Implements sec. III of the CoLD Fusion paper on numpy arrays (numpy and scipy only):
convoy fusion of overlapping detections, spline fusion across a gap (the paper's natural
spline with apex estimation, or a G1 Hermite variant), the fusibility check, and the
Bézier exchange format (:mod:`fusion.bezier`). Frames: world = OpenDRIVE inertial frame,
vehicle = ISO 8855. See :func:`fuse`.
"""

from fusion import bezier
from fusion.api import DEFAULT_PARAMS, fuse, is_fusible
from fusion.errors import BezierDecodeError, FusionError, InvalidDetectionError, InvalidParameterError
from fusion.chain import ChainLink, ChainResult, fuse_chain
from fusion.history import fuse_history
from fusion.types import (FusionParams, FusionResult, LaneBranch, LaneDetection, LaneHistory, NDArrayFloat,
                          NDArrayInt8, NeighbourLane, Pose2D, RoadEdges, Source)

__all__ = [
    "DEFAULT_PARAMS", "bezier", "BezierDecodeError", "ChainLink", "ChainResult", "FusionError", "FusionParams",
    "FusionResult", "InvalidDetectionError", "InvalidParameterError", "LaneBranch", "LaneDetection", "LaneHistory",
    "NDArrayFloat", "NDArrayInt8", "NeighbourLane", "Pose2D", "RoadEdges", "Source", "fuse", "fuse_chain",
    "fuse_history", "is_fusible",
]
