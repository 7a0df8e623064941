"""One continuous GT border assembled along a sequence of lanelets, resampled, and the
closest-point distances of detected points to it."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Final

import numpy as np

from gt_matching.geometry import MapLines
from gt_matching.polyline import NDArrayBool, NDArrayFloat, NDArrayInt, arc_lengths, resample, windowed_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Spacing of the coarse border samples that seed each point's closest-point search, m.
GUESS_STEP_M: Final = 0.05
#: The closest resampled point lies within this arc length of the nearest coarse sample
#: (half a coarse step, plus slack), m.
SAMPLE_REACH_M: Final = GUESS_STEP_M / 2.0
#: Spacing of the samples of nearby lines that bound their distance to the border, m.
CLEARANCE_STEP_M: Final = 0.25


@dataclass(frozen=True)
class BorderDistances:
    """Closest-point distances of detected points to a GT border.

    Fields:
        distances: per point, m (exact, or to the GT resampled every ``step_m``).
        arc_m: per point, arc length of its closest GT point along the border, m.
        other_closer: per point, True when a border of another lane (not this GT border,
            not a lanelet overlapping the route) is closer than the resampled GT border by
            more than the margin (distances to samples every ``step_m``).
    """

    distances: NDArrayFloat
    arc_m: NDArrayFloat
    other_closer: NDArrayBool


class RouteBorder:
    """The left or right GT border of a lanelet sequence (the lanelets' borders joined in
    driving order) and its samples every ``step_m``, with what is needed to find each
    detected point's closest GT point and whether another lane's border is closer."""

    def __init__(
        self,
        lines: MapLines,
        parts: list[NDArrayFloat],
        ignored: set[int],
        step_m: float,
        reach_m: float,
    ) -> None:
        """``parts``: border vertices per lanelet in driving order, m; ``ignored``: line
        string ids that are never another lane's border (this border's own lines and
        those of lanelets overlapping the route); ``reach_m``: lines farther than this from
        the border are never closer than it for a point within ``reach_m / 2``."""
        from scipy.spatial import cKDTree

        self.step_m = step_m
        self.vertices: NDArrayFloat = np.concatenate(parts)
        self.samples, segment = resample(self.vertices, step_m)
        self._window = int(np.ceil(2.0 * (SAMPLE_REACH_M + step_m) / step_m)) + 1
        cum = arc_lengths(self.vertices)
        self.sample_arc: NDArrayFloat = cum[segment] + np.hypot(*(self.samples - self.vertices[segment]).T)
        guess, segment = resample(self.vertices, GUESS_STEP_M)
        self._guess_arc = cum[segment] + np.hypot(*(guess - self.vertices[segment]).T)
        self._guess_tree = cKDTree(guess)
        boxes = np.array([np.concatenate((p.min(axis=0), p.max(axis=0))) for p in parts])
        near = lines.near(boxes, reach_m)
        self._lines = lines
        self._others: NDArrayInt = near[~np.isin(near, lines.slots(ignored))]
        self._clearance = np.full(len(guess), np.inf)
        if len(self._others):
            coarse = np.concatenate([lines.samples(int(slot), CLEARANCE_STEP_M) for slot in self._others])
            self._clearance = cKDTree(coarse).query(guess)[0] - CLEARANCE_STEP_M / 2.0

    @cached_property
    def _others_tree(self) -> cKDTree:
        """KD-tree of the other lines' samples every ``step_m``, built on first use."""
        from scipy.spatial import cKDTree

        return cKDTree(np.concatenate([self._lines.samples(int(slot), self.step_m) for slot in self._others]))

    def distances(self, points: NDArrayFloat, *, exact: bool, other_margin_m: float) -> BorderDistances:
        """Closest-point distances of ``points`` (world frame, m) to this border.

        The nearest coarse sample (KD-tree) seeds both searches: the resampled distance is
        the smallest to the samples within ``SAMPLE_REACH_M`` of its arc length, the exact
        one the smallest to the segments within ``GUESS_STEP_M``. Both equal a global search
        wherever the border's radius of curvature exceeds the distance. Only points far
        enough off the border to possibly be closer to another line (by the clearance of
        the coarse sample) are checked against the other lines.
        """
        _, guess = self._guess_tree.query(points)
        guess_arc = self._guess_arc[guess]
        first = np.floor((guess_arc - SAMPLE_REACH_M - self.step_m) / self.step_m).astype(np.int64)
        around = np.clip(first[:, None] + np.arange(self._window), 0, len(self.samples) - 1)
        gaps = self.samples[around] - points[:, None, :]
        sample_distances = np.hypot(gaps[..., 0], gaps[..., 1])
        closest = np.argmin(sample_distances, axis=1)
        rows = np.arange(len(points))
        resampled = sample_distances[rows, closest]
        other_closer = np.zeros(len(points), dtype=bool)
        suspect = 2.0 * resampled > self._clearance[guess] + other_margin_m - GUESS_STEP_M / 2.0
        if np.any(suspect):
            other = self._others_tree.query(points[suspect])[0]
            other_closer[suspect] = other < resampled[suspect] - other_margin_m
        if exact:
            exact_distance, arc = windowed_distances(points, self.vertices, guess_arc, GUESS_STEP_M)
            return BorderDistances(distances=exact_distance, arc_m=arc, other_closer=other_closer)
        return BorderDistances(
            distances=resampled, arc_m=self.sample_arc[around[rows, closest]], other_closer=other_closer
        )
