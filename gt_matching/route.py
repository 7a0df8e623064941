"""One continuous GT border assembled along a sequence of lanelets, resampled, and the
closest-point distances of detected points to it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np

from gt_matching.geometry import MapLines
from gt_matching.polyline import NDArrayBool, NDArrayFloat, NDArrayInt, arc_lengths, closest_distances, windowed_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Every this many GT samples seed the closest-point search (KD-tree).
GUESS_STRIDE: Final = 3
#: Spacing of the samples of nearby lines that bound their distance to the border, m.
CLEARANCE_STEP_M: Final = 0.5
#: Spacing along the border of the checkpoints whose clearance to other lines is kept, m.
CLEARANCE_SPACING_M: Final = 1.0


@dataclass(frozen=True)
class BorderDistances:
    """Closest-point distances of detected points to a GT border.

    Fields:
        distances: per point, m (exact, or to the GT resampled every ``step_m``).
        arc_m: per point, arc length of its closest GT point along the border, m.
        other_closer: per point, True when a border of another lane (not this GT border,
            not a lanelet overlapping the route; exact distance) is closer than the
            resampled GT border by more than the margin.
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
        parts: list[tuple[NDArrayFloat, NDArrayFloat]],
        ignored: set[int],
        step_m: float,
        reach_m: float,
    ) -> None:
        """``parts``: per lanelet in driving order, its border vertices and their samples
        every ``step_m`` (ends included), m; ``ignored``: line string ids that are never
        another lane's border (this border's own lines and those of lanelets overlapping
        the route); ``reach_m``: lines farther than this from the border are never closer
        than it for a point within ``reach_m / 2``."""
        from scipy.spatial import cKDTree

        self.step_m = step_m
        self.vertices: NDArrayFloat = np.concatenate([vertices for vertices, _ in parts])
        self.samples: NDArrayFloat = np.concatenate([samples for _, samples in parts])
        cum = arc_lengths(self.vertices)
        offsets = cum[np.cumsum([0] + [len(vertices) for vertices, _ in parts[:-1]])]
        self.sample_arc: NDArrayFloat = np.concatenate(
            [offset + np.minimum(np.arange(len(samples)) * step_m, arc_lengths(vertices)[-1])
             for offset, (vertices, samples) in zip(offsets, parts)]
        )
        guess = np.unique(np.append(np.arange(0, len(self.samples), GUESS_STRIDE), len(self.samples) - 1))
        self._guess_arc = self.sample_arc[guess]
        self._guess_tree = cKDTree(self.samples[guess])
        # The closest sample lies within half a guess gap (+ one step) of the guess's arc
        # length; joints between lanelets may repeat a sample.
        self._sample_reach_m = (GUESS_STRIDE / 2.0 + 1.0) * step_m
        self._window = int(2.0 * self._sample_reach_m / step_m) + 1 + len(parts)
        boxes = np.array([np.concatenate((v.min(axis=0), v.max(axis=0))) for v, _ in parts])
        near = lines.near(boxes, reach_m)
        self._lines = lines
        self._others: NDArrayInt = near[~np.isin(near, lines.slots(ignored))]
        last = len(self.samples) - 1
        spaced = np.searchsorted(self.sample_arc, np.arange(0.0, self.sample_arc[-1], CLEARANCE_SPACING_M))
        checkpoints = np.unique(np.append(np.minimum(spaced, last), last))
        self._checkpoint_arc = self.sample_arc[checkpoints]
        self._clearance = np.full(len(checkpoints), np.inf)
        self._coarse_owner: NDArrayInt = np.empty(0, dtype=np.int64)
        self._coarse_tree: cKDTree | None = None
        if len(self._others):
            coarse = [lines.samples(int(slot), CLEARANCE_STEP_M) for slot in self._others]
            self._coarse_owner = np.repeat(self._others, [len(c) for c in coarse])
            self._coarse_tree = cKDTree(np.concatenate(coarse), balanced_tree=False, compact_nodes=False)
            self._clearance = self._coarse_tree.query(self.samples[checkpoints])[0] - CLEARANCE_STEP_M / 2.0

    def _other_closer(self, points: NDArrayFloat, limits: NDArrayFloat) -> NDArrayBool:
        """Whether another line comes closer to each point than its limit (m): a lower
        bound from the coarse samples first, then exact distances to the lines near the
        few points it cannot rule out."""
        closer = np.zeros(len(points), dtype=bool)
        if self._coarse_tree is None:
            return closer
        coarse_distance = self._coarse_tree.query(points)[0]
        for i in np.flatnonzero(coarse_distance - CLEARANCE_STEP_M / 2.0 < limits):
            near = self._coarse_tree.query_ball_point(points[i], limits[i] + CLEARANCE_STEP_M / 2.0)
            for slot in np.unique(self._coarse_owner[near]):
                if closest_distances(points[i : i + 1], self._lines.vertices[int(slot)])[0][0] < limits[i]:
                    closer[i] = True
                    break
        return closer

    def distances(self, points: NDArrayFloat, *, exact: bool, other_margin_m: float) -> BorderDistances:
        """Closest-point distances of ``points`` (world frame, m) to this border.

        The nearest of every ``GUESS_STRIDE``-th sample (KD-tree) seeds both searches: the
        resampled distance is the smallest to the samples around its arc length, the exact
        one the smallest to the segments within one guess gap of it. Both equal a global
        search wherever the border's radius of curvature exceeds the distance. Only points far
        enough off the border to possibly be closer to another line (by the clearance of
        the nearest checkpoint: distance to another line >= clearance - distance to the
        checkpoint) are checked against the other lines.
        """
        _, guess = self._guess_tree.query(points)
        guess_arc = self._guess_arc[guess]
        first = np.searchsorted(self.sample_arc, guess_arc - self._sample_reach_m)
        around = np.minimum(first[:, None] + np.arange(self._window), len(self.samples) - 1)
        gaps = self.samples[around] - points[:, None, :]
        sample_distances = np.hypot(gaps[..., 0], gaps[..., 1])
        closest = np.argmin(sample_distances, axis=1)
        rows = np.arange(len(points))
        resampled = sample_distances[rows, closest]
        other_closer = np.zeros(len(points), dtype=bool)
        after = np.minimum(np.searchsorted(self._checkpoint_arc, guess_arc), len(self._clearance) - 1)
        clearance = np.minimum(self._clearance[after], self._clearance[np.maximum(after - 1, 0)])
        slack = GUESS_STRIDE * self.step_m + CLEARANCE_SPACING_M
        suspect = 2.0 * resampled > clearance + other_margin_m - slack
        if np.any(suspect):
            other_closer[suspect] = self._other_closer(points[suspect], resampled[suspect] - other_margin_m)
        if exact:
            exact_distance, arc = windowed_distances(points, self.vertices, guess_arc, GUESS_STRIDE * self.step_m)
            return BorderDistances(distances=exact_distance, arc_m=arc, other_closer=other_closer)
        return BorderDistances(
            distances=resampled, arc_m=self.sample_arc[around[rows, closest]], other_closer=other_closer
        )
