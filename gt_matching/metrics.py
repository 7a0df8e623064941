"""Closest-point errors of a detected lane against its ground truth: per point, and
summarised per border."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from gt_matching.lane_match import LaneMatch
from gt_matching.polyline import NDArrayBool, NDArrayFloat

#: The percentile reported as ``p95_error_m``.
P95: Final = 95.0
#: Points up to this distance from the ego are *near*, beyond it *far* (m): OpenLane's
#: split of its near / far errors (its evaluation scores 0-40 m and 40-100 m ahead apart).
NEAR_FAR_SPLIT_M: Final = 40.0


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
class ErrorStats:
    """Pooled statistics of closest-point distances.

    Fields:
        points: number of distances.
        mean_error_m, max_error_m, p95_error_m: their mean, maximum and 95th percentile
            (linear interpolation), m; NaN when ``points`` is 0.
    """

    points: int
    mean_error_m: float
    max_error_m: float
    p95_error_m: float

    @classmethod
    def of(cls, distances_m: NDArrayFloat) -> ErrorStats:
        """The statistics of ``distances_m`` (1-D, m)."""
        if not distances_m.size:
            return cls(0, math.nan, math.nan, math.nan)
        return cls(int(distances_m.size), float(np.mean(distances_m)), float(np.max(distances_m)),
                   _percentile(distances_m, P95))


def near_count(ahead_m: NDArrayFloat, split_m: float = NEAR_FAR_SPLIT_M) -> int:
    """How many leading points of a border lie within ``split_m`` of the ego: ``ahead_m``
    (``(N,)``, m, non-decreasing) is each point's distance from the ego along the border;
    the points up to the count are near (<= ``split_m``), the rest far."""
    return int(np.searchsorted(ahead_m, split_m, side="right"))


def known_distance_m(distances_m: NDArrayFloat, ahead_m: NDArrayFloat, threshold_m: float) -> float:
    """How far from the ego a border is known within ``threshold_m``: the distance along it
    (``ahead_m``, m, from the ego, non-decreasing) of the last point before the first whose
    error (``distances_m``, m) exceeds ``threshold_m``; of its last point when none does;
    0 when its first point does or it has none. So the result is >= D (> 0) exactly when
    the border has a point at D or beyond and every point up to the first such point is within
    the threshold (the stretch between two points counts only when both are)."""
    if distances_m.shape != ahead_m.shape:
        raise ValueError(f"known_distance_m: {distances_m.shape} errors but {ahead_m.shape} distances")
    bad = np.flatnonzero(distances_m > threshold_m)
    last = int(bad[0]) - 1 if bad.size else distances_m.size - 1
    return float(ahead_m[last]) if last >= 0 else 0.0


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
