"""The ground truth found for one detected lane: its lanelets and their borders."""

from __future__ import annotations

from dataclasses import dataclass

from gt_matching.geometry import LaneletKey
from gt_matching.polyline import NDArrayFloat


@dataclass(frozen=True)
class LaneMatch:
    """The ground truth found for one detected lane.

    Fields:
        lanelet_ids: GT lanelets in driving order; their borders cover the detection plus
            ``margin_m`` on both ends where the map allows.
        route_key: (lanelet id, inverted) per GT lanelet: the key of the assembled borders.
        left_gt: GT left border, ``(M, 2)`` world frame, m, in driving order.
        right_gt: GT right border, ``(K, 2)`` world frame, m, in driving order.
        left_gt_samples, right_gt_samples: each GT lanelet's border resampled every
            ``step_m`` (ends included), joined: spacing <= ``step_m``, m; the points
            closest-point errors are measured to.
        pose_lanelet_ids: lanelets the sender's pose is on (several when ambiguous).
        matched: False when the detection does not follow the sender's lane; the GT is
            then the sender's lane that fits the detection best.
        mismatch: why ``matched`` is False, else None.
    """

    lanelet_ids: tuple[int, ...]
    route_key: tuple[LaneletKey, ...]
    left_gt: NDArrayFloat
    right_gt: NDArrayFloat
    left_gt_samples: NDArrayFloat
    right_gt_samples: NDArrayFloat
    pose_lanelet_ids: tuple[int, ...]
    matched: bool
    mismatch: str | None
