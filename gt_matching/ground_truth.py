"""Ground truth of detected lanes from a Lanelet2 map: lanelet matching at the sender's
pose, the lanelet sequence the detection follows, and closest-point error metrics.

Everything is in the map's local metric frame (x east, y north, yaw counter-clockwise
from x), which is the world frame of the detections.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import reduce
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from gt_matching.config import MatchingConfig
from gt_matching.errors import MatchingError
from gt_matching.geometry import LaneletGeometry, LaneletKey, MapLines
from gt_matching.lane_match import LaneMatch
from gt_matching.lru import lru_get
from gt_matching.metrics import BorderErrors, LaneErrors, LaneMetrics
from gt_matching.polyline import (
    NDArrayFloat,
    NDArrayInt,
    angle_difference,
    arc_lengths_many,
    as_polyline,
    closest_many,
    mid_line,
    SegmentIndex,
)
from gt_matching.route import BorderPart, RouteBorder

#: More candidate lanelet sequences than this for one detection is an error.
MAX_SEQUENCES: Final = 4096
#: Assembled routes kept per ``GroundTruth`` (consecutive frames of a drive reuse them; a
#: route holds its resampled borders and KD-trees, about 0.7 MB on Town04, so the cache
#: bounds a long drive's memory: 600 frames on Town04 touch 154 routes, and an LRU of 16
#: already misses no more than one of any size).
ROUTE_CACHE_SIZE: Final = 32
#: Samples (both borders, every ``step_m``) the routes kept hold together at most, the
#: latest route always kept: with their KD-trees and windows about 80 bytes each (about 32 MB
#: together), bounding the cache where lanelets are long (1 to 2 km routes near the end of a
#: 10 000-frame drive on Town04 hold 3 to 15 MB each). A route dropped for it keeps its
#: place and its borders' call counts among the ``ROUTE_CACHE_SIZE`` and is assembled again
#: when used: the same results as had it been kept.
ROUTE_CACHE_SAMPLES: Final = 400_000
#: Lanelet borders a ``GroundTruth`` prepared on first use keeps (LRU; with their clearances
#: about 160 kB each on Town04, 1746 of them), and line strings whose samples and KD-tree it
#: keeps (``MapLines``, about 80 kB each): a long drive touching much of a map stays bounded;
#: one prepared whole keeps all.
PART_CACHE_SIZE: Final = 64
#: Lanelets whose geometry (``LaneletGeometry``: mid-line every 0.1 m and its KD-tree,
#: about 35 kB on Town04, 30 MB for its 873 lanelets) a ``GroundTruth`` prepared on first
#: use keeps (LRU; one still referenced, by a match in progress, is found again as the
#: same object): a long drive touching much of a map stays bounded.
GEOMETRY_CACHE_SIZE: Final = 128
#: Poses whose candidate lanelets a ``GroundTruth`` keeps (every lane measured in a frame
#: is matched at the same pose, the ego's).
CANDIDATE_CACHE_SIZE: Final = 8
#: ``GroundTruth`` objects kept by ``match_lane``/``evaluate_lane``.
GROUND_TRUTH_CACHE_SIZE: Final = 4
#: A lanelet sequence fits a detection when at least this share of the detection's
#: centreline samples lie within ``max_distance_m`` of the sequence's centreline.
MIN_FIT_SHARE: Final = 0.5
#: The detection follows another lane when a sequence from a lanelet off the sender's
#: pose fits it better (mean capped centreline distance) by more than this, m.
OTHER_LANE_GAIN_M: Final = 0.5
#: Sequences of the sender's lane whose scores lie within this of the best one (m; the
#: score measures to mid-line vertices every 0.1 m, so it cannot separate branches or
#: merging lanelets that differ by centimetres) are told apart by ``_border_fit_m``.
TIE_SCORE_M: Final = 0.05
#: ``_border_fit_m`` measures every this many detected border points.
BORDER_FIT_STRIDE: Final = 5

Pose = tuple[float, float, float]
"""Sender pose (x m, y m, yaw rad), world frame."""


@dataclass(frozen=True)
class _Candidate:
    """A lanelet near the pose: its geometry, Lanelet2 matching distance (m), the pose's
    arc length on its centreline (m), and whether it counts as the sender's lane."""

    geometry: LaneletGeometry
    distance_m: float
    pose_arc_m: float
    on_pose: bool


@dataclass(frozen=True)
class _Sequence:
    """A scored lanelet sequence: lanelets in driving order, the candidate it starts from,
    mean capped centreline distance of the detection (m), and the share of detection
    samples within ``max_distance_m``."""

    lanelets: tuple[LaneletGeometry, ...]
    candidate: _Candidate
    score_m: float
    fit_share: float


@dataclass(frozen=True)
class _Route:
    """Assembled GT borders of a lanelet sequence."""

    keys: tuple[LaneletKey, ...]
    left: RouteBorder
    right: RouteBorder

    @property
    def samples(self) -> int:
        """Samples of both borders."""
        return len(self.left.samples) + len(self.right.samples)


@dataclass(frozen=True)
class _Prepared:
    """What lanelet sequences are scored on, for one detected lane: its mid-line samples
    every ``score_step_m`` (``(K, 2)``, m) and their length (m), the sender's distance to
    them (m) and arc length along them (m), and each lanelet's ``centre_nearest`` of the
    samples."""

    centre: NDArrayFloat
    length_m: float
    pose_gap_m: float
    pose_arc_m: float
    centre_nearest: CentreNearest


def _pose(pose: Sequence[float]) -> Pose:
    try:
        x, y, yaw = (float(v) for v in pose)
    except (TypeError, ValueError) as exc:
        raise MatchingError(f"pose {pose!r}: expected (x, y, yaw)") from exc
    if not all(np.isfinite((x, y, yaw))):
        raise MatchingError(f"pose (x={x}, y={y}, yaw={yaw}) is not finite")
    return x, y, yaw


def _describe(pose: Pose) -> str:
    return f"(x={pose[0]:.3f} m, y={pose[1]:.3f} m, yaw={pose[2]:.4f} rad)"


def _ids(lanelets: Sequence[LaneletGeometry]) -> tuple[int, ...]:
    return tuple(g.key[0] for g in lanelets)


CentreNearest = Callable[[LaneletGeometry], tuple[NDArrayFloat, NDArrayInt]]
"""A lanelet's ``centre_nearest`` of the detection's mid-line samples (memoised per frame)."""


def _sequence_arc(lanelets: Sequence[LaneletGeometry], centre_nearest: CentreNearest) -> NDArrayFloat:
    """Arc length (m) along the joined mid-lines of ``lanelets`` of each detection mid-line
    sample's closest mid-line vertex (the first lanelet wins a tie)."""
    found = [centre_nearest(g) for g in lanelets]
    if len(found) == 1:
        only: NDArrayFloat = lanelets[0].centre_arc_m[found[0][1]]
        return only
    nearest = np.argmin([distance for distance, _ in found], axis=0)
    offsets = np.cumsum([0.0] + [g.length_m for g in lanelets[:-1]])
    along = np.array([offset + g.centre_arc_m[index] for offset, g, (_, index) in zip(offsets, lanelets, found)])
    arc: NDArrayFloat = along[nearest, np.arange(len(nearest))]
    return arc


def _advance_m(lanelets: Sequence[LaneletGeometry], centre_nearest: CentreNearest, join_m: float,
               samples: NDArrayFloat, cap_m: float) -> float:
    """How far (m) the detection's mid-line (``samples``) advances along the joined
    mid-lines of ``lanelets`` (negative when it runs against them). When they close into a
    loop (the last ends within ``join_m`` of where the first starts: a ring road) each step
    between samples is taken the short way round, so crossing the loop's seam is no
    reversal. When a step still jumps (longer than twice the samples' spacing plus
    ``cap_m``, either way: the mid-lines pass over themselves, a helical ramp whose turns
    lie on one another in 2-D), the samples are walked along the mid-lines instead
    (``_walked_arc``), so no sample jumps to the other turn."""
    arc = _sequence_arc(lanelets, centre_nearest)
    steps = arc[1:] - arc[:-1]
    loop_m = float(sum(g.length_m for g in lanelets))
    if float(np.hypot(*(lanelets[-1].centre[-1] - lanelets[0].centre[0]))) <= join_m:
        steps = (steps + loop_m / 2) % loop_m - loop_m / 2
    between = samples[1:] - samples[:-1]
    spacing = np.hypot(between[:, 0], between[:, 1])
    if (np.abs(steps) > 2.0 * spacing + cap_m).any():
        steps = np.diff(_walked_arc(lanelets, samples, spacing, cap_m))
    return float(steps.sum())


def _walked_arc(lanelets: Sequence[LaneletGeometry], samples: NDArrayFloat, spacing: NDArrayFloat,
                cap_m: float) -> NDArrayFloat:
    """Arc length (m) along the joined mid-lines of ``lanelets`` of each sample, walked: of
    the mid-line vertices within ``cap_m`` of a sample's nearest distance, it takes the one
    whose arc lies nearest the previous sample's arc plus the ``spacing`` (m) between them.
    Walks start at each place the first sample lies near (one per ``cap_m`` of arc); the
    walk that departs least from the steps the samples take is kept."""
    from scipy.spatial import cKDTree

    offsets = np.cumsum([0.0] + [g.length_m for g in lanelets[:-1]])
    arcs = np.concatenate([offset + g.centre_arc_m for offset, g in zip(offsets, lanelets)])
    tree = cKDTree(np.vstack([g.centre for g in lanelets]))
    nearest, _ = tree.query(samples)
    options = [np.sort(arcs[near]) for near in tree.query_ball_point(samples, nearest + cap_m)]
    first = options[0]
    starts = first[np.concatenate(([True], np.diff(first) > cap_m))]

    def walk(start: float) -> tuple[float, NDArrayFloat]:
        walked, departure = [start], 0.0
        for step, choices in zip(spacing, options[1:]):
            target = walked[-1] + float(step)
            chosen = float(choices[np.argmin(np.abs(choices - target))])
            departure += abs(chosen - target)
            walked.append(chosen)
        return departure, np.array(walked)

    return min((walk(float(start)) for start in starts), key=lambda found: found[0])[1]


def _joined_border(lanelets: Sequence[LaneletGeometry], side: str) -> SegmentIndex:
    """The ``side`` ("left", "right") borders of ``lanelets`` joined, repeated vertices
    dropped, indexed for capped distances."""
    vertices = np.vstack([getattr(g, side) for g in lanelets])
    distinct = np.concatenate(([True], np.any(np.diff(vertices, axis=0) != 0.0, axis=1)))
    return SegmentIndex(vertices[distinct])


JoinedBorder = Callable[[Sequence[LaneletGeometry], str], SegmentIndex]
"""``_joined_border`` (or a cached equivalent)."""


def _border_fit_m(lanelets: Sequence[LaneletGeometry], left: NDArrayFloat, right: NDArrayFloat, cap_m: float,
                  joined: JoinedBorder = _joined_border) -> float:
    """Mean exact distance (m, each capped at ``cap_m``) of every ``BORDER_FIT_STRIDE``-th
    detected border point to the joined borders of ``lanelets``, both sides."""
    fits = [float(np.mean(joined(lanelets, side).capped(points[::BORDER_FIT_STRIDE], cap_m)))
            for points, side in ((left, "left"), (right, "right"))]
    return float(np.mean(fits))


class _SharedNearest:
    """Lanelets' ``centre_nearest`` of several lanes' mid-line samples, each lanelet's
    KD-tree asked once for all of them on first use (a point's answer does not depend on the
    others asked with it)."""

    def __init__(self, centres: list[NDArrayFloat]) -> None:
        self._points = np.concatenate(centres)
        ends = np.cumsum([len(centre) for centre in centres]).tolist()
        self._bounds = list(zip([0, *ends[:-1]], ends))
        self._found: dict[LaneletKey, list[tuple[NDArrayFloat, NDArrayInt]]] = {}

    def of(self, lane: int) -> CentreNearest:
        """``centre_nearest`` of the ``lane``-th lane's samples."""
        def centre_nearest(geometry: LaneletGeometry) -> tuple[NDArrayFloat, NDArrayInt]:
            found = self._found.get(geometry.key)
            if found is None:
                distances, index = geometry.centre_nearest(self._points)
                found = self._found[geometry.key] = [(distances[first:end], index[first:end])
                                                     for first, end in self._bounds]
            return found[lane]

        return centre_nearest


class GroundTruth:
    """A Lanelet2 map prepared for matching detections: built once, reused per frame.

    Construction extracts every lanelet's geometry, border samples and the borders'
    clearances to other lines, and every line string's samples and KD-tree (with
    ``prepare_all=False`` the lanelets' geometry, border samples, clearances and KD-trees
    are built on first use instead: the same results, cheaper when frames match few of the map's lanelets); lanelet
    sequences matched by frames are assembled from them on first use (joining arrays) and
    kept (LRU, ``ROUTE_CACHE_SIZE`` and ``ROUTE_CACHE_SAMPLES``).

    The map must not change after construction.
    """

    def __init__(
        self,
        lanelet_map: Any,
        routing_graph: Any = None,
        *,
        traffic_rules: Any = None,
        config: MatchingConfig | None = None,
        prepare_all: bool = True,
    ) -> None:
        """``traffic_rules`` (default: Lanelet2 Germany, vehicle) should be those of
        ``routing_graph``; they remove matches against the allowed driving direction.
        ``routing_graph``: lanelet2's ``RoutingGraph`` of the map under those rules, or
        None: the same relations computed per lanelet on first use
        (``relations.LaneletRelations``; no cost for the lanelets no frame reaches)."""
        import lanelet2

        from gt_matching.relations import LaneletRelations

        self.lanelet_map = lanelet_map
        self.config = config or MatchingConfig()
        self.traffic_rules = traffic_rules or lanelet2.traffic_rules.create(
            lanelet2.traffic_rules.Locations.Germany, lanelet2.traffic_rules.Participants.Vehicle
        )
        self.routing_graph = routing_graph if routing_graph is not None else LaneletRelations(
            lanelet_map, self.traffic_rules)
        self.lines = MapLines(lanelet_map, cache_size=None if prepare_all else PART_CACHE_SIZE)
        self._geometry: OrderedDict[LaneletKey, LaneletGeometry] = OrderedDict()
        self._geometry_kept = None if prepare_all else GEOMETRY_CACHE_SIZE
        self._geometry_alive: weakref.WeakValueDictionary[LaneletKey, LaneletGeometry] = (
            weakref.WeakValueDictionary())
        self._parts: OrderedDict[tuple[LaneletKey, str], BorderPart] = OrderedDict()
        self._parts_kept = None if prepare_all else PART_CACHE_SIZE
        self._routes: OrderedDict[tuple[LaneletKey, ...], _Route | tuple[int, int]] = OrderedDict()
        """The latest routes (LRU, ``ROUTE_CACHE_SIZE``): assembled, or (beyond
        ``ROUTE_CACHE_SAMPLES``) the call counts of their left and right borders."""
        self._near_pose: OrderedDict[Pose, list[_Candidate]] = OrderedDict()
        self._graph_neighbours: dict[tuple[LaneletKey, str], list[tuple[LaneletKey, Any]]] = {}
        self._joined: OrderedDict[tuple[tuple[LaneletKey, ...], str], SegmentIndex] = OrderedDict()
        if prepare_all:
            for lanelet in lanelet_map.laneletLayer:
                geometry = self._lanelet(lanelet)
                for side in ("left", "right"):
                    self._part(geometry, side).clearances
            for slot in range(len(self.lines.vertices)):
                self.lines.tree(slot, self.config.step_m)

    def match(self, left: npt.ArrayLike, right: npt.ArrayLike, pose: Sequence[float]) -> LaneMatch:
        """Ground truth of a detected lane given its borders (``(N, 2)``, world frame,
        driving order) and the sender's pose (x, y, yaw)."""
        return self._match(*self._inputs(left, right, pose))[0]

    def match_many(self, lanes: Sequence[tuple[npt.ArrayLike, npt.ArrayLike, Sequence[float]]]
                   ) -> list[LaneMatch | MatchingError]:
        """``match`` of each lane (left, right, pose), or its ``MatchingError``, bit for bit as
        one by one: the lanes' mid-line samples measured from their poses in one pass, and the
        lanes at one pose (a frame's) measured to each lanelet in one KD-tree query."""
        found: list[LaneMatch | MatchingError | None] = [None] * len(lanes)
        valid = []
        for index, (left, right, pose) in enumerate(lanes):
            try:
                valid.append((index, *self._inputs(left, right, pose)))
            except MatchingError as exc:
                found[index] = exc
        prepared = self._prepare([(left, right, pose) for _, left, right, pose in valid]) if valid else []
        for (index, left, right, pose), lane in zip(valid, prepared):
            try:
                found[index] = self._match(left, right, pose, lane)[0]
            except MatchingError as exc:
                found[index] = exc
        return [item for item in found if item is not None]

    def _prepare(self, lanes: Sequence[tuple[NDArrayFloat, NDArrayFloat, Pose]]) -> list[_Prepared]:
        """``_Prepared`` of validated lanes: the poses' closest points on the mid-lines in one
        pass (``closest_many``); the lanes at one pose share one query per lanelet."""
        centres = [mid_line(left, right, self.config.score_step_m) for left, right, _ in lanes]
        cum = arc_lengths_many(centres)
        lengths = cum[np.cumsum([len(centre) for centre in centres]) - 1].tolist()
        gaps, arcs = closest_many(np.array([pose[:2] for _, _, pose in lanes]), centres, cum)
        at_pose: dict[Pose, list[int]] = {}
        for index, (_, _, pose) in enumerate(lanes):
            at_pose.setdefault(pose, []).append(index)
        nearest: dict[int, CentreNearest] = {}
        for members in at_pose.values():
            shared = _SharedNearest([centres[index] for index in members])
            nearest.update((index, shared.of(rank)) for rank, index in enumerate(members))
        return [_Prepared(centre, length, gap, arc, nearest[index]) for index, (centre, length, gap, arc)
                in enumerate(zip(centres, lengths, gaps.tolist(), arcs.tolist()))]

    def _match(self, left: NDArrayFloat, right: NDArrayFloat, pose: Pose,
               prepared: _Prepared | None = None) -> tuple[LaneMatch, _Route]:
        """``match`` of validated inputs (``prepared``: by ``_prepare``, else prepared
        alone), and the assembled route."""
        sequence, pose_ids, mismatch = self._select(left, right, pose,
                                                    prepared or self._prepare([(left, right, pose)])[0])
        route = self._route(sequence.lanelets)
        match = LaneMatch(
            lanelet_ids=_ids(sequence.lanelets),
            route_key=route.keys,
            left_gt=route.left.vertices,
            right_gt=route.right.vertices,
            left_gt_samples=route.left.samples,
            right_gt_samples=route.right.samples,
            pose_lanelet_ids=pose_ids,
            matched=mismatch is None,
            mismatch=mismatch,
        )
        return match, route

    def errors(
        self, left: npt.ArrayLike, right: npt.ArrayLike, match: LaneMatch, *, exact: bool = False, others: bool = True
    ) -> LaneErrors:
        """Per-point closest-point errors of a detected lane against the GT of ``match``
        (from ``match()`` on this lane, or on a reference lane that it should follow).

        ``exact`` False: distances to the GT resampled every ``config.step_m`` (the paper's
        method, floor up to ``step_m / 2``); True: point-to-segment distances to the GT
        polyline. ``others`` False skips the check for other lanes' borders closer than
        the GT: ``unmatched`` then marks only points beyond ``max_distance_m``.
        """
        left_xy, right_xy = as_polyline("left border", left), as_polyline("right border", right)
        route = self._route(self._route_geometry(match))
        return self._errors(left_xy, right_xy, match, route, exact, others)

    def resampled(self, match: LaneMatch, lanes: Sequence[tuple[NDArrayFloat, NDArrayFloat]]
                  ) -> list[tuple[NDArrayFloat, NDArrayFloat]]:
        """Per lane (left and right borders, ``as_polyline``-valid, world frame, driving
        order), its points' distances (m) to the GT borders of ``match`` resampled every
        ``config.step_m``: the ``distances_m`` of ``errors(left, right, match,
        others=False)`` bit for bit, all lanes in one pass per border."""
        route = self._route(self._route_geometry(match))
        return list(zip(route.left.resampled([left for left, _ in lanes]),
                        route.right.resampled([right for _, right in lanes])))

    def _errors(
        self, left: NDArrayFloat, right: NDArrayFloat, match: LaneMatch, route: _Route, exact: bool, others: bool
    ) -> LaneErrors:
        """``errors`` of validated borders against the assembled route of ``match``."""
        config = self.config
        borders = []
        for points, border in ((left, route.left), (right, route.right)):
            found = border.distances(points, exact=exact, others=others)
            unmatched = (found.distances > config.max_distance_m) | found.other_closer
            borders.append(BorderErrors(distances_m=found.distances, arc_m=found.arc_m, unmatched=unmatched))
        return LaneErrors(left=borders[0], right=borders[1], match=match, exact=exact, step_m=config.step_m)

    def evaluate(
        self, left: npt.ArrayLike, right: npt.ArrayLike, pose: Sequence[float], *, exact: bool = False
    ) -> LaneMetrics:
        """Closest-point error metrics of a detected lane (borders ``(N, 2)``, world frame,
        driving order; sender at ``pose`` (x, y, yaw)) against its ground truth: ``match``,
        then ``errors``, summarised."""
        left_xy, right_xy, pose_ = self._inputs(left, right, pose)
        match, route = self._match(left_xy, right_xy, pose_)
        return self._errors(left_xy, right_xy, match, route, exact, others=True).metrics()

    def _inputs(
        self, left: npt.ArrayLike, right: npt.ArrayLike, pose: Sequence[float]
    ) -> tuple[NDArrayFloat, NDArrayFloat, Pose]:
        return as_polyline("left border", left), as_polyline("right border", right), _pose(pose)

    def _route_geometry(self, match: LaneMatch) -> list[LaneletGeometry]:
        """The geometry of each lanelet of ``match``'s route; MatchingError naming those
        not in this GroundTruth's map."""
        layer = self.lanelet_map.laneletLayer
        unknown = [key for key in match.route_key if key not in self._geometry and not layer.exists(key[0])]
        if unknown:
            raise MatchingError(f"lanelets {unknown} of the match are not in this GroundTruth's map")
        return [self._lanelet(layer[key[0]].invert() if key[1] else layer[key[0]], key) for key in match.route_key]

    def _lanelet(self, lanelet: Any, key: LaneletKey | None = None) -> LaneletGeometry:
        """The geometry of a Lanelet2 lanelet (its ``key``, if known), kept (LRU of
        ``GEOMETRY_CACHE_SIZE`` when prepared on first use; while referenced elsewhere the
        same object)."""
        key = key or (int(lanelet.id), bool(lanelet.inverted()))

        def make() -> LaneletGeometry:
            geometry = self._geometry_alive.get(key)
            if geometry is None:
                geometry = self._geometry_alive[key] = LaneletGeometry.of(lanelet)
            return geometry

        return lru_get(self._geometry, key, make, self._geometry_kept)

    def _part(self, geometry: LaneletGeometry, side: str) -> BorderPart:
        """A lanelet border ("left" or "right") prepared for routes (cached; LRU of
        ``PART_CACHE_SIZE`` when prepared on first use)."""
        config = self.config
        return lru_get(self._parts, (geometry.key, side), lambda: BorderPart.of(
            getattr(geometry, side),
            getattr(geometry, f"{side}_line"),
            self.lines,
            config.step_m,
            2.0 * config.max_distance_m + config.other_border_margin_m,
            config.other_border_margin_m,
        ), self._parts_kept)

    def _neighbours(self, geometry: LaneletGeometry, way: str) -> list[LaneletGeometry]:
        """The routing graph's ``previous`` or ``following`` lanelets (``way``) of a lanelet,
        in the graph's order (the lanelets kept: the graph does not change)."""
        key = (geometry.key, way)
        found = self._graph_neighbours.get(key)
        if found is None:
            found = self._graph_neighbours[key] = [((int(g.id), bool(g.inverted())), g)
                                                   for g in getattr(self.routing_graph, way)(geometry.lanelet)]
        return [self._lanelet(lanelet, lanelet_key) for lanelet_key, lanelet in found]

    def _joined_border(self, lanelets: Sequence[LaneletGeometry], side: str) -> SegmentIndex:
        """``_joined_border`` of a lanelet sequence, kept (LRU, ``ROUTE_CACHE_SIZE``): the
        tied sequences of consecutive frames recur."""
        return lru_get(self._joined, (tuple(g.key for g in lanelets), side), lambda: _joined_border(lanelets, side),
                       ROUTE_CACHE_SIZE)

    def _candidates(self, pose: Pose) -> list[_Candidate]:
        """Heading-consistent, rule-compliant lanelets within ``search_radius_m`` of the pose
        (those of the last ``CANDIDATE_CACHE_SIZE`` poses kept)."""
        return lru_get(self._near_pose, pose, lambda: self._find_candidates(pose), CANDIDATE_CACHE_SIZE)

    def _find_candidates(self, pose: Pose) -> list[_Candidate]:
        """``_candidates`` of a pose, from Lanelet2's matching."""
        from lanelet2 import matching

        config = self.config
        obj = matching.Object2d(0, matching.Pose2d(*pose), [])
        found = matching.getDeterministicMatches(self.lanelet_map, obj, config.search_radius_m)
        found = matching.removeNonRuleCompliantMatches(found, self.traffic_rules)
        if not found:
            raise MatchingError(f"no lanelet within {config.search_radius_m} m of the pose {_describe(pose)}")
        near: dict[LaneletKey, tuple[LaneletGeometry, float, float]] = {}
        headings = []
        for match in found:
            geometry = self._lanelet(match.lanelet)
            if geometry.key in near:
                continue
            arc, heading = geometry.locate(pose[:2])
            headings.append(f"{geometry.key[0]}: {heading:.3f} rad")
            if angle_difference(heading, pose[2]) <= config.max_heading_diff_rad:
                near[geometry.key] = (geometry, float(match.distance), arc)
        if not near:
            raise MatchingError(
                f"no lanelet within {config.search_radius_m} m of the pose {_describe(pose)} runs within "
                f"{config.max_heading_diff_rad:.3f} rad of its yaw (lanelet headings {', '.join(headings)})"
            )
        nearest = min(distance for _, distance, _ in near.values())
        return [
            _Candidate(geometry, distance, arc, distance <= nearest + config.ambiguity_m)
            for geometry, distance, arc in near.values()
        ]

    def _select(
        self, left: NDArrayFloat, right: NDArrayFloat, pose: Pose, prepared: _Prepared
    ) -> tuple[_Sequence, tuple[int, ...], str | None]:
        """The lanelet sequence to score against, the sender's lanelets, and a mismatch reason
        (``prepared``: the lane's ``_Prepared``)."""
        config = self.config
        candidates = self._candidates(pose)
        centre, centre_nearest = prepared.centre, prepared.centre_nearest
        ahead_m = prepared.length_m - prepared.pose_arc_m + prepared.pose_gap_m + config.margin_m
        behind_m = prepared.pose_arc_m + config.margin_m

        def centre_distances(geometry: LaneletGeometry) -> NDArrayFloat:
            return centre_nearest(geometry)[0]

        sequences = [
            sequence
            for candidate in candidates
            for sequence in self._sequences(candidate, centre, ahead_m, behind_m, centre_distances)
        ]
        order = sorted(range(len(sequences)), key=lambda i: (sequences[i].score_m, not sequences[i].candidate.on_pose))
        best = sequences[order[0]]
        own = next(sequences[i] for i in order if sequences[i].candidate.on_pose)
        tied = [sequences[i] for i in order if sequences[i].candidate.on_pose
                and sequences[i].score_m - own.score_m <= TIE_SCORE_M and sequences[i].lanelets != own.lanelets]
        if tied:
            own = min([own, *tied], key=lambda s: _border_fit_m(s.lanelets, left, right, config.max_distance_m,
                                                                 self._joined_border))
        pose_ids = tuple(sorted(c.geometry.key[0] for c in candidates if c.on_pose))
        mismatch = None
        if own.score_m - best.score_m > OTHER_LANE_GAIN_M:
            mismatch = (
                f"detection follows lanelets {_ids(best.lanelets)}, not the lane of the sender at pose "
                f"{_describe(pose)} (lanelets {pose_ids})"
            )
        elif own.fit_share < MIN_FIT_SHARE:
            mismatch = (
                f"detection is off the lane of the sender at pose {_describe(pose)}: only "
                f"{own.fit_share:.0%} of its centreline lies within {config.max_distance_m} m of lanelets "
                f"{_ids(own.lanelets)}"
            )
        else:
            if _advance_m(own.lanelets, centre_nearest, config.step_m, centre, config.max_distance_m) < 0:
                mismatch = f"detection runs against the driving direction of lanelets {_ids(own.lanelets)}"
        return own, pose_ids, mismatch

    def _sequences(
        self,
        candidate: _Candidate,
        detection: NDArrayFloat,
        ahead_m: float,
        behind_m: float,
        centre_distances: Callable[[LaneletGeometry], NDArrayFloat],
    ) -> list[_Sequence]:
        """Scored lanelet sequences through ``candidate``: predecessors chosen greedily until
        ``behind_m`` is covered, then every successor sequence (routing graph) until
        ``ahead_m`` is covered or the map ends. Lanelets followed stay within
        ``max_distance_m`` of the detection's mid-line samples ``detection`` or join the
        sequence within ``margin_m + max_distance_m`` of the detection's ends."""
        config = self.config
        cap = config.max_distance_m
        reach = config.margin_m + cap

        def near(geometry: LaneletGeometry, taken: Sequence[LaneletGeometry], joint: NDArrayFloat, end: NDArrayFloat) -> bool:
            """Not taken yet, and near the detection or joined to the path near its end."""
            if any(geometry.key == g.key for g in taken):
                return False
            return float(centre_distances(geometry).min()) <= cap or float(np.hypot(*(joint - end))) <= reach

        start = candidate.geometry
        behind: list[LaneletGeometry] = []
        covered = candidate.pose_arc_m
        while covered < behind_m:
            first = (behind or [start])[0]
            previous = [
                g
                for g in self._neighbours(first, "previous")
                if near(g, [start, *behind], g.centre[-1], detection[0])
            ]
            if not previous:
                break
            chosen = min(previous, key=lambda g: float(np.minimum(centre_distances(g), cap).sum()))
            behind.insert(0, chosen)
            covered += chosen.length_m
        leaves: list[list[LaneletGeometry]] = []
        stack = [([start], start.length_m - candidate.pose_arc_m)]
        while stack:
            path, covered = stack.pop()
            following = []
            if covered < ahead_m:
                following = [
                    g
                    for g in self._neighbours(path[-1], "following")
                    if near(g, behind + path, g.centre[0], detection[-1])
                ]
            if not following:
                leaves.append(path)
                if len(leaves) > MAX_SEQUENCES:
                    raise MatchingError(
                        f"more than {MAX_SEQUENCES} lanelet sequences from lanelet {start.key[0]} fit the detection"
                    )
            stack.extend((path + [g], covered + g.length_m) for g in following)
        scored = []
        for path in leaves:
            lanelets = tuple(behind + path)
            distances = reduce(np.minimum, [centre_distances(g) for g in lanelets])
            scored.append(
                _Sequence(
                    lanelets=lanelets,
                    candidate=candidate,
                    # np.mean's sums and quotients without its dispatch (a frame scores a handful of short arrays)
                    score_m=float(np.minimum(distances, cap).sum()) / len(distances),
                    fit_share=int(np.count_nonzero(distances <= cap)) / len(distances),
                )
            )
        return scored

    def _route(self, lanelets: Sequence[LaneletGeometry]) -> _Route:
        """The assembled borders of a lanelet sequence, kept (``ROUTE_CACHE_SIZE``,
        ``ROUTE_CACHE_SAMPLES``)."""
        keys = tuple(g.key for g in lanelets)
        calls = self._routes.get(keys)
        if isinstance(calls, tuple):  # shed: assembled again, its place taken anew
            del self._routes[keys]
        route = lru_get(self._routes, keys,
                        lambda: self._build_route(keys, lanelets, calls if isinstance(calls, tuple) else (0, 0)),
                        ROUTE_CACHE_SIZE)
        assert isinstance(route, _Route)
        if route is not calls:
            self._shed_routes()
        return route

    def _shed_routes(self) -> None:
        """Beyond ``ROUTE_CACHE_SAMPLES``, the least recently used assembled routes (never
        the latest) keep only their borders' call counts."""
        assembled = [(keys, route) for keys, route in self._routes.items() if isinstance(route, _Route)]
        samples = sum(route.samples for _, route in assembled)
        for keys, route in assembled[:-1]:
            if samples <= ROUTE_CACHE_SAMPLES:
                break
            self._routes[keys] = (route.left.calls, route.right.calls)
            samples -= route.samples

    def _build_route(self, keys: tuple[LaneletKey, ...], lanelets: Sequence[LaneletGeometry],
                     calls: tuple[int, int]) -> _Route:
        overlapping = {
            int(line.id)
            for g in lanelets
            for other in self.routing_graph.conflicting(g.lanelet)
            if hasattr(other, "leftBound")
            for line in (other.leftBound, other.rightBound)
        }

        def border(side: str, count: int) -> RouteBorder:
            own = {getattr(g, f"{side}_line") for g in lanelets}
            return RouteBorder(self.lines, [self._part(g, side) for g in lanelets], own | overlapping, count)

        return _Route(keys=keys, left=border("left", calls[0]), right=border("right", calls[1]))


_GROUND_TRUTHS: OrderedDict[tuple[int, int, MatchingConfig], tuple[Any, Any, GroundTruth]] = OrderedDict()


def ground_truth_for(lanelet_map: Any, routing_graph: Any, config: MatchingConfig | None = None) -> GroundTruth:
    """The cached ``GroundTruth`` of a map and routing graph (built on first use)."""
    config = config or MatchingConfig()
    key = (id(lanelet_map), id(routing_graph), config)
    entry = _GROUND_TRUTHS.get(key)
    if entry is None or entry[0] is not lanelet_map or entry[1] is not routing_graph:
        entry = (lanelet_map, routing_graph, GroundTruth(lanelet_map, routing_graph, config=config))
        _GROUND_TRUTHS[key] = entry
        if len(_GROUND_TRUTHS) > GROUND_TRUTH_CACHE_SIZE:
            _GROUND_TRUTHS.popitem(last=False)
    _GROUND_TRUTHS.move_to_end(key)
    return entry[2]


def match_lane(
    lanelet_map: Any,
    routing_graph: Any,
    left: npt.ArrayLike,
    right: npt.ArrayLike,
    pose: Sequence[float],
    *,
    config: MatchingConfig | None = None,
) -> LaneMatch:
    """Ground-truth lanelets and assembled GT borders of a detected lane (see ``GroundTruth.match``)."""
    return ground_truth_for(lanelet_map, routing_graph, config).match(left, right, pose)


def evaluate_lane(
    lanelet_map: Any,
    routing_graph: Any,
    left: npt.ArrayLike,
    right: npt.ArrayLike,
    pose: Sequence[float],
    *,
    step: float | None = None,
    exact: bool = False,
    config: MatchingConfig | None = None,
) -> LaneMetrics:
    """Error metrics of one detected lane in one frame (see ``GroundTruth.evaluate``).

    ``step`` (m) overrides ``config.step_m``, the GT resampling distance (default 0.02 m).
    """
    config = config or MatchingConfig()
    if step is not None and step != config.step_m:
        config = replace(config, step_m=step)
    return ground_truth_for(lanelet_map, routing_graph, config).evaluate(left, right, pose, exact=exact)
