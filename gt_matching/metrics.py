"""Closest-point error metrics of a detected lane against its ground truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gt_matching.polyline import NDArrayBool, NDArrayFloat


@dataclass(frozen=True)
class BorderMetrics:
    """Errors of one detected border (left or right) against its GT border.

    Every detected point counts in the statistics, matched or not.

    Fields:
        mean_error_m: mean closest-point distance, m. The paper calls this "mse_l"
            (eq. 1), but it is the mean of the distances, not of their squares.
        rmse_m: root mean square of the distances, m.
        max_error_m: largest distance, m.
        p95_error_m: 95th percentile of the distances (linear interpolation), m.
        points: number of detected points.
        unmatched_points: points that match no GT: farther than ``max_distance_m`` from
            the GT border or clearly closer to another border of the map.
        length_m: length of the detection along the GT border, from the projection of its
            first point to that of its last, m (the perception range).
    """

    mean_error_m: float
    rmse_m: float
    max_error_m: float
    p95_error_m: float
    points: int
    unmatched_points: int
    length_m: float

    @classmethod
    def from_distances(cls, distances: NDArrayFloat, unmatched: NDArrayBool, length_m: float) -> BorderMetrics:
        """Metrics of per-point distances (m) with their unmatched mask."""
        return cls(
            mean_error_m=float(np.mean(distances)),
            rmse_m=float(np.sqrt(np.mean(distances * distances))),
            max_error_m=float(np.max(distances)),
            p95_error_m=float(np.percentile(distances, 95.0)),
            points=int(distances.size),
            unmatched_points=int(np.count_nonzero(unmatched)),
            length_m=float(length_m),
        )


@dataclass(frozen=True)
class LaneMetrics:
    """Errors of one detected lane in one frame.

    Fields:
        left: metrics of the left border.
        right: metrics of the right border.
        lanelet_ids: ids of the GT lanelets in driving order (the route scored against).
        matched: False when the detection does not follow the sender's lane; the metrics
            are then against the sender's lane and show how far off the detection is.
        mismatch: why ``matched`` is False, else None.
        exact: True for point-to-segment distances to the GT polyline, False for
            distances to the GT resampled every ``step_m``.
        step_m: GT resampling distance, m.
    """

    left: BorderMetrics
    right: BorderMetrics
    lanelet_ids: tuple[int, ...]
    matched: bool
    mismatch: str | None
    exact: bool
    step_m: float
