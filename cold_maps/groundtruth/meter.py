"""Closest-point errors of lanes against the Lanelet2 ground truth (``gt_matching``).

:class:`GroundTruthMeter` is the evaluation's one door to ``gt_matching.GroundTruth``:
it matches a lane (or the lane the vehicles truly drive) to its lanelets and measures
every detected point against the GT borders resampled every ``step_m``.

A measurement *covers* the lane only when the GT does: the lane follows the sender's lane
(``LaneMatch.matched``) and no detected point lies beyond either end of the GT sequence
(its nearest GT point is the end and it lies more than ``GT_END_TOLERANCE_M`` past it
along the GT's end direction). Otherwise ``Measurement.gt_unmatched`` names why, and the
evaluation does not score the frame: a GT that stops at a lane end the routing graph
does not continue would measure every point beyond to that end.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

import numpy as np

from cold_maps.network.lane_strip import NDArrayFloat
from gt_matching.lru import lru_get
from gt_matching.metrics import known_distance_m, near_count
from gt_matching.polyline import NDArrayInt, arc_lengths, arc_lengths_many, as_polyline

if TYPE_CHECKING:
    from gt_matching import GroundTruth, LaneMatch, MatchingError

Lane = tuple[NDArrayFloat, NDArrayFloat, tuple[float, float, float],
             tuple[NDArrayFloat, NDArrayFloat] | None]
"""A lane to measure: left and right border (``(N, 2)``, world frame, driving order), the
sender's pose (x m, y m, yaw rad) and the reference lane's borders or None
(``GroundTruthMeter.measure``)."""

MATCH_CACHE_SIZE: Final[int] = 16
"""Reference lanes whose GT match ``GroundTruthMeter`` keeps (a frame has a handful)."""
ENDS_CACHE_SIZE: Final[int] = 64
"""GT borders whose end directions (``gt_ends``) ``GroundTruthMeter`` keeps."""
RANGE_ERROR_THRESHOLD_M: Final[float] = 1.0
"""A stretch of a detected border counts towards the perception range only where its
points lie within this distance (m) of the GT: the paper (sec. IV) calls interpolation
distances whose maximum error exceeds 1 m not reliable."""


RANGE_CHORD_M: Final[float] = 0.5
"""Chord (m) along which ``covered_length_m`` measures a border: detection noise of σ on
points 0.1 m apart lengthens a polyline by about σ²/step² (5 cm: +25 %), along 0.5 m
chords by σ²/chord² (1 %); a chord shortens an arc of radius R by chord²/(24 R²) (R 6 m: 0.03 %)."""


def _chord_numbers(arc: NDArrayFloat) -> NDArrayFloat:
    """Which ``RANGE_CHORD_M`` of arc length each arc length (m, >= 0) lies in: the floor of
    their quotient (``arc // RANGE_CHORD_M`` bit for bit while ``RANGE_CHORD_M`` is a power of
    two; numpy's floor division costs several times more)."""
    numbers: NDArrayFloat = np.floor(arc / RANGE_CHORD_M)
    return numbers


def _chords(border: NDArrayFloat, arc: NDArrayFloat, first: int, end: int) -> tuple[NDArrayInt, NDArrayFloat]:
    """The chords of about ``RANGE_CHORD_M`` along the points ``first`` to ``end - 1`` of a
    border (``arc``: its ``arc_lengths``): the indices of their ends (the first point, each
    point that starts another ``RANGE_CHORD_M`` of arc length from the first, the last)
    and their lengths (m)."""
    stations = _chord_numbers(arc[first:end] if first == 0 else arc[first:end] - arc[first])
    change = np.flatnonzero(stations[1:] != stations[:-1])
    ends = np.empty(len(change) + 2, dtype=np.int64)
    ends[0], ends[-1] = first, end - 1
    np.add(change, first + 1, out=ends[1:-1])
    if ends[-1] == ends[-2]:
        ends = ends[:-1]
    step = border[ends[1:]] - border[ends[:-1]]
    lengths: NDArrayFloat = np.hypot(step[:, 0], step[:, 1])
    return ends, lengths


def covered_length_m(border: NDArrayFloat, errors_m: NDArrayFloat,
                     threshold_m: float = RANGE_ERROR_THRESHOLD_M) -> float:
    """Perception range of a detected border (``(N, 2)``, world frame, driving order): the
    length (m) of its runs of consecutive points within ``threshold_m`` of the GT
    (``errors_m``, per point), each measured along chords of about ``RANGE_CHORD_M`` so
    that detection noise does not lengthen it. Never negative; the whole length of a
    border that is everywhere within the threshold."""
    return _covered(border, arc_lengths(border), errors_m, threshold_m)


def _covered(border: NDArrayFloat, arc: NDArrayFloat, errors_m: NDArrayFloat,
             threshold_m: float = RANGE_ERROR_THRESHOLD_M) -> float:
    """:func:`covered_length_m` of a border with arc lengths ``arc``."""
    within = errors_m <= threshold_m
    total = 0.0
    edges = np.flatnonzero(np.diff(np.concatenate(([False], within, [False])).astype(np.int8)))
    for first, end in zip(edges[::2].tolist(), edges[1::2].tolist()):
        total += float(np.sum(_chords(border, arc, first, end)[1]))
    return total


def _ahead(border: NDArrayFloat, arc: NDArrayFloat, chords: tuple[NDArrayInt, NDArrayFloat],
           pose: tuple[float, float, float] | None) -> NDArrayFloat:
    """:func:`ahead_of_m` of a border from its arc lengths and the ``_chords`` of all its points."""
    ends, lengths = chords
    along = np.empty(len(lengths) + 1)
    along[0] = 0.0
    np.cumsum(lengths, out=along[1:])
    stations: NDArrayFloat = np.interp(arc, arc[ends], along)
    if pose is None:
        return stations
    x, y, yaw = pose
    start = math.cos(yaw) * (border[0, 0] - x) + math.sin(yaw) * (border[0, 1] - y)
    return stations + max(start, 0.0)


def chord_stations_m(border: NDArrayFloat) -> NDArrayFloat:
    """Each point's distance (m) from the first along a border (``(N, 2)``, driving order),
    measured like ``covered_length_m``: along chords of about ``RANGE_CHORD_M`` between
    which the points are placed by their own arc length, so that detection noise does not
    lengthen it. Non-decreasing, 0 at the first point."""
    return ahead_of_m(border, None)


def ahead_of_m(border: NDArrayFloat, pose: tuple[float, float, float] | None) -> NDArrayFloat:
    """Each point's distance (m) from a vehicle at ``pose`` (x m, y m, yaw rad, world frame)
    along a border (``(N, 2)``, world frame, driving order) that starts at or ahead of it:
    how far ahead of the vehicle its first point lies (its longitudinal coordinate in the
    vehicle frame, 0 when behind; 0 for a detection from the vehicle's own cross-section,
    the minimum range for a sensor that has one) plus :func:`chord_stations_m`. Without a
    pose, from the first point."""
    arc = arc_lengths(border)
    return _ahead(border, arc, _chords(border, arc, 0, len(arc)), pose)


GT_END_TOLERANCE_M: Final[float] = 0.1
"""A detected point more than this (m) past an end of its GT border, along the border's
end direction, lies beyond the GT (one detection sample spacing)."""

OFF_LANE: Final[str] = "off_lane"
"""``Measurement.gt_unmatched``: the lane does not follow the sender's lane (gt_matching)."""
PAST_GT_END: Final[str] = "past_gt_end"
"""``Measurement.gt_unmatched``: detected points lie beyond the end of the GT sequence
(no routing-graph successor where the lane goes on)."""


@dataclass(frozen=True)
class Measurement:
    """A lane measured against its ground truth (world frame, m).

    Fields:
        left_errors_m, right_errors_m: per detected point, the distance to the GT border
            resampled every ``step_m``.
        left_range_m, right_range_m: perception range: length of the detected border
            within ``RANGE_ERROR_THRESHOLD_M`` of the GT (``covered_length_m``).
        left_gt, right_gt: the GT borders (``(M, 2)``) the lane was matched to.
        matched: False when the lane does not follow the sender's lane (see gt_matching).
        gt_unmatched: "" when the GT covers the lane, else why not: ``OFF_LANE`` or
            ``PAST_GT_END``.
        left_ahead_m, right_ahead_m: per detected point, its distance from the sender
            along the border (``ahead_of_m``, m; from the lane's first point without a pose).
    """

    left_errors_m: NDArrayFloat
    right_errors_m: NDArrayFloat
    left_range_m: float
    right_range_m: float
    left_gt: NDArrayFloat
    right_gt: NDArrayFloat
    matched: bool
    gt_unmatched: str = ""
    left_ahead_m: NDArrayFloat = field(default_factory=lambda: np.empty(0))
    right_ahead_m: NDArrayFloat = field(default_factory=lambda: np.empty(0))

    def known_to_m(self, threshold_m: float) -> float:
        """How far from the ego both borders are known within ``threshold_m`` (m): the smaller
        of their ``gt_matching.metrics.known_distance_m``."""
        return min(known_distance_m(self.left_errors_m, self.left_ahead_m, threshold_m),
                   known_distance_m(self.right_errors_m, self.right_ahead_m, threshold_m))

    def near_points(self) -> tuple[int, int]:
        """How many leading points of the left and the right border are near the ego
        (``gt_matching.metrics.near_count``)."""
        return near_count(self.left_ahead_m), near_count(self.right_ahead_m)


#: Vertices next to an end of a GT border searched first for one farther than
#: ``GT_END_TOLERANCE_M`` from it (the border's end direction); the rest only if none is.
END_VERTICES: Final[int] = 8


def _end_direction(end: NDArrayFloat, inner: NDArrayFloat) -> NDArrayFloat | None:
    """Unit vector (world frame) to ``end`` from the first of the vertices ``inner`` (ordered
    away from the end) farther than ``GT_END_TOLERANCE_M`` from it; None when none is."""
    for vertices in (inner[:END_VERTICES], inner[END_VERTICES:]):
        away = end - vertices
        length = np.hypot(*away.T)
        apart = np.flatnonzero(length > GT_END_TOLERANCE_M)
        if apart.size:
            direction: NDArrayFloat = away[apart[0]] / length[apart[0]]
            return direction
    return None


GtEnds = tuple[tuple[NDArrayFloat, NDArrayFloat], ...]
"""The ends of a GT border that have an end direction: (end vertex, unit vector), world frame."""


def gt_ends(gt: NDArrayFloat) -> GtEnds:
    """The last and the first vertex of the polyline ``gt`` with their end directions
    (``_end_direction``), those that have one."""
    found = ((end, _end_direction(end, inner)) for end, inner in ((gt[-1], gt[-2::-1]), (gt[0], gt[1:])))
    return tuple((end, direction) for end, direction in found if direction is not None)


def points_past_ends(points: NDArrayFloat, gt: NDArrayFloat | GtEnds, distances_m: NDArrayFloat,
                     step_m: float) -> int:
    """How many ``points`` (``(N, 2)``, m) lie more than ``GT_END_TOLERANCE_M`` past the
    first or last vertex of the polyline ``gt`` (or its ``gt_ends``) along its end direction
    while that vertex is their nearest GT point (within ``step_m`` of their GT distance
    ``distances_m``)."""
    count = 0
    for end, direction in gt_ends(gt) if isinstance(gt, np.ndarray) else gt:
        offset = points - end
        past = np.flatnonzero(offset @ direction > GT_END_TOLERANCE_M)
        if past.size:
            count += int(np.count_nonzero(np.hypot(*offset[past].T) <= distances_m[past] + step_m))
    return count


FIGURE_BORDERS: Final[int] = 32
"""Detected borders :func:`border_figures` takes in one pass: the arrays of their points
(about 800 each) then stay in a core's cache; a block's 200 at once run a quarter slower."""


def border_figures(borders: Sequence[NDArrayFloat], errors_m: Sequence[NDArrayFloat],
                   poses: Sequence[tuple[float, float, float] | None], gt: GtEnds, step_m: float
                   ) -> list[tuple[int, float, NDArrayFloat]]:
    """Per detected border (``(N >= 2, 2)``, world frame, driving order; ``errors_m`` its
    points' GT distances, m; its sender's pose or None), against one GT border (its
    ``gt_ends``): :func:`points_past_ends`, :func:`covered_length_m` and
    :func:`ahead_of_m`, bit for bit, in passes over up to ``FIGURE_BORDERS`` borders."""
    return [figures for first in range(0, len(borders), FIGURE_BORDERS)
            for figures in _border_figures(borders[first:first + FIGURE_BORDERS],
                                           errors_m[first:first + FIGURE_BORDERS],
                                           poses[first:first + FIGURE_BORDERS], gt, step_m)]


def _border_figures(borders: Sequence[NDArrayFloat], errors_m: Sequence[NDArrayFloat],
                    poses: Sequence[tuple[float, float, float] | None], gt: GtEnds, step_m: float
                    ) -> list[tuple[int, float, NDArrayFloat]]:
    """:func:`border_figures` of some borders in one pass: arc lengths and chords of all at
    once, the end check only for the borders that come near an end vertex."""
    counts = np.array([len(border) for border in borders])
    starts = np.cumsum(counts) - counts
    lasts = starts + counts - 1
    points = borders[0] if len(borders) == 1 else np.concatenate(borders)
    errors = errors_m[0] if len(errors_m) == 1 else np.concatenate(errors_m)
    owner = np.repeat(np.arange(len(borders)), counts)
    # A point past an end lies within its GT distance plus a step of it: not beside a
    # border's bounding box grown by its largest GT distance plus two steps (one for rounding).
    reach = np.fmax.reduceat(errors, starts)[:, None] + 2.0 * step_m
    low, high = np.minimum.reduceat(points, starts) - reach, np.maximum.reduceat(points, starts) + reach
    near_end = np.zeros(len(borders), dtype=bool)
    for end, _ in gt:
        near_end |= np.all((low <= end) & (end <= high), axis=1)
    beyond = np.zeros(len(borders), dtype=bool)
    beyond[owner[~(errors <= RANGE_ERROR_THRESHOLD_M)]] = True
    arc = arc_lengths_many(list(borders), points)
    stations = _chord_numbers(arc)
    is_end = np.empty(len(points), dtype=bool)
    np.not_equal(stations[1:], stations[:-1], out=is_end[1:])
    is_end[starts] = True
    is_end[lasts] = True
    ends = np.flatnonzero(is_end)
    paired = np.ones(len(points), dtype=bool)
    paired[lasts] = False  # a chord joins two ends of the same border
    chord_of = paired[ends[:-1]]
    first, second = ends[:-1][chord_of], ends[1:][chord_of]
    step = points[second] - points[first]
    lengths = np.hypot(step[:, 0], step[:, 1])
    chords = np.bincount(owner[ends], minlength=len(borders)) - 1
    figures = []
    chord_start = 0
    for index, (border, border_errors, pose) in enumerate(zip(borders, errors_m, poses)):
        start, count, chord_count = int(starts[index]), int(counts[index]), int(chords[index])
        border_arc = arc[start:start + count]
        past = points_past_ends(border, gt, border_errors, step_m) if near_end[index] else 0
        chord_lengths = lengths[chord_start:chord_start + chord_count]
        covered = _covered(border, border_arc, border_errors) if beyond[index] else float(chord_lengths.sum())
        border_ends = ends[chord_start + index:chord_start + index + chord_count + 1] - start
        figures.append((past, covered, _ahead(border, border_arc, (border_ends, chord_lengths), pose)))
        chord_start += chord_count
    return figures


class GroundTruthMeter:
    """Closest-point errors of lanes against a ``gt_matching.GroundTruth``
    (``GroundTruth.errors``: per-point distances to the GT borders resampled every
    ``step_m``, samples cached per lanelet; without the other-lane check, which the
    reports do not use). Matches of the last few reference lanes are kept: the scenarios
    of a frame share their coops' true lanes."""

    def __init__(self, ground_truth: GroundTruth) -> None:
        self.ground_truth = ground_truth
        self.step_m = ground_truth.config.step_m
        self._matches: OrderedDict[tuple[bytes, bytes, tuple[float, float, float]], LaneMatch] = OrderedDict()
        self._gt_ends: OrderedDict[tuple[tuple[tuple[int, bool], ...], str], GtEnds] = OrderedDict()

    def match(self, left: NDArrayFloat, right: NDArrayFloat, pose: tuple[float, float, float]) -> LaneMatch:
        """The GT lanelets and borders of a lane (``gt_matching.GroundTruth.match``), from
        the cache when the same borders and pose were matched lately."""
        left, right = np.asarray(left, dtype=np.float64), np.asarray(right, dtype=np.float64)
        key = (left.tobytes(), right.tobytes(), tuple(pose))
        return lru_get(self._matches, key, lambda: self.ground_truth.match(left, right, pose), MATCH_CACHE_SIZE)

    def match_many(self, lanes: Sequence[tuple[NDArrayFloat, NDArrayFloat, tuple[float, float, float]]]
                   ) -> list[LaneMatch | MatchingError]:
        """:meth:`match` of each lane (left, right, pose), or its ``gt_matching.MatchingError``:
        those not matched lately matched together (``GroundTruth.match_many``), each once."""
        from gt_matching import MatchingError

        keys = []
        made: dict[tuple[int, int, tuple[float, float, float]], tuple[bytes, bytes, tuple[float, float, float]]] = {}
        for left, right, pose in lanes:
            left, right = np.asarray(left, dtype=np.float64), np.asarray(right, dtype=np.float64)
            # The scenarios of a frame pass the same reference arrays (alive in ``keys``: ids stay theirs).
            ids = (id(left), id(right), tuple(pose))
            key = made.get(ids)
            if key is None:
                key = made[ids] = (left.tobytes(), right.tobytes(), tuple(pose))
            keys.append((key, (left, right, pose)))
        known = {key: self._matches[key] for key, _ in keys if key in self._matches}
        missing = {key: lane for key, lane in keys if key not in known}
        known.update(zip(missing, self.ground_truth.match_many(list(missing.values()))))
        for key, _ in keys:
            if not isinstance(known[key], MatchingError):
                lru_get(self._matches, key, lambda: known[key], MATCH_CACHE_SIZE)
        return [known[key] for key, _ in keys]

    def errors(self, match: LaneMatch, left: NDArrayFloat, right: NDArrayFloat,
               pose: tuple[float, float, float] | None = None) -> Measurement:
        """Closest-point errors and range of a lane against the GT borders of ``match``; the
        points' distances from the sender at ``pose`` (x m, y m, yaw rad; None: from the
        lane's first points) by :func:`ahead_of_m`. Raises ``gt_matching.MatchingError``."""
        lane = (as_polyline("left border", left), as_polyline("right border", right))
        return self._measured([match], [lane], [pose])[0]

    def measure_many(self, lanes: Sequence[Lane]) -> list[Measurement | MatchingError]:
        """:meth:`measure` of each lane (left, right, pose, reference), or its
        ``gt_matching.MatchingError``: the lanes matched to the same GT lanelets (the lanes
        of a block of frames on one route) measured in one pass per GT border, bit for bit
        as one by one."""
        from gt_matching import MatchingError

        found: list[Measurement | MatchingError | None] = [None] * len(lanes)
        routes: dict[tuple[tuple[int, bool], ...], list[tuple[int, LaneMatch, tuple[NDArrayFloat, NDArrayFloat]]]] = {}
        matches = self.match_many([(*(reference or (left, right)), pose) for left, right, pose, reference in lanes])
        for index, ((left, right, _, _), match) in enumerate(zip(lanes, matches)):
            if isinstance(match, MatchingError):
                found[index] = match
                continue
            try:
                lane = (as_polyline("left border", left), as_polyline("right border", right))
            except MatchingError as exc:
                found[index] = exc
                continue
            routes.setdefault(match.route_key, []).append((index, match, lane))
        for members in routes.values():
            measured = self._measured([match for _, match, _ in members], [lane for _, _, lane in members],
                                      [lanes[index][2] for index, _, _ in members])
            for (index, _, _), measurement in zip(members, measured):
                found[index] = measurement
        return [item for item in found if item is not None]

    def _measured(self, matches: list[LaneMatch], lanes: list[tuple[NDArrayFloat, NDArrayFloat]],
                  poses: Sequence[tuple[float, float, float] | None]) -> list[Measurement]:
        """:meth:`errors` of validated lanes against matches of one GT lanelet sequence."""
        distances = self.ground_truth.resampled(matches[0], lanes)
        left, right = (border_figures([lane[column] for lane in lanes], [found[column] for found in distances], poses,
                                      self._ends(matches[0], side), self.step_m)
                       for column, side in ((0, "left"), (1, "right")))
        measured = []
        for match, (left_errors, right_errors), (left_past, left_range, left_ahead), \
                (right_past, right_range, right_ahead) in zip(matches, distances, left, right):
            reason = OFF_LANE if not match.matched else PAST_GT_END if left_past + right_past else ""
            measured.append(Measurement(left_errors, right_errors, left_range, right_range, match.left_gt,
                                        match.right_gt, match.matched, reason, left_ahead, right_ahead))
        return measured

    def _ends(self, match: LaneMatch, side: str) -> GtEnds:
        """``gt_ends`` of the ``side`` GT border of ``match`` (kept per route, LRU)."""
        return lru_get(self._gt_ends, (match.route_key, side),
                       lambda: gt_ends(match.left_gt if side == "left" else match.right_gt), ENDS_CACHE_SIZE)

    def measure(self, left: NDArrayFloat, right: NDArrayFloat, pose: tuple[float, float, float], *,
                reference: tuple[NDArrayFloat, NDArrayFloat] | None = None) -> Measurement:
        """Errors of a lane (borders ``(N, 2)`` world frame, driving order) whose sender
        stands at ``pose`` (x m, y m, yaw rad). The GT lanelets are those matched to
        ``reference`` (the borders of the lane the vehicles truly drive, from the drive),
        or to the lane itself; the errors are always against Lanelet2's borders. Raises
        ``gt_matching.MatchingError``."""
        return self.errors(self.match(*(reference or (left, right)), pose), left, right, pose)
