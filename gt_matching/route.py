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
#: Checkpoint-to-sample distances computed at once when clearances are built.
CLEARANCE_BLOCK: Final = 1 << 20


def _kinks(vertices: NDArrayFloat) -> NDArrayBool:
    """Per interior vertex, whether the polyline turns there by more than ``KINK_RAD``
    (a zero-length segment next to it counts as a kink)."""
    ahead = np.diff(vertices, axis=0)
    before, after = ahead[:-1], ahead[1:]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = np.einsum("ij,ij->i", before, after)
    degenerate = (np.hypot(*before.T) == 0.0) | (np.hypot(*after.T) == 0.0)
    return degenerate | (np.abs(np.arctan2(cross, dot)) > KINK_RAD)


def _spaced(sample_arc: NDArrayFloat, spacing_m: float) -> NDArrayInt:
    """Indices of the samples at about every ``spacing_m`` of arc length, the last included."""
    last = len(sample_arc) - 1
    spaced = np.searchsorted(sample_arc, np.arange(0.0, sample_arc[-1], spacing_m))
    return np.unique(np.append(np.minimum(spaced, last), last))


def _coincidence_m(step_m: float, other_margin_m: float) -> float:
    """Samples of other lines this close to a border can never be closer than it by the
    margin to a point: d(p, o) >= d(p, border) - coincidence and d_resampled <= d + step / 2."""
    return (other_margin_m - step_m / 2.0) / 2.0


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
    """One lanelet's left or right border in driving order, prepared once per map; its
    KD-trees and clearances to other lines are built on first use and shared by every
    route through the lanelet.

    Fields:
        vertices: ``(N, 2)`` vertices, world frame, m.
        samples: points every ``step_m`` along it, ends included, m.
        sample_arc_m: arc length of each sample, m.
        line: id of the line string the border lies on.
        lines: every line of the map.
        step_m: sampling distance, m.
        reach_m: other lines farther than this from the border are never closer than it
            for a point within ``reach_m / 2``, m.
        other_margin_m: how much closer another lane's border must be for a point to count
            as unmatched, m.
    """

    vertices: NDArrayFloat
    samples: NDArrayFloat
    sample_arc_m: NDArrayFloat
    line: int
    lines: MapLines
    step_m: float
    reach_m: float
    other_margin_m: float

    @classmethod
    def of(
        cls, vertices: NDArrayFloat, line: int, lines: MapLines, step_m: float, reach_m: float, other_margin_m: float
    ) -> BorderPart:
        """A border polyline (m) on line string ``line``, sampled every ``step_m``."""
        samples, _ = resample(vertices, step_m)
        return cls(
            vertices=vertices,
            samples=samples,
            sample_arc_m=np.minimum(np.arange(len(samples)) * step_m, arc_lengths(vertices)[-1]),
            line=line,
            lines=lines,
            step_m=step_m,
            reach_m=reach_m,
            other_margin_m=other_margin_m,
        )

    @cached_property
    def guess(self) -> NDArrayInt:
        """Indices of every ``GUESS_STRIDE``-th sample, the last included."""
        guess = np.arange(0, len(self.samples) + GUESS_STRIDE - 1, GUESS_STRIDE)
        guess[-1] = len(self.samples) - 1
        return guess

    @cached_property
    def guess_tree(self) -> cKDTree:
        """KD-tree of the ``guess`` samples."""
        from scipy.spatial import cKDTree

        return cKDTree(self.samples[self.guess])

    @cached_property
    def fine_tree(self) -> cKDTree:
        """KD-tree of all samples."""
        from scipy.spatial import cKDTree

        return cKDTree(self.samples)

    @cached_property
    def checkpoints(self) -> NDArrayInt:
        """Indices of the samples every ``CLEARANCE_SPACING_M``, the last included."""
        return _spaced(self.sample_arc_m, CLEARANCE_SPACING_M)

    @cached_property
    def clearances(self) -> tuple[NDArrayInt, NDArrayFloat]:
        """Slots of the other lines near this border and, per slot (rows), each
        checkpoint's distance to the line's coarse samples minus ``COARSE_STEP_M / 2``
        (a lower bound to its samples every ``step_m``), m.

        Coarse samples farther than ``reach_m + COARSE_STEP_M`` from the border or within
        the coincidence distance of it are left out, as a route does: a route's clearance
        is the smallest row of the lines it does not ignore, capped (``clearance_cap_m``)."""
        lines = self.lines
        lookouts = self.samples[_spaced(self.sample_arc_m, LOOKOUT_SPACING_M)]
        near = lines.coarse_near(lookouts, self.reach_m + COARSE_STEP_M + LOOKOUT_SPACING_M / 2.0)
        near = near[lines.coarse_owner[near] != lines.slot_of_line[self.line]]
        if len(near):
            gap = self.guess_tree.query(lines.coarse[near], distance_upper_bound=self.reach_m + COARSE_STEP_M)[0]
            near = near[(gap > _coincidence_m(self.step_m, self.other_margin_m)) & np.isfinite(gap)]
        owners = lines.coarse_owner[near]
        slots, starts = np.unique(owners, return_index=True)
        points = self.samples[self.checkpoints]
        rows = np.empty((len(slots), len(points)))
        if len(slots):
            others = lines.coarse[near, 0] + 1j * lines.coarse[near, 1]
            complex_points = points[:, 0] + 1j * points[:, 1]
            chunk = max(1, CLEARANCE_BLOCK // len(others))
            for at in range(0, len(points), chunk):
                gaps = np.abs(complex_points[at : at + chunk, None] - others)
                rows[:, at : at + chunk] = np.minimum.reduceat(gaps, starts, axis=1).T
            rows -= COARSE_STEP_M / 2.0
        return slots, rows

    @property
    def clearance_cap_m(self) -> float:
        """Clearance of a checkpoint with no near line: samples of other lines within this
        (plus ``COARSE_STEP_M / 2``) of it lie within ``reach_m + COARSE_STEP_M`` of a
        ``guess`` sample (at most ``GUESS_STRIDE - 1`` steps away), m."""
        return self.reach_m + COARSE_STEP_M / 2.0 - (GUESS_STRIDE - 1) * self.step_m


def _nearest_over(
    trees: list[cKDTree], points: NDArrayFloat, within: NDArrayFloat | None = None
) -> tuple[NDArrayFloat, NDArrayInt, NDArrayInt]:
    """Per point, the smallest distance over several KD-trees (m), the first tree that
    has it, and the index in that tree (-1 where none is below ``within``, m, default
    infinite: the distance stays ``within``). A tree is only asked for the points whose
    best distance so far exceeds their distance to its bounding box, and only that far."""
    best = np.full(len(points), np.inf) if within is None else within.astype(np.float64)
    which = np.full(len(points), -1, dtype=np.int64)
    index = np.full(len(points), -1, dtype=np.int64)
    for k, tree in enumerate(trees):
        outside = np.maximum(np.maximum(tree.mins - points, points - tree.maxes), 0.0)
        ask = np.flatnonzero(np.hypot(outside[:, 0], outside[:, 1]) < best)
        if len(ask) == 0:
            continue
        distances, found = tree.query(points[ask], distance_upper_bound=float(np.max(best[ask])))
        better = distances < best[ask]
        ask = ask[better]
        best[ask], which[ask], index[ask] = distances[better], k, found[better]
    return best, which, index


class RouteBorder:
    """The left or right GT border of a lanelet sequence (the lanelets' borders joined in
    driving order) and its samples every ``step_m``, with what is needed to find each
    detected point's closest GT point and whether another lane's border is closer.

    Assembly only joins the parts' arrays: KD-trees and clearances live in the parts."""

    def __init__(self, lines: MapLines, parts: list[BorderPart], ignored: set[int]) -> None:
        """``parts``: the lanelets' borders in driving order (same ``step_m``, reach and
        margin); ``ignored``: line string ids that are never another lane's border (this
        border's own lines and those of lanelets overlapping the route)."""
        first = parts[0]
        self.step_m = first.step_m
        self.reach_m = first.reach_m
        self.other_margin_m = first.other_margin_m
        self._parts = parts
        self._lines = lines
        self._ignored = ignored
        self.vertices: NDArrayFloat = np.concatenate([part.vertices for part in parts])
        self.samples: NDArrayFloat = np.concatenate([part.samples for part in parts])
        cum = arc_lengths(self.vertices)
        arc_offsets = cum[np.cumsum([0] + [len(part.vertices) for part in parts[:-1]])]
        self._sample_offsets = np.cumsum([0] + [len(part.samples) for part in parts[:-1]])
        self.sample_arc: NDArrayFloat = np.concatenate(
            [offset + part.sample_arc_m for offset, part in zip(arc_offsets, parts)]
        )
        self._break_arc = np.sort(np.concatenate((arc_offsets[1:], cum[1:-1][_kinks(self.vertices)])))
        self._guess_arc = np.concatenate(
            [offset + part.sample_arc_m[part.guess] for offset, part in zip(arc_offsets, parts)]
        )
        self._guess_offsets = np.cumsum([0] + [len(part.guess) for part in parts[:-1]])
        self._complex_samples = self.samples[:, 0] + 1j * self.samples[:, 1]
        # A window may hold a repeated sample where two lanelets join.
        self._joints = min(len(parts), 2)
        self._checkpoint_arc = np.concatenate(
            [offset + part.sample_arc_m[part.checkpoints] for offset, part in zip(arc_offsets, parts)]
        )
        ignored_slots = lines.slots(ignored)
        clearance = []
        for part in parts:
            slots, rows = part.clearances
            kept = rows[~np.isin(slots, ignored_slots)]
            cap = np.full(rows.shape[1], part.clearance_cap_m)
            clearance.append(np.minimum(cap, kept.min(axis=0)) if len(kept) else cap)
        self._clearance = np.concatenate(clearance)

    @cached_property
    def _near_others(self) -> tuple[NDArrayInt, cKDTree | None]:
        """Slot of each coarse sample of the other lines near the border that may come
        closer than it by the margin, and their KD-tree (None when there are none); built
        on first use (a point far enough off the border)."""
        from scipy.spatial import cKDTree

        lines = self._lines
        lookouts = self.samples[_spaced(self.sample_arc, LOOKOUT_SPACING_M)]
        near = lines.coarse_near(lookouts, self.reach_m + COARSE_STEP_M + LOOKOUT_SPACING_M / 2.0)
        near = near[~np.isin(lines.coarse_owner[near], lines.slots(self._ignored))]
        if len(near):
            bound = self.reach_m + COARSE_STEP_M
            others = lines.coarse[near]
            gap = np.min([part.guess_tree.query(others, distance_upper_bound=bound)[0] for part in self._parts], axis=0)
            near = near[(gap > _coincidence_m(self.step_m, self.other_margin_m)) & np.isfinite(gap)]
        if len(near) == 0:
            return np.empty(0, dtype=np.int64), None
        return lines.coarse_owner[near], cKDTree(lines.coarse[near])

    def _global_nearest(
        self, points: NDArrayFloat, distances: NDArrayFloat, samples: NDArrayInt
    ) -> tuple[NDArrayFloat, NDArrayInt]:
        """Distance (m) and index of each point's nearest sample over the whole border,
        given the distance to some sample (``distances``, m; index ``samples``)."""
        best, part, index = _nearest_over([p.fine_tree for p in self._parts], points, distances)
        found = part >= 0
        return best, np.where(found, self._sample_offsets[part] + index, samples)

    def _seed_arc(self, points: NDArrayFloat) -> NDArrayFloat:
        """Arc length (m) of each point's nearest coarse sample (every ``GUESS_STRIDE``-th
        sample of each part)."""
        _, part, index = _nearest_over([p.guess_tree for p in self._parts], points)
        arc: NDArrayFloat = self._guess_arc[self._guess_offsets[part] + index]
        return arc

    def _other_closer(self, points: NDArrayFloat, limits: NDArrayFloat) -> NDArrayBool:
        """Whether another line's samples every ``step_m`` come closer to each point than
        its limit (m): a lower bound from the coarse samples first, then the KD-trees of
        the few lines near the points it cannot rule out."""
        closer = np.zeros(len(points), dtype=bool)
        owner, tree = self._near_others
        if tree is None:
            return closer
        half = COARSE_STEP_M / 2.0
        open_ = np.flatnonzero(tree.query(points)[0] - half < limits)
        if len(open_) == 0:
            return closer
        near = tree.query_ball_point(points[open_], limits[open_] + half)
        for slot in np.unique(owner[np.concatenate([np.asarray(n, dtype=np.int64) for n in near])]):
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
            resampled[redo], sample[redo] = self._global_nearest(points[redo], resampled[redo], sample[redo])
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
