"""One continuous GT border assembled along a sequence of lanelets, resampled, and the
closest-point distances of detected points to it."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Final

import numpy as np

from gt_matching.geometry import COARSE_STEP_M, MapLines
from gt_matching.polyline import NDArrayBool, NDArrayFloat, NDArrayInt, arc_lengths, resample, windowed_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Every this many GT samples seed the closest-point search (KD-tree).
GUESS_STRIDE: Final = 3
#: Every this many detected points look up their nearest coarse sample; the others
#: interpolate its arc length along the detection.
ANCHOR_STRIDE: Final = 10
#: Arc length either side of an interpolated seed searched for the nearest sample, m.
ANCHOR_REACH_M: Final = 0.1
#: Points farther than this from the border are searched globally (KD-tree), m.
REFINE_DISTANCE_M: Final = 1.0
#: A border vertex turning by more than this is a kink: points whose nearest sample lies
#: near one are searched globally (a second minimum may start there), rad.
KINK_RAD: Final = 0.02
#: Spacing along the border of the points around which other lines are looked up, m.
LOOKOUT_SPACING_M: Final = 5.0
#: Spacing along the border of the checkpoints whose clearance to other lines is kept, m.
CLEARANCE_SPACING_M: Final = 0.25


def _kinks(vertices: NDArrayFloat) -> NDArrayBool:
    """Per interior vertex, whether the polyline turns there by more than ``KINK_RAD``
    (a zero-length segment next to it counts as a kink)."""
    ahead = np.diff(vertices, axis=0)
    before, after = ahead[:-1], ahead[1:]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = np.einsum("ij,ij->i", before, after)
    degenerate = (np.hypot(*before.T) == 0.0) | (np.hypot(*after.T) == 0.0)
    return degenerate | (np.abs(np.arctan2(cross, dot)) > KINK_RAD)


@dataclass(frozen=True)
class BorderDistances:
    """Closest-point distances of detected points to a GT border.

    Fields:
        distances: per point, m (exact, or to the GT resampled every ``step_m``).
        arc_m: per point, arc length of its closest GT point along the border, m.
        other_closer: per point, True when a border of another lane (not this GT border,
            not a lanelet overlapping the route) is closer than this GT border by more than
            the margin (both resampled every ``step_m``).
    """

    distances: NDArrayFloat
    arc_m: NDArrayFloat
    other_closer: NDArrayBool


@dataclass(frozen=True, eq=False)
class BorderPart:
    """One lanelet's left or right border in driving order, prepared once per map.

    Fields:
        vertices: ``(N, 2)`` vertices, world frame, m.
        samples: points every ``step_m`` along it, ends included, m.
        sample_arc_m: arc length of each sample, m.
    """

    vertices: NDArrayFloat
    samples: NDArrayFloat
    sample_arc_m: NDArrayFloat

    @classmethod
    def of(cls, vertices: NDArrayFloat, step_m: float) -> BorderPart:
        """Samples of a border polyline (m) every ``step_m``."""
        samples, _ = resample(vertices, step_m)
        return cls(
            vertices=vertices,
            samples=samples,
            sample_arc_m=np.minimum(np.arange(len(samples)) * step_m, arc_lengths(vertices)[-1]),
        )


class RouteBorder:
    """The left or right GT border of a lanelet sequence (the lanelets' borders joined in
    driving order) and its samples every ``step_m``, with what is needed to find each
    detected point's closest GT point and whether another lane's border is closer."""

    def __init__(
        self,
        lines: MapLines,
        parts: list[BorderPart],
        ignored: set[int],
        step_m: float,
        reach_m: float,
        other_margin_m: float,
    ) -> None:
        """``parts``: the lanelets' borders in driving order, sampled every ``step_m``;
        ``ignored``: line string ids that are never another lane's border (this border's
        own lines and those of lanelets overlapping the route); ``reach_m``: lines farther
        than this from the border are never closer than it for a point within
        ``reach_m / 2``; ``other_margin_m``: how much closer another lane's border must be
        for a point to count as unmatched."""
        from scipy.spatial import cKDTree

        self.step_m = step_m
        self.other_margin_m = other_margin_m
        self.vertices: NDArrayFloat = np.concatenate([part.vertices for part in parts])
        self.samples: NDArrayFloat = np.concatenate([part.samples for part in parts])
        cum = arc_lengths(self.vertices)
        arc_offsets = cum[np.cumsum([0] + [len(part.vertices) for part in parts[:-1]])]
        self.sample_arc: NDArrayFloat = np.concatenate(
            [offset + part.sample_arc_m for offset, part in zip(arc_offsets, parts)]
        )
        self._break_arc = np.sort(np.concatenate((arc_offsets[1:], cum[1:-1][_kinks(self.vertices)])))
        guess = np.arange(0, len(self.samples) + GUESS_STRIDE - 1, GUESS_STRIDE)
        guess[-1] = len(self.samples) - 1
        self._guess_arc = self.sample_arc[guess]
        self._guess_tree = cKDTree(self.samples[guess])
        self._complex_samples = self.samples[:, 0] + 1j * self.samples[:, 1]
        # A window may hold a repeated sample where two lanelets join.
        self._joints = min(len(parts), 2)
        self._lines = lines
        last = len(self.samples) - 1
        spaced = np.searchsorted(self.sample_arc, np.arange(0.0, self.sample_arc[-1], CLEARANCE_SPACING_M))
        checkpoints = np.unique(np.append(np.minimum(spaced, last), last))
        self._checkpoint_arc = self.sample_arc[checkpoints]
        self._clearance = np.full(len(checkpoints), np.inf)
        self._coarse_owner: NDArrayInt = np.empty(0, dtype=np.int64)
        self._coarse_tree: cKDTree | None = None
        lookouts = np.searchsorted(self.sample_arc, np.arange(0.0, self.sample_arc[-1], LOOKOUT_SPACING_M))
        lookouts = self.samples[np.append(np.minimum(lookouts, last), last)]
        near = lines.coarse_near(lookouts, reach_m + COARSE_STEP_M + LOOKOUT_SPACING_M / 2.0)
        near = near[~np.isin(lines.coarse_owner[near], lines.slots(ignored))]
        if len(near):
            # Samples of other lines farther than the reach never matter; those this close
            # to the border (e.g. a neighbour's border drawn on top of this one) can never
            # be closer than it by the margin: d(p, o) >= d(p, border) - coincidence and
            # d_resampled <= d + step / 2.
            coincident = (other_margin_m - step_m / 2.0) / 2.0
            gap = self._guess_tree.query(lines.coarse[near], distance_upper_bound=reach_m + COARSE_STEP_M)[0]
            near = near[(gap > coincident) & np.isfinite(gap)]
        if len(near):
            self._coarse_owner = lines.coarse_owner[near]
            self._coarse_tree = cKDTree(lines.coarse[near])
            self._clearance = self._coarse_tree.query(self.samples[checkpoints])[0] - COARSE_STEP_M / 2.0

    @cached_property
    def _fine_tree(self) -> cKDTree:
        """KD-tree of all samples, built on first use (points the windows cannot settle)."""
        from scipy.spatial import cKDTree

        return cKDTree(self.samples)

    def _seed_arc(self, points: NDArrayFloat) -> NDArrayFloat:
        """Arc length (m) of each point's nearest coarse sample."""
        arc: NDArrayFloat = self._guess_arc[self._guess_tree.query(points)[1]]
        return arc

    def _other_closer(self, points: NDArrayFloat, limits: NDArrayFloat) -> NDArrayBool:
        """Whether another line's samples every ``step_m`` come closer to each point than
        its limit (m): a lower bound from the coarse samples first, then the KD-trees of
        the few lines near the points it cannot rule out."""
        closer = np.zeros(len(points), dtype=bool)
        if self._coarse_tree is None:
            return closer
        half = COARSE_STEP_M / 2.0
        open_ = np.flatnonzero(self._coarse_tree.query(points)[0] - half < limits)
        if len(open_) == 0:
            return closer
        near = self._coarse_tree.query_ball_point(points[open_], limits[open_] + half)
        for slot in np.unique(self._coarse_owner[np.concatenate([np.asarray(n, dtype=np.int64) for n in near])]):
            distances = self._lines.tree(int(slot), self.step_m).query(points[open_])[0]
            closer[open_] |= distances < limits[open_]
        return closer

    def _nearest_samples(
        self, points: NDArrayFloat, seed_arc: NDArrayFloat, reach_m: float
    ) -> tuple[NDArrayFloat, NDArrayInt, NDArrayBool]:
        """Per point, the smallest distance (m) to the samples within ``reach_m`` of arc
        length ``seed_arc``, that sample's index, and whether the window settles it: the
        minimum is not on its edge (it may continue outside), and no kink or lanelet joint
        lies within twice the distance (+ a step) of it, where another minimum may start
        (any closer sample lies within twice the distance of the one found)."""
        last = len(self.samples) - 1
        width = int(2.0 * reach_m / self.step_m) + 1 + self._joints
        first = np.searchsorted(self.sample_arc, seed_arc - reach_m)
        around = np.minimum(first[:, None] + np.arange(width), last)
        sample_distances = np.abs(self._complex_samples[around] - (points[:, 0] + 1j * points[:, 1])[:, None])
        closest = np.argmin(sample_distances, axis=1)
        rows = np.arange(len(points))
        inside = ((closest > 0) | (first == 0)) & ((closest < width - 1) | (around[:, -1] == last))
        distance, sample = sample_distances[rows, closest], around[rows, closest]
        arc, reach = self.sample_arc[sample], 2.0 * distance + self.step_m
        breaks = self._break_arc
        smooth = np.searchsorted(breaks, arc - reach) == np.searchsorted(breaks, arc + reach, side="right")
        return distance, sample, inside & smooth

    def distances(self, points: NDArrayFloat, *, exact: bool) -> BorderDistances:
        """Closest-point distances of ``points`` (world frame, m, in driving order) to this
        border.

        Every ``ANCHOR_STRIDE``-th point finds its nearest coarse sample (KD-tree over every
        ``GUESS_STRIDE``-th sample); the arc lengths of the points between are interpolated
        along the detection, and each point takes the nearest sample within
        ``ANCHOR_REACH_M`` of that. Where that window cannot settle it (minimum on its
        edge, a kink or lanelet joint near it, or the point farther than
        ``REFINE_DISTANCE_M``) a KD-tree over all samples answers. The exact distance is the
        smallest to the segments within two steps of the nearest sample (twice the
        distance for the points the KD-tree answered). Only points far enough off the
        border to possibly be closer to another line (by the clearance of the checkpoints
        around the nearest sample) are checked against the other lines.
        """
        anchors = np.arange(0, len(points) + ANCHOR_STRIDE - 1, ANCHOR_STRIDE)
        anchors[-1] = len(points) - 1
        along = arc_lengths(points)
        seed = np.interp(along, along[anchors], self._seed_arc(points[anchors]))
        resampled, sample, inside = self._nearest_samples(points, seed, ANCHOR_REACH_M)
        redo = np.flatnonzero(~inside | (resampled > REFINE_DISTANCE_M))
        if len(redo):
            resampled[redo], sample[redo] = self._fine_tree.query(points[redo])
        arc = self.sample_arc[sample]
        after = np.minimum(np.searchsorted(self._checkpoint_arc, arc), len(self._clearance) - 1)
        clearance = np.minimum(self._clearance[after], self._clearance[np.maximum(after - 1, 0)])
        suspect = 2.0 * resampled > clearance + self.other_margin_m - (self.step_m + CLEARANCE_SPACING_M)
        other_closer = np.zeros(len(points), dtype=bool)
        if np.any(suspect):
            other_closer[suspect] = self._other_closer(points[suspect], resampled[suspect] - self.other_margin_m)
        if exact:
            exact_distance, exact_arc = windowed_distances(points, self.vertices, arc, 2.0 * self.step_m)
            if len(redo):
                # The closest GT point is within the sample's distance of the point, so
                # within twice that of the sample (along a border, arc ~ chord).
                reach = 2.0 * float(np.max(resampled[redo])) + 2.0 * self.step_m
                exact_distance[redo], exact_arc[redo] = windowed_distances(points[redo], self.vertices, arc[redo], reach)
            return BorderDistances(distances=exact_distance, arc_m=exact_arc, other_closer=other_closer)
        return BorderDistances(distances=resampled, arc_m=arc, other_closer=other_closer)
