"""Closest-point errors of a detected lane against its ground truth: per point, and
summarised per border."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from gt_matching.lane_match import LaneMatch
from gt_matching.polyline import NDArrayBool, NDArrayFloat

#: The percentile reported as ``p95_error_m``.
P95: Final = 95.0


def _percentile(values: NDArrayFloat, percent: float) -> float:
    """``np.percentile(values, percent)`` (linear interpolation) by partial sorting."""
    position = percent / 100.0 * (len(values) - 1)
    below = int(np.floor(position))
    above = min(below + 1, len(values) - 1)
    low, high = np.partition(values, (below, above))[[below, above]]
    return float(low + (high - low) * (position - below))


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
            p95_error_m=_percentile(distances, P95),
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


@dataclass(frozen=True)
class BorderErrors:
    """Per-point errors of one detected border against its GT border.

    Fields:
        distances_m: ``(N,)`` closest-point distance of each detected point, m.
        arc_m: ``(N,)`` arc length along the GT border of each point's closest GT point, m.
        unmatched: ``(N,)`` True where the point matches no GT (see
            ``BorderMetrics.unmatched_points``).
    """

    distances_m: NDArrayFloat
    arc_m: NDArrayFloat
    unmatched: NDArrayBool

    def metrics(self) -> BorderMetrics:
        """The summary statistics; the length runs from the first point to the last."""
        return BorderMetrics.from_distances(self.distances_m, self.unmatched, float(self.arc_m[-1] - self.arc_m[0]))


@dataclass(frozen=True)
class LaneErrors:
    """Per-point errors of one detected lane in one frame.

    Fields:
        left, right: errors of the left and right border.
        match: the ground truth the errors are against.
        exact: True for point-to-segment distances to the GT polyline, False for
            distances to the GT resampled every ``step_m``.
        step_m: GT resampling distance, m.
    """

    left: BorderErrors
    right: BorderErrors
    match: LaneMatch
    exact: bool
    step_m: float

    def metrics(self) -> LaneMetrics:
        """Summary statistics per border, with the match verdict."""
        return LaneMetrics(
            left=self.left.metrics(),
            right=self.right.metrics(),
            lanelet_ids=self.match.lanelet_ids,
            matched=self.match.matched,
            mismatch=self.match.mismatch,
            exact=self.exact,
            step_m=self.step_m,
        )


@dataclass(frozen=True)
class Calibration:
    """How honest a lane's stated uncertainty is: its points' errors against their stated σ.

    Fields:
        points: error samples with a stated σ.
        within_1sigma, within_2sigma: share of them whose error is at most 1σ / 2σ of their
            stated lateral σ (68.3 % / 95.4 % for calibrated Gaussian errors; a closest-point
            distance is the absolute lateral error).
        mean_sigma_m: mean stated σ, m.
        mean_error_m: mean error of the same points, m.
    """

    points: int
    within_1sigma: float
    within_2sigma: float
    mean_sigma_m: float
    mean_error_m: float

    @classmethod
    def from_errors(cls, distances_m: NDArrayFloat, sigmas_m: NDArrayFloat) -> Calibration:
        """Calibration of per-point distances (m) against their stated 1σ (m), same shape, not empty."""
        if distances_m.shape != sigmas_m.shape or distances_m.size == 0:
            raise ValueError(f"calibration needs as many σ as errors, at least one: got {sigmas_m.shape} σ "
                             f"for {distances_m.shape} errors")
        return cls(points=int(distances_m.size),
                   within_1sigma=float(np.mean(distances_m <= sigmas_m)),
                   within_2sigma=float(np.mean(distances_m <= 2.0 * sigmas_m)),
                   mean_sigma_m=float(np.mean(sigmas_m)), mean_error_m=float(np.mean(distances_m)))
