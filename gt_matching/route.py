"""One continuous GT border assembled along a sequence of lanelets, resampled, and the
closest-point distances of detected points to it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from gt_matching.geometry import COARSE_STEP_M, MapLines
from gt_matching.polyline import NDArrayBool, NDArrayFloat, NDArrayInt, arc_lengths, resample, windowed_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Every this many GT samples of a lanelet border are its guess samples (KD-tree): other
#: lines' samples near them are "near the border", those very near "on the border".
GUESS_STRIDE: Final = 3
#: Coarse samples of a border (the exact nearest-sample search starts from them): every
#: this many samples at least, and at most this many in all.
MIN_COARSE_STRIDE: Final = 25
MAX_COARSE_SAMPLES: Final = 256
#: Borders with more samples than this find the nearest samples of anchors and of the
#: points their window does not settle with a KD-tree (its build time pays off over the
#: frames of a long route; short routes change often).
KD_TREE_SAMPLES: Final = 16384
#: Borders asked for distances to the resampled GT more often than this also get one (a
#: route measured many times: every lane of every frame while a drive stays on it). Its
#: build costs about as much as it saves over this many such calls; exact distances,
#: dominated by the segment search, gain nothing from it and do not count.
KD_TREE_CALLS: Final = 8
#: ``RouteBorder.resampled`` measures the points of the lanes of a block in passes over
#: at most about this many points (lanes are not split), bounding its arrays.
BLOCK_POINTS: Final = 32768
#: ``RouteBorder.resampled`` searches the whole border for at most this many points at a
#: time (the search without a KD-tree holds points x coarse samples x a stride of floats).
NEAREST_CHUNK: Final = 512
#: Every this many detected points look up their nearest sample; the others
#: interpolate its sample index by point index.
ANCHOR_STRIDE: Final = 20
#: ``ANCHOR_STRIDE`` of ``RouteBorder.resampled``, which gives the distances alone: they do
#: not depend on the seeds (a window that cannot settle a point hands it to the exact
#: search), and on Town01's detections the narrow and wide windows settle about as many
#: points from seeds interpolated over this many points as over ``ANCHOR_STRIDE``, at a
#: quarter of the look-ups.
RESAMPLED_ANCHOR_STRIDE: Final = 80
#: Arc length either side of an interpolated seed searched first for the nearest sample,
#: m (on Town01's noise-free detections all but about one seed in 2000 lie within it of
#: the nearest sample).
NARROW_REACH_M: Final = 0.04
#: Arc length either side of the narrow window's edge minimum searched next, m (noisy
#: detected points scatter their nearest samples along the border); the points it leaves
#: on its edge too are searched over the whole border.
ANCHOR_REACH_M: Final = 0.2
#: Points farther than this from the border are searched over all samples, m.
REFINE_DISTANCE_M: Final = 1.0
#: A border vertex turning by more than this is a kink: points whose nearest sample lies
#: near one are searched globally (a second minimum may start there), rad.
KINK_RAD: Final = 0.02
#: Turning from which a break may start another minimum anywhere within twice the
#: distance, rad (arctan 2: ``tan`` reaches 2 there).
MAX_TAN_TURNING_RAD: Final = float(np.arctan(2.0))
#: Spacing along the border of the points around which other lines are looked up, m.
LOOKOUT_SPACING_M: Final = 5.0
#: Spacing along the border of the checkpoints whose clearance to other lines is kept, m.
CLEARANCE_SPACING_M: Final = 0.25
#: Nearest coarse samples of other lines looked up per checkpoint (lines farther away
#: get the distance of the farthest of them as their clearance).
CLEARANCE_NEIGHBOURS: Final = 16


def _turning(vertices: NDArrayFloat) -> NDArrayFloat:
    """Per interior vertex, the angle the polyline turns by there, rad (pi next to a
    zero-length segment: its direction is unknown)."""
    ahead = np.diff(vertices, axis=0)
    before, after = ahead[:-1], ahead[1:]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = np.einsum("ij,ij->i", before, after)
    degenerate = (np.hypot(*before.T) == 0.0) | (np.hypot(*after.T) == 0.0)
    turning: NDArrayFloat = np.where(degenerate, np.pi, np.abs(np.arctan2(cross, dot)))
    return turning


def _spaced(sample_arc: NDArrayFloat, spacing_m: float) -> NDArrayInt:
    """Indices of the samples at about every ``spacing_m`` of arc length, the last included."""
    last = len(sample_arc) - 1
    spaced = np.searchsorted(sample_arc, np.arange(0.0, sample_arc[-1], spacing_m))
    return np.unique(np.append(np.minimum(spaced, last), last))


def _coincidence_m(step_m: float, other_margin_m: float) -> float:
    """Samples of other lines this close to a border can never be closer than it by the
    margin to a point: d(p, o) >= d(p, border) - coincidence and d_resampled <= d + step / 2."""
    return (other_margin_m - step_m / 2.0) / 2.0


def _interpolated(anchors: NDArrayInt, values: NDArrayFloat) -> NDArrayFloat:
    """``values`` at the point indices ``anchors`` (ascending, the first 0) interpolated
    linearly to every point index up to the last anchor: ``np.interp``'s up to rounding, in
    fewer passes over the points."""
    steps = np.diff(anchors)
    slope = np.diff(values) / steps
    found = np.empty(int(anchors[-1]) + 1)
    found[:-1] = np.repeat(values[:-1] - anchors[:-1] * slope, steps)
    found[:-1] += np.arange(len(found) - 1) * np.repeat(slope, steps)
    found[-1] = values[-1]
    return found


@dataclass(frozen=True)
class BorderDistances:
    """Closest-point distances of detected points to a GT border.

    Fields:
        distances: per point, m (exact, or to the GT resampled every ``step_m``).
        arc_m: per point, arc length of its closest GT point along the border, m; on a closed
            border continuous across its seam (may then leave [0, length]).
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
    guess samples' KD-tree and its clearances to other lines are built on first use
    (``GroundTruth`` builds them with the map) and shared by every route through it.

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
    def checkpoints(self) -> NDArrayInt:
        """Indices of the samples every ``CLEARANCE_SPACING_M``, the last included."""
        return _spaced(self.sample_arc_m, CLEARANCE_SPACING_M)

    @cached_property
    def near_coarse(self) -> tuple[NDArrayInt, NDArrayInt]:
        """Indices (ascending) into ``lines.coarse`` of the samples of other lines within
        ``reach_m + COARSE_STEP_M`` of a ``guess`` sample: those farther from every guess
        sample than the coincidence distance (``_coincidence_m``), and the others."""
        lines = self.lines
        lookouts = self.samples[_spaced(self.sample_arc_m, LOOKOUT_SPACING_M)]
        near = lines.coarse_near(lookouts, self.reach_m + COARSE_STEP_M + LOOKOUT_SPACING_M / 2.0)
        near = near[lines.coarse_owner[near] != lines.slot_of_line[self.line]]
        if len(near) == 0:
            return near, near
        gap = self.guess_tree.query(lines.coarse[near], distance_upper_bound=self.reach_m + COARSE_STEP_M)[0]
        coincident = gap <= _coincidence_m(self.step_m, self.other_margin_m)
        return near[~coincident & np.isfinite(gap)], near[coincident]

    @cached_property
    def clearances(self) -> tuple[NDArrayInt, NDArrayFloat]:
        """Slots of the other lines near this border and, per slot (rows), a lower bound
        of each checkpoint's distance to the line's samples every ``step_m``, m: the
        distance to its nearest coarse sample among the checkpoint's
        ``CLEARANCE_NEIGHBOURS`` nearest (else the farthest of those) minus
        ``COARSE_STEP_M / 2``.

        Coarse samples farther than ``reach_m + COARSE_STEP_M`` from the border or within
        the coincidence distance of it are left out, as a route does: a route's clearance
        is the smallest row of the lines it does not ignore, capped (``clearance_cap_m``)."""
        lines = self.lines
        near = self.near_coarse[0]
        owners = lines.coarse_owner[near]
        slots = np.unique(owners)
        points = self.samples[self.checkpoints]
        rows = np.empty((len(slots), len(points)))
        if len(slots):
            from scipy.spatial import cKDTree

            count = min(CLEARANCE_NEIGHBOURS, len(near))
            distances, index = cKDTree(lines.coarse[near]).query(points, k=count)
            distances, index = distances.reshape(len(points), count), index.reshape(len(points), count)
            rows[:] = distances[:, -1]
            columns = np.broadcast_to(np.arange(len(points))[:, None], index.shape)
            np.minimum.at(rows, (np.searchsorted(slots, owners[index]), columns), distances)
            rows -= COARSE_STEP_M / 2.0
        return slots, rows

    @property
    def clearance_cap_m(self) -> float:
        """Clearance of a checkpoint with no near line: samples of other lines within this
        (plus ``COARSE_STEP_M / 2``) of it lie within ``reach_m + COARSE_STEP_M`` of a
        ``guess`` sample (at most ``GUESS_STRIDE - 1`` steps away), m."""
        return self.reach_m + COARSE_STEP_M / 2.0 - (GUESS_STRIDE - 1) * self.step_m


class RouteBorder:
    """The left or right GT border of a lanelet sequence (the lanelets' borders joined in
    driving order) and its samples every ``step_m``, with what is needed to find each
    detected point's closest GT point and whether another lane's border is closer.

    Assembly only joins the parts' arrays: clearances live in the parts (and are joined on
    first use, by the check for other lanes' borders); a KD-tree of the samples is built
    only for long borders, on first use."""

    def __init__(self, lines: MapLines, parts: list[BorderPart], ignored: set[int], calls: int = 0) -> None:
        """``parts``: the lanelets' borders in driving order (same ``step_m``, reach and
        margin); ``ignored``: line string ids that are never another lane's border (this
        border's own lines and those of lanelets overlapping the route); ``calls``: the
        :attr:`calls` of the same border assembled before (dropped from a cache), so that
        the same method answers as had it been kept."""
        first = parts[0]
        self._calls = calls
        self.step_m = first.step_m
        self.reach_m = first.reach_m
        self.other_margin_m = first.other_margin_m
        self._parts = parts
        self._lines = lines
        self._ignored = ignored
        self.vertices: NDArrayFloat = np.concatenate([part.vertices for part in parts])
        self.samples: NDArrayFloat = np.concatenate([part.samples for part in parts])
        cum = arc_lengths(self.vertices)
        closed = len(self.vertices) > 2 and float(np.hypot(*(self.vertices[-1] - self.vertices[0]))) <= self.step_m
        self.loop_m: float | None = float(cum[-1]) if closed else None
        """Length (m) of a border that ends where it starts (a ring road), else None."""
        arc_offsets = cum[np.cumsum([0] + [len(part.vertices) for part in parts[:-1]])]
        self.sample_arc: NDArrayFloat = np.concatenate(
            [offset + part.sample_arc_m for offset, part in zip(arc_offsets, parts)]
        )
        turning = _turning(self.vertices)
        kinks = turning > KINK_RAD
        break_arc = np.concatenate((arc_offsets[1:], cum[1:-1][kinks]))
        order = np.argsort(break_arc, kind="stable")
        self._break_arc = break_arc[order]
        # Joints count as turning by pi: the borders of two lanelets may not meet.
        break_turning = np.concatenate((np.full(len(parts) - 1, np.pi), turning[kinks]))[order]
        self._break_turning_sum = np.concatenate(([0.0], np.cumsum(break_turning)))
        stride = self._coarse_stride = max(MIN_COARSE_STRIDE, -(-len(self.samples) // MAX_COARSE_SAMPLES))
        starts = np.cumsum([0] + [len(part.samples) for part in parts])
        self._coarse_index = np.unique(
            np.concatenate([np.append(np.arange(a, b, stride), b - 1) for a, b in zip(starts[:-1], starts[1:])])
        )
        self._coarse_half_m = (self._coarse_stride // 2 + 1) * self.step_m
        # A window may hold a repeated sample where two lanelets join.
        widths = [int(2.0 * reach / self.step_m) + 1 + min(len(parts), 2) for reach in (NARROW_REACH_M, ANCHOR_REACH_M)]
        beyond = np.full(widths[-1] - 1, np.inf)
        padded_x, padded_y = (np.concatenate((self.samples[:, axis], beyond)) for axis in (0, 1))
        self._padded = padded_x, padded_y
        """x and y of the samples, m, then infinite: a window may reach past the last."""
        self._sample_x, self._sample_y = padded_x[: len(self.samples)], padded_y[: len(self.samples)]
        self._widths = tuple(widths)
        """Samples in the narrow and in the wide window."""
        self._arc_offsets = arc_offsets

    @cached_property
    def _clearances(self) -> tuple[NDArrayFloat, NDArrayFloat]:
        """Arc length (m) of each part's checkpoints along the border, and each one's
        clearance to the lines that are not ignored (m, the parts' ``clearances``): built on
        first use, by the check for other lanes' borders (distances to the samples alone
        need none)."""
        checkpoint_arc = np.concatenate(
            [offset + part.sample_arc_m[part.checkpoints] for offset, part in zip(self._arc_offsets, self._parts)]
        )
        ignored_slots = set(self._lines.slots(self._ignored).tolist())
        clearance = []
        for part in self._parts:
            slots, rows = part.clearances
            kept = rows[[slot not in ignored_slots for slot in slots.tolist()]]
            cap = np.full(rows.shape[1], part.clearance_cap_m)
            clearance.append(np.minimum(cap, kept.min(axis=0)) if len(kept) else cap)
        return checkpoint_arc, np.concatenate(clearance)

    @cached_property
    def _near_others(self) -> tuple[NDArrayInt, cKDTree | None]:
        """Slot of each coarse sample of the other lines near the border that may come
        closer than it by the margin, and their KD-tree (None when there are none); built
        on first use (a point far enough off the border)."""
        from scipy.spatial import cKDTree

        lines = self._lines
        near = np.unique(np.concatenate([part.near_coarse[0] for part in self._parts]))
        coincident = np.concatenate([part.near_coarse[1] for part in self._parts])
        near = near[~np.isin(near, coincident) & ~np.isin(lines.coarse_owner[near], lines.slots(self._ignored))]
        if len(near) == 0:
            return np.empty(0, dtype=np.int64), None
        return lines.coarse_owner[near], cKDTree(lines.coarse[near])

    def _around_coarse(self, coarse: NDArrayInt) -> NDArrayInt:
        """Per coarse sample (index into the samples), the indices of the samples within
        half a stride (+ 1) of it, clipped to the border: ``(len(coarse), K)``."""
        half = self._coarse_stride // 2 + 1
        around: NDArrayInt = np.clip(coarse[:, None] + np.arange(-half, half + 1), 0, len(self.samples) - 1)
        return around

    def _seed_sample(self, points: NDArrayFloat, tree: bool | None = None) -> NDArrayInt:
        """Index of a sample near each point's nearest one: the nearest from the KD-tree of
        a border that has one (``tree``, default ``_uses_tree``), else the nearest within
        half a stride of the point's nearest coarse sample (exact where the border is smooth)."""
        if self._uses_tree() if tree is None else tree:
            nearest: NDArrayInt = self._tree.query(points)[1]
            return nearest
        coarse = self._coarse_index[np.argmin(self._squared_distances(points, self._coarse_index[None, :]), axis=1)]
        around = self._around_coarse(coarse)
        sample: NDArrayInt = around[np.arange(len(points)), np.argmin(self._squared_distances(points, around), axis=1)]
        return sample

    def _nearest(self, points: NDArrayFloat, within: NDArrayFloat | None = None,
                 tree: bool | None = None) -> tuple[NDArrayFloat, NDArrayInt]:
        """Distance (m) and index of each point's nearest sample over the whole border,
        exactly (ties: the lower index). ``within``: distances to some sample, if known, m.

        Every sample lies within half a stride (+ a step) of a coarse sample of its part
        (every ``_coarse_stride``-th sample of each part and each part's ends), so the
        nearest one, at distance d, lies within that many samples of a coarse sample within
        d + half a stride of the point, and d is at most the distance to the nearest coarse
        sample (or ``within``). A border with a KD-tree (``tree``, default ``_uses_tree``)
        asks it instead."""
        if self._uses_tree() if tree is None else tree:
            distance, sample = self._tree.query(points)
            return distance, sample
        coarse = self._squared_distances(points, self._coarse_index[None, :])
        bound = np.sqrt(np.min(coarse, axis=1))
        if within is not None:
            bound = np.minimum(bound, within)
        point, candidate = np.nonzero(coarse <= ((bound + self._coarse_half_m) ** 2)[:, None])
        around = self._around_coarse(self._coarse_index[candidate])
        squared = self._squared_distances(points[point], around)
        best = np.argmin(squared, axis=1)
        rows = np.arange(len(point))
        distance, sample = np.sqrt(squared[rows, best]), around[rows, best]
        order = np.lexsort((sample, distance, point))
        first = order[np.r_[True, point[order][1:] != point[order][:-1]]]
        return distance[first], sample[first]

    @cached_property
    def _tree(self) -> cKDTree:
        """KD-tree of all samples (built on first use, kept with the route)."""
        from scipy.spatial import cKDTree

        return cKDTree(self.samples)

    def _squared_distances(self, points: NDArrayFloat, samples: NDArrayInt) -> NDArrayFloat:
        """Squared distance (m²) of each point (row) to the samples of its row of indices
        (``(N, K)``, or ``(1, K)`` for the same samples for all)."""
        dx = self._sample_x[samples] - points[:, :1]
        dy = self._sample_y[samples] - points[:, 1:]
        squared: NDArrayFloat = dx * dx + dy * dy
        return squared

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
        self, points: NDArrayFloat, seed: NDArrayFloat
    ) -> tuple[NDArrayFloat, NDArrayInt, NDArrayBool]:
        """Per point, the smallest distance (m) to the samples of the narrow window centred
        on the sample index ``seed`` (rounded; at least ``NARROW_REACH_M`` either side, a
        sample more where lanelets join), or of the wide one (``ANCHOR_REACH_M``) centred on
        the narrow one's minimum where that lies on its edge; that sample's index, and
        whether the window settles it: the minimum is not on the edge (it may continue
        outside), and no kink or lanelet joint near it may start another minimum
        (``_clear_of_breaks``)."""
        narrow, wide = self._widths
        distance, sample, inside = self._window_minimum(points, np.rint(seed).astype(np.int64), narrow)
        edge = np.flatnonzero(~inside)
        if len(edge):
            distance[edge], sample[edge], inside[edge] = self._window_minimum(points[edge], sample[edge], wide)
        return distance, sample, inside & self._smooth(distance, sample)

    def _window_minimum(self, points: NDArrayFloat, centre: NDArrayInt, width: int
                        ) -> tuple[NDArrayFloat, NDArrayInt, NDArrayBool]:
        """Per point, the smallest distance (m) to the ``width`` samples of the window
        centred on sample ``centre``, that sample's index (ties: the first), and whether it
        lies inside the window (not on an edge that is not the border's end; a ring has no end)."""
        last = len(self.samples) - 1
        padded_x, padded_y = self._padded
        first = np.clip(centre - width // 2, 0, last)
        x, y = points[:, 0], points[:, 1]
        squared = np.full(len(points), np.inf)
        closest = np.zeros(len(points), dtype=np.int64)
        for offset in range(width):
            sample = first + offset
            dx, dy = padded_x[sample] - x, padded_y[sample] - y
            dx *= dx
            dy *= dy
            dx += dy
            closer = dx < squared
            np.copyto(squared, dx, where=closer)
            closest[closer] = offset
        ends = self.loop_m is None  # a ring's first and last samples are no ends: it goes on
        inside = ((closest > 0) | ((first == 0) & ends)) & ((closest < width - 1) | ((first + width - 1 >= last) & ends))
        return np.sqrt(squared), first + closest, inside

    def _smooth(self, distance: NDArrayFloat, sample: NDArrayInt) -> NDArrayBool:
        """Whether no kink or lanelet joint near each point's nearest sample (index
        ``sample``, ``distance`` m away) may start another minimum (``_clear_of_breaks``)."""
        breaks = self._break_arc
        if len(breaks) == 0:
            return np.ones(len(sample), dtype=bool)
        arc, reach = self.sample_arc[sample], 2.0 * distance + self.step_m
        low, high = np.searchsorted(breaks, arc - reach), np.searchsorted(breaks, arc + reach, side="right")
        smooth = low == high
        check = np.flatnonzero(~smooth)
        if len(check):
            smooth[check] = self._clear_of_breaks(arc[check], distance[check], low[check], high[check])
        return smooth

    @property
    def calls(self) -> int:
        """Calls for distances to the samples so far (``_uses_tree`` counts them)."""
        return self._calls

    def _uses_tree(self) -> bool:
        """Whether nearest samples come from a KD-tree of all samples: for a long border,
        or one asked for resampled distances more than ``KD_TREE_CALLS`` times (its build
        time then pays off)."""
        return self._calls > KD_TREE_CALLS or len(self.samples) > KD_TREE_SAMPLES

    def _clear_of_breaks(
        self, arc: NDArrayFloat, distance: NDArrayFloat, low: NDArrayInt, high: NDArrayInt
    ) -> NDArrayBool:
        """Whether none of the breaks ``low`` to ``high - 1`` (kinks, lanelet joints) can
        start another minimum for a point ``distance`` (m) from the sample at ``arc`` (m).

        Any closer sample lies within twice the distance of the one found, so only breaks
        within ``2 * distance + step_m`` of it count. Where the border turns by a total of
        Θ < arctan 2 from the sample up to a break, the normals of two minima meet at the
        point only if the sample is within ``distance * tan(Θ)`` of the break (one kink of
        Θ is the worst case), plus a step for the sampling; from arctan 2 on (a joint
        counts as pi) the reach stays ``2 * distance + step_m``."""
        breaks, turning_sum = self._break_arc, self._break_turning_sum
        split = np.searchsorted(breaks, arc)
        clear = np.ones(len(arc), dtype=bool)
        for offset in range(int(np.max(high - low))):
            index = np.minimum(low + offset, len(breaks) - 1)
            turning = np.where(
                index >= split, turning_sum[index + 1] - turning_sum[split], turning_sum[split] - turning_sum[index]
            )
            factor = np.where(turning < MAX_TAN_TURNING_RAD, np.tan(np.minimum(turning, MAX_TAN_TURNING_RAD)), 2.0)
            far = np.abs(breaks[index] - arc) > distance * factor + self.step_m
            clear &= far | (low + offset >= high)
        return clear

    def distances(self, points: NDArrayFloat, *, exact: bool, others: bool = True) -> BorderDistances:
        """Closest-point distances of ``points`` (world frame, m, in driving order) to this
        border, and (``others``; else all False) whether another lane's border is closer.

        Every ``ANCHOR_STRIDE``-th point finds a sample near its nearest one
        (``_seed_sample``); the sample indices of the points between are interpolated by
        point index (detected points lie about evenly apart), and each point takes the
        nearest sample within ``NARROW_REACH_M`` of that, or ``ANCHOR_REACH_M`` where the
        nearest lies farther (the seed need not be exact: the window check below decides). Where that window cannot settle it (minimum on its
        edge, a kink or lanelet joint near it, or the point farther than
        ``REFINE_DISTANCE_M``) ``_nearest`` answers (from the KD-tree of a border that has
        one). The exact distance is the smallest to the segments within two steps of the
        nearest sample (twice the distance for the points near a kink or joint, or far).
        Only points far enough off the border to possibly be closer to another line (by the
        clearance of the checkpoints around the nearest sample) are checked against the
        other lines.
        """
        if not exact:
            self._calls += 1
        anchors = np.arange(0, len(points) + ANCHOR_STRIDE - 1, ANCHOR_STRIDE)
        anchors[-1] = len(points) - 1
        seed = np.interp(np.arange(len(points)), anchors, self._seed_sample(points[anchors]))
        resampled, sample, settled = self._nearest_samples(points, seed)
        redo = np.flatnonzero(~settled | (resampled > REFINE_DISTANCE_M))
        if len(redo):
            resampled[redo], sample[redo] = self._nearest(points[redo], resampled[redo])
        arc = self.sample_arc[sample]
        other_closer = np.zeros(len(points), dtype=bool)
        if others:
            checkpoint_arc, clearances = self._clearances
            after = np.minimum(np.searchsorted(checkpoint_arc, arc), len(clearances) - 1)
            clearance = np.minimum(clearances[after], clearances[np.maximum(after - 1, 0)])
            suspect = 2.0 * resampled > clearance + self.other_margin_m - (self.step_m + CLEARANCE_SPACING_M)
            if np.any(suspect):
                other_closer[suspect] = self._other_closer(points[suspect], resampled[suspect] - self.other_margin_m)
        if exact:
            exact_distance, exact_arc = windowed_distances(points, self.vertices, arc, 2.0 * self.step_m)
            if len(redo):
                # The closest GT point is within the sample's distance of the point, so
                # within twice that of the sample (along a border, arc ~ chord).
                reach = 2.0 * float(np.max(resampled[redo])) + 2.0 * self.step_m
                exact_distance[redo], exact_arc[redo] = windowed_distances(points[redo], self.vertices, arc[redo], reach)
            return BorderDistances(distances=exact_distance, arc_m=self._unwrap(exact_arc), other_closer=other_closer)
        return BorderDistances(distances=resampled, arc_m=self._unwrap(arc), other_closer=other_closer)

    def resampled(self, lanes: Sequence[NDArrayFloat]) -> list[NDArrayFloat]:
        """Per lane (points ``(N >= 2, 2)``, world frame, driving order), the distances (m)
        of its points to the samples: ``distances(points, exact=False, others=False)`` of
        each lane in turn, bit for bit (seeds from each lane's own anchors, the KD-tree from
        the same call on; every ``RESAMPLED_ANCHOR_STRIDE``-th point an anchor), in one pass
        over the points of up to ``BLOCK_POINTS`` of them."""
        found: list[NDArrayFloat] = []
        group: list[NDArrayFloat] = []
        size = 0
        for points in lanes:
            if group and size + len(points) > BLOCK_POINTS:
                found.extend(self._resampled(group))
                group, size = [], 0
            group.append(points)
            size += len(points)
        return found + self._resampled(group) if group else found

    def _resampled(self, lanes: Sequence[NDArrayFloat]) -> list[NDArrayFloat]:
        """``resampled`` of a group of lanes in one pass."""
        counts = [len(points) for points in lanes]
        starts = np.cumsum([0, *counts])
        anchors, by_tree = [], []
        for start, count in zip(starts.tolist(), counts):
            self._calls += 1
            anchors.extend(range(start, start + count - 1, RESAMPLED_ANCHOR_STRIDE))
            anchors.append(start + count - 1)
            by_tree.append(self._uses_tree())
        points = lanes[0] if len(lanes) == 1 else np.concatenate(lanes)
        anchors_ = np.array(anchors)
        seeds = self._by_method((points[anchors_],), np.searchsorted(starts, anchors_, side="right") - 1, by_tree,
                                lambda chosen, tree: (self._seed_sample(chosen, tree),))[0]
        seed = _interpolated(anchors_, seeds)
        resampled, sample, settled = self._nearest_samples(points, seed)
        redo = np.flatnonzero(~settled | (resampled > REFINE_DISTANCE_M))
        for first in range(0, len(redo), NEAREST_CHUNK):
            chunk = redo[first:first + NEAREST_CHUNK]
            resampled[chunk] = self._by_method((points[chunk], resampled[chunk]),
                                               np.searchsorted(starts, chunk, side="right") - 1, by_tree,
                                               self._nearest)[0]
        bounds = starts.tolist()
        return [resampled[first:end] for first, end in zip(bounds[:-1], bounds[1:])]

    def _by_method(self, arrays: tuple[Any, ...], lane: NDArrayInt, by_tree: list[bool],
                   method: Callable[..., tuple[Any, ...]]) -> tuple[Any, ...]:
        """``method(*arrays, tree)`` with each row of ``arrays`` (one of lane ``lane``)
        answered with its lane's ``tree`` flag (``by_tree``)."""
        if all(by_tree) or not any(by_tree):
            return method(*arrays, by_tree[0])
        flags = np.array(by_tree)[lane]
        results: list[Any] = []
        for tree in (False, True):
            rows = np.flatnonzero(flags == tree)
            if len(rows) == 0:
                continue
            answer = method(*(array[rows] for array in arrays), tree)
            results = results or [np.empty(len(lane), dtype=part.dtype) for part in answer]
            for result, part in zip(results, answer):
                result[rows] = part
        return tuple(results)

    def _unwrap(self, arc: NDArrayFloat) -> NDArrayFloat:
        """On a closed border, arc lengths made continuous across its seam (a jump by more
        than half the loop counts as crossing it), so the last minus the first is the
        distance driven; unchanged otherwise."""
        if self.loop_m is None or len(arc) < 2:
            return arc
        return np.unwrap(arc, period=self.loop_m)
