"""Ground truth for detected lanes from Lanelet2 maps: lanelet matching at the sender's
pose, GT border assembly along the routing graph, resampling and closest-point error
metrics (paper sec. IV). Never imports ``cold_maps``; lanelet2 and scipy load lazily."""

from gt_matching.config import PAPER_STEP_M, MatchingConfig
from gt_matching.errors import MatchingError
from gt_matching.ground_truth import GroundTruth, evaluate_lane, ground_truth_for, match_lane
from gt_matching.lane_match import LaneMatch
from gt_matching.metrics import BorderErrors, BorderMetrics, LaneErrors, LaneMetrics

__all__ = [
    "PAPER_STEP_M",
    "BorderErrors",
    "BorderMetrics",
    "GroundTruth",
    "LaneErrors",
    "LaneMatch",
    "LaneMetrics",
    "MatchingConfig",
    "MatchingError",
    "evaluate_lane",
    "ground_truth_for",
    "match_lane",
]
