"""Polyline primitives in the world frame: validation, arc length, resampling,
simplification (Douglas-Peucker: :func:`simplify` keeps vertex indices, for the converter's
shared nodes; :func:`simplify_lines` many display lines at once through shapely, for the
recording) and vectorised closest-point distances to polyline segments. The one home of
these helpers: the converter, the recording and the lane strips use them too."""

from __future__ import annotations

from itertools import chain
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from gt_matching.errors import MatchingError

NDArrayFloat = npt.NDArray[np.float64]
NDArrayInt = npt.NDArray[np.int64]
NDArrayBool = npt.NDArray[np.bool_]

#: Segments shorter than this are treated as zero-length (a repeated vertex), m.
ZERO_LENGTH_M: Final = 1e-12
#: Longest piece (m) of a segment in ``SegmentIndex``'s KD-tree of piece midpoints.
INDEX_PIECE_M: Final = 0.5
#: Nearest piece midpoints ``SegmentIndex.capped`` asks its KD-tree for at once (on
#: Town01's tie-breaks all but about 3 points in 1000 have fewer within their search radius).
CAPPED_NEIGHBOURS: Final = 6
#: Slack (m) on ``SegmentIndex.capped``'s search radius: covers the rounding of the
#: distances it is built from, so the closest segment is never left out.
CAP_MARGIN_M: Final = 1e-6


def as_polyline(name: str, points: npt.ArrayLike) -> NDArrayFloat:
    """``points`` as a ``(N, 2)`` float64 polyline with N >= 2, finite and of positive length.

    Raises ``MatchingError`` naming ``name`` otherwise.
    """
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MatchingError(f"{name}: not a numeric (N, 2) array ({exc})") from exc
    if array.ndim != 2 or array.shape[1] != 2:
        raise MatchingError(f"{name}: expected an (N, 2) array, got shape {array.shape}")
    if array.shape[0] < 2:
        raise MatchingError(f"{name}: needs at least 2 points, got {array.shape[0]}")
    if not np.isfinite(array).all():
        bad = int(np.argmax(~np.all(np.isfinite(array), axis=1)))
        raise MatchingError(f"{name}: point {bad} is not finite ({array[bad].tolist()})")
    # The last point apart from the first settles it without a pass over the others.
    apart = float(np.abs(array[-1] - array[0]).max()) > ZERO_LENGTH_M
    if not apart and float(np.abs(array - array[0]).max()) <= ZERO_LENGTH_M:
        raise MatchingError(f"{name}: all {array.shape[0]} points coincide (zero length)")
    return array


def arc_lengths(polyline: NDArrayFloat) -> NDArrayFloat:
    """Cumulative arc length at each vertex, m; starts at 0."""
    polyline = np.asarray(polyline)
    step = polyline[1:] - polyline[:-1]
    cum = np.empty(max(len(polyline), 1))
    cum[0] = 0.0
    np.cumsum(np.hypot(step[:, 0], step[:, 1]), out=cum[1:])
    return cum


def resample(polyline: NDArrayFloat, step_m: float) -> tuple[NDArrayFloat, NDArrayInt]:
    """Points every ``step_m`` along ``polyline`` (both ends included; the last gap may be
    shorter) and, for each, the index of the segment it lies on. A zero-length polyline
    gives its first point. ``polyline`` needs at least 2 vertices."""
    points, segments, _ = _resampled([np.asarray(polyline)], step_m)
    return points, segments


def resample_many(polylines: list[NDArrayFloat], step_m: float) -> list[NDArrayFloat]:
    """``resample(polyline, step_m)[0]`` of each polyline (at least 2 vertices), bit for bit."""
    points, _, sizes = _resampled(polylines, step_m)
    return np.split(points, np.cumsum(sizes)[:-1])


def _resampled(polylines: list[NDArrayFloat], step_m: float) -> tuple[NDArrayFloat, NDArrayInt, list[int]]:
    """``resample`` of each polyline, concatenated: the points, the index of each one's
    segment among all the polylines' vertices, and how many points each polyline has. The
    arc lengths go line by line, the stations (``np.arange``'s values and length), segment
    searches and interpolation of all in one pass."""
    counts = np.array([len(polyline) for polyline in polylines], dtype=np.int64)
    vertices = np.concatenate(polylines)
    step = vertices[1:] - vertices[:-1]
    lengths = np.hypot(step[:, 0], step[:, 1])
    cum = np.empty(len(vertices))
    firsts = np.cumsum(counts) - counts
    for first, count in zip(firsts.tolist(), counts.tolist()):
        cum[first] = 0.0
        np.cumsum(lengths[first:first + count - 1], out=cum[first + 1:first + count])
    total = cum[firsts + counts - 1]
    flat = total <= ZERO_LENGTH_M
    arange_sizes = np.where(flat, 1, np.ceil(total / step_m)).astype(np.int64)  # np.arange(0.0, total, step_m)'s
    closed = ~flat & (total - (arange_sizes - 1) * step_m > ZERO_LENGTH_M)  # the end appended
    sizes = arange_sizes + closed
    line = np.repeat(np.arange(len(counts)), sizes)
    within = np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    s = within * step_m  # np.arange's i-th value: 0.0 + i * step_m
    s[(np.cumsum(sizes) - 1)[closed]] = total[closed]
    # each station's place in its own line's arc lengths: (line, arc length) pairs as complex numbers, in order
    found = np.searchsorted(np.repeat(np.arange(len(counts)), counts) + 1j * cum, line + 1j * s, side="right")
    seg = firsts[line] + np.clip(found - firsts[line] - 1, 0, counts[line] - 2)
    seg[flat[line]] = firsts[line][flat[line]]
    seg_len = cum[seg + 1] - cum[seg]
    t = np.divide(s - cum[seg], seg_len, out=np.zeros_like(s), where=seg_len > ZERO_LENGTH_M)
    points = vertices[seg] + np.clip(t, 0.0, 1.0)[:, None] * (vertices[seg + 1] - vertices[seg])
    at_first = flat[line]
    points[at_first] = vertices[seg[at_first]]  # a zero-length polyline: its first point as it is
    return points, seg, sizes.tolist()


def segment_distances(
    points: NDArrayFloat, vertices: NDArrayFloat, segments: NDArrayInt, cum: NDArrayFloat | None = None
) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Closest-point distance of each point to a set of candidate segments of ``vertices``.

    ``segments`` is ``(N, K)``: for point i the indices of K candidate segments
    (segment j joins vertex j and j + 1). Returns the smallest distance per point, m,
    and the arc length along ``vertices`` of the closest point, m (``cum``: the arc length
    of each vertex, default ``arc_lengths(vertices)``).
    """
    cum = arc_lengths(vertices) if cum is None else cum
    dist, t, length_sq = _candidate_distances(points, vertices, segments)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    best_seg = segments[rows, best]
    s = cum[best_seg] + t[rows, best] * np.sqrt(length_sq[rows, best])
    return dist[rows, best], s


def _candidate_distances(points: NDArrayFloat, vertices: NDArrayFloat, segments: NDArrayInt
                         ) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Per point and candidate segment (``segments``: ``(N, K)``, as in
    :func:`segment_distances`), ``(N, K)``: the distance to the segment (m), where its
    closest point lies along it (0 at its start, 1 at its end) and its squared length (m²)."""
    start = vertices[segments]
    delta = vertices[segments + 1] - start
    length_sq = np.einsum("nkd,nkd->nk", delta, delta)
    rel = points[:, None, :] - start
    dot = np.einsum("nkd,nkd->nk", rel, delta)
    t = np.clip(np.divide(dot, length_sq, out=np.zeros_like(dot), where=length_sq > 0.0), 0.0, 1.0)
    gap = rel - t[..., None] * delta
    dist: NDArrayFloat = np.hypot(gap[..., 0], gap[..., 1])
    return dist, t, length_sq


def closest_distances(points: NDArrayFloat, vertices: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Exact closest-point distance (m) and arc length (m) of each point on ``vertices``,
    brute force over all segments: O(N * M), for short inputs."""
    all_segments = np.broadcast_to(np.arange(len(vertices) - 1), (len(points), len(vertices) - 1))
    return segment_distances(points, vertices, all_segments)


def arc_lengths_many(polylines: list[NDArrayFloat], joined: NDArrayFloat | None = None) -> NDArrayFloat:
    """``arc_lengths`` of each polyline (at least 2 vertices), bit for bit, concatenated: the
    segment lengths of all at once, the running sums line by line (``joined``: the
    polylines concatenated, if at hand)."""
    if len(polylines) == 1:
        return arc_lengths(polylines[0])
    vertices = np.concatenate(polylines) if joined is None else joined
    step = vertices[1:] - vertices[:-1]
    lengths = np.hypot(step[:, 0], step[:, 1])
    cum = np.empty(len(vertices))
    first = 0
    for polyline in polylines:
        end = first + len(polyline)
        cum[first] = 0.0
        np.cumsum(lengths[first:end - 1], out=cum[first + 1:end])
        first = end
    return cum


def closest_many(points: NDArrayFloat, polylines: list[NDArrayFloat], cum: NDArrayFloat | None = None
                 ) -> tuple[NDArrayFloat, NDArrayFloat]:
    """``closest_distances`` of each point (``(L, 2)``) on its polyline (``L`` of them, at
    least 2 vertices each), bit for bit, all in one pass: distance (m) and arc length (m)
    (``cum``: the polylines' ``arc_lengths_many``, if at hand)."""
    counts = np.array([len(polyline) for polyline in polylines])
    starts = np.cumsum(counts) - counts
    segments = np.minimum(starts[:, None] + np.arange(int(counts.max()) - 1), (starts + counts - 2)[:, None])
    vertices = np.concatenate(polylines)
    return segment_distances(points, vertices, segments, arc_lengths_many(polylines, vertices) if cum is None else cum)


def _flattened(found: Any) -> tuple[NDArrayInt, NDArrayInt]:
    """The lists of indices of a KD-tree's ``query_ball_point`` (one per point): how many
    each holds, and all of them in order."""
    counts = np.fromiter(map(len, found), dtype=np.int64, count=len(found))
    return counts, np.fromiter(chain.from_iterable(found), dtype=np.int64, count=int(counts.sum()))


class SegmentIndex:
    """The segments of a polyline (``(M >= 2, 2)`` vertices, m) indexed for distances
    capped at a bound (KD-trees built on first use): :meth:`capped` gives
    ``np.minimum(closest_distances(points, vertices)[0], cap_m)`` bit for bit while
    measuring only the segments that can be the closest. Each segment is cut into pieces of
    at most ``INDEX_PIECE_M`` whose midpoints stand for it in a KD-tree: a segment is no
    nearer to a point than its nearest piece midpoint minus half a piece."""

    def __init__(self, vertices: NDArrayFloat) -> None:
        self.vertices = vertices
        self._trees: tuple[Any, NDArrayInt] | None = None

    def _index(self) -> tuple[Any, NDArrayInt]:
        """KD-tree of the piece midpoints, and each piece's segment."""
        if self._trees is None:
            from scipy.spatial import cKDTree

            start, delta = self.vertices[:-1], np.diff(self.vertices, axis=0)
            pieces = np.maximum(1, np.ceil(np.hypot(*delta.T) / INDEX_PIECE_M)).astype(np.int64)
            segment = np.repeat(np.arange(len(delta)), pieces)
            within = np.arange(len(segment)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
            middles = start[segment] + ((within + 0.5) / pieces[segment])[:, None] * delta[segment]
            self._trees = cKDTree(middles), segment
        return self._trees

    def capped(self, points: NDArrayFloat, cap_m: float) -> NDArrayFloat:
        """Per point, its exact closest-point distance to the polyline or ``cap_m`` if that
        is smaller, m. The closest segment is no farther than the nearest piece midpoint's
        segment, so it has a piece midpoint within a radius of the smaller of ``cap_m`` and
        that segment's distance, plus half a piece (and a micrometre for rounding). The
        segments of the ``CAPPED_NEIGHBOURS`` nearest piece midpoints are measured, those of
        midpoints within the radius kept; a point whose every one of those lies within the
        radius may have more there, and takes all of them (:meth:`_within`)."""
        by_piece, segment = self._index()
        count = min(CAPPED_NEIGHBOURS, len(segment))
        gaps, nearest = by_piece.query(points, k=list(range(1, count + 1)))
        to_pieces = _candidate_distances(points, self.vertices, segment[nearest])[0]
        bound = to_pieces[:, 0]
        radius = np.minimum(bound, cap_m) + (INDEX_PIECE_M / 2.0 + CAP_MARGIN_M)
        within = gaps <= radius[:, None]
        capped: NDArrayFloat = np.minimum(np.where(within, to_pieces, bound[:, None]).min(axis=1), cap_m)
        more = np.flatnonzero(within[:, -1]) if count < len(segment) else []
        if len(more):
            capped[more] = self._within(points[more], radius[more], cap_m)
        return capped

    def _within(self, points: NDArrayFloat, radius: NDArrayFloat, cap_m: float) -> NDArrayFloat:
        """Per point, the smallest of ``cap_m`` and its distances (m) to the segments with a
        piece midpoint within its ``radius`` (m): ``cap_m`` when none has."""
        by_piece, segment = self._index()
        counts, flat = _flattened(by_piece.query_ball_point(points, r=radius))
        found = np.full(len(points), cap_m)
        rows = np.flatnonzero(counts)
        if len(rows):
            counts = counts[rows]
            starts = np.cumsum(counts) - counts
            pieces = flat[np.minimum(starts[:, None] + np.arange(int(counts.max())), (starts + counts - 1)[:, None])]
            found[rows] = np.minimum(_candidate_distances(points[rows], self.vertices, segment[pieces])[0].min(axis=1),
                                     cap_m)
        return found


def nearest_distances(points: NDArrayFloat, vertices: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Exact closest-point distance (m) and arc length (m) of each point on the whole
    polyline ``vertices`` (rings, short and self-approaching polylines included): only the
    segments whose midpoint lies within the distance to the nearest vertex plus the
    longest half segment can be closer, and those are all measured."""
    from scipy.spatial import cKDTree

    if len(vertices) < 2:
        raise ValueError("nearest_distances needs a polyline of at least two vertices")
    mids = 0.5 * (vertices[1:] + vertices[:-1])
    half = 0.5 * float(np.max(np.hypot(*(vertices[1:] - vertices[:-1]).T)))
    to_vertex = cKDTree(vertices).query(points)[0]
    candidates = cKDTree(mids).query_ball_point(points, r=to_vertex + half + 1e-9)
    counts, segment = _flattened(candidates)
    owner = np.repeat(np.arange(len(points)), counts)
    start = vertices[segment]
    delta = vertices[segment + 1] - start
    length_sq = np.einsum("nd,nd->n", delta, delta)
    rel = points[owner] - start
    along = np.clip(np.divide(np.einsum("nd,nd->n", rel, delta), length_sq, out=np.zeros(len(segment)),
                              where=length_sq > 0.0), 0.0, 1.0)
    gap = rel - along[:, None] * delta
    distance = np.hypot(gap[:, 0], gap[:, 1])
    order = np.lexsort((distance, owner))
    first = order[np.searchsorted(owner[order], np.arange(len(points)))]
    cum = arc_lengths(vertices)
    return distance[first], cum[segment[first]] + along[first] * np.sqrt(length_sq[first])


def windowed_distances(
    points: NDArrayFloat, vertices: NDArrayFloat, near_arc_m: NDArrayFloat, reach_m: float
) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Exact closest-point distance (m) and arc length (m) of each point on ``vertices``,
    searching the segments within ``reach_m`` of arc length ``near_arc_m`` (per point; e.g.
    that of its closest resampled point, with ``reach_m`` >= the resampling step)."""
    cum = arc_lengths(vertices)
    first = np.clip(np.searchsorted(cum, near_arc_m - reach_m, side="right") - 1, 0, len(vertices) - 2)
    last = np.clip(np.searchsorted(cum, near_arc_m + reach_m, side="left"), 1, len(vertices) - 1) - 1
    span = int(np.max(last - first)) + 1
    segments = np.minimum(first[:, None] + np.arange(span), last[:, None])
    return segment_distances(points, vertices, segments, cum)


def angle_difference(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi], rad."""
    return abs((a - b + np.pi) % (2.0 * np.pi) - np.pi)


def at_fractions(polyline: NDArrayFloat, fractions: NDArrayFloat, cum: NDArrayFloat | None = None) -> NDArrayFloat:
    """Points at the given fractions (0..1) of the polyline's length, m (``cum``: its
    ``arc_lengths`` if known)."""
    cum = arc_lengths(polyline) if cum is None else cum
    s = fractions * cum[-1]
    points = np.empty((len(s), 2))
    points[:, 0] = np.interp(s, cum, polyline[:, 0])
    points[:, 1] = np.interp(s, cum, polyline[:, 1])
    return points


def paired_fractions(left: NDArrayFloat, right: NDArrayFloat, step_m: float) -> NDArrayFloat:
    """Fractions that sample two borders about every ``step_m`` of the longer one (>= 2)."""
    return _fractions(max(arc_lengths(left)[-1], arc_lengths(right)[-1]), step_m)


def _fractions(longer_m: float, step_m: float) -> NDArrayFloat:
    return np.linspace(0.0, 1.0, max(2, int(np.ceil(longer_m / step_m)) + 1))


def mid_line(left: NDArrayFloat, right: NDArrayFloat, step_m: float) -> NDArrayFloat:
    """Mid-line of two borders, sampled at equal fractions of their lengths, about every
    ``step_m`` of the longer border (at least 2 points), m."""
    left_cum, right_cum = arc_lengths(left), arc_lengths(right)
    fractions = _fractions(max(left_cum[-1], right_cum[-1]), step_m)
    return 0.5 * (at_fractions(left, fractions, left_cum) + at_fractions(right, fractions, right_cum))


def simplify(points: NDArrayFloat, tolerance: float) -> NDArrayBool:
    """Douglas-Peucker: which vertices of the polyline ``points`` (N, 2) to keep so that no
    dropped vertex is farther than ``tolerance`` (m) from the kept polyline. The ends are
    always kept."""
    keep = np.zeros(len(points), dtype=bool)
    keep[[0, -1]] = True
    pending = [(0, len(points) - 1)]
    while pending:
        first, last = pending.pop()
        if last - first < 2:
            continue
        chord = points[last] - points[first]
        rel = points[first + 1 : last] - points[first]
        length_sq = float(chord @ chord)
        along = np.clip(rel @ chord / length_sq, 0.0, 1.0) if length_sq > 0.0 else np.zeros(len(rel))
        gap = rel - along[:, None] * chord
        offsets = np.hypot(gap[:, 0], gap[:, 1])
        worst = int(np.argmax(offsets))
        if offsets[worst] > tolerance:
            split = first + 1 + worst
            keep[split] = True
            pending.extend(((first, split), (split, last)))
    return keep


def simplify_lines(lines: list[NDArrayFloat], tolerance_m: float) -> list[NDArrayFloat]:
    """Douglas-Peucker (shapely/GEOS, all lines in one call): each ``(N >= 2, 2)`` polyline's
    vertices such that no dropped one is farther than ``tolerance_m`` from the kept line;
    the ends are kept."""
    if not lines:
        return []
    coordinates, counts = simplify_joined(lines, tolerance_m)
    return np.split(coordinates, np.cumsum(counts)[:-1])


def simplify_joined(lines: list[NDArrayFloat], tolerance_m: float) -> tuple[NDArrayFloat, NDArrayInt]:
    """:func:`simplify_lines` of at least one line as one ``(M, 2)`` array of the kept
    vertices, line after line, and the number kept of each line."""
    import shapely

    counts = [len(line) for line in lines]
    geometries = shapely.linestrings(np.vstack(lines), indices=np.repeat(np.arange(len(lines)), counts))
    with np.errstate(divide="ignore", invalid="ignore"):  # GEOS on a zero-length line: kept as is
        simple = shapely.simplify(geometries, tolerance_m, preserve_topology=False)
    coordinates, owner = shapely.get_coordinates(simple, return_index=True)
    return coordinates, np.bincount(owner, minlength=len(lines))
