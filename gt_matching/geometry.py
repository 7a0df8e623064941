"""Numpy geometry of a Lanelet2 map, extracted once per map: lanelet borders and
mid-lines, and every border line string of the map with its bounding box and samples."""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from itertools import chain
from operator import attrgetter
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from gt_matching.errors import MatchingError
from gt_matching.lru import lru_get
from gt_matching.polyline import NDArrayFloat, NDArrayInt, arc_lengths, mid_line, resample, resample_many

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Sampling distance of lanelet mid-lines (scoring lanelet sequences), m.
CENTRE_STEP_M: Final = 0.1
#: Coarse sampling distance of all lines (finding the lines near a border), m.
COARSE_STEP_M: Final = 0.5
#: Coarse samples per chunk (a chunk is found or not as a whole).
CHUNK_SAMPLES: Final = 20

_XY: Final = attrgetter("x", "y")
"""A Lanelet2 point's x, y (m)."""

LaneletKey = tuple[int, bool]
"""A lanelet as (id, inverted): a bidirectional lanelet is driven in either orientation."""


def line_xy(line: Any, owner: str) -> NDArrayFloat:
    """x, y of a Lanelet2 line string as an ``(N, 2)`` array in its own orientation (read
    point by point: lanelet2's Python bindings have no bulk accessor; in C-level loops)."""
    points = np.fromiter(chain.from_iterable(map(_XY, line)), np.float64, count=2 * len(line)).reshape(-1, 2)
    if len(points) < 2 or not np.all(np.isfinite(points)):
        raise MatchingError(f"line string {line.id} of {owner} needs >= 2 finite points, got {points.tolist()}")
    return points


@dataclass(frozen=True, eq=False)
class LaneletGeometry:
    """One lanelet in one driving orientation, world frame, vertices in driving order.

    Fields:
        lanelet: the Lanelet2 ``ConstLanelet`` (routing-graph queries take it).
        key: (id, inverted).
        left, right: border vertices, m.
        left_line, right_line: ids of the border line strings.
        centre: mid-line of the borders every <= ``CENTRE_STEP_M``, m (Lanelet2's own
            centreline costs O(N^2) on densely sampled borders).
        centre_arc_m: arc length of each ``centre`` vertex, m.
        length_m: mid-line length, m.
        centre_tree: KD-tree of ``centre``.
    """

    lanelet: Any
    key: LaneletKey
    left: NDArrayFloat
    right: NDArrayFloat
    left_line: int
    right_line: int
    centre: NDArrayFloat
    centre_arc_m: NDArrayFloat
    length_m: float
    centre_tree: cKDTree

    @classmethod
    def of(cls, lanelet: Any) -> LaneletGeometry:
        """Numpy geometry of a Lanelet2 lanelet (either orientation)."""
        from scipy.spatial import cKDTree

        owner = f"lanelet {lanelet.id}"
        left, right = line_xy(lanelet.leftBound, owner), line_xy(lanelet.rightBound, owner)
        centre = mid_line(left, right, CENTRE_STEP_M)
        centre_arc = arc_lengths(centre)
        return cls(
            lanelet=lanelet,
            key=(int(lanelet.id), bool(lanelet.inverted())),
            left=left,
            right=right,
            left_line=int(lanelet.leftBound.id),
            right_line=int(lanelet.rightBound.id),
            centre=centre,
            centre_arc_m=centre_arc,
            length_m=float(centre_arc[-1]),
            centre_tree=cKDTree(centre),
        )

    def centre_nearest(self, points: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayInt]:
        """Distance of each point to the closest ``centre`` vertex, m (at most
        ``sqrt(d**2 + (CENTRE_STEP_M / 2)**2)`` for a distance d to the mid-line), and
        that vertex's index."""
        distances, index = self.centre_tree.query(points)
        return distances, index

    def locate(self, xy: tuple[float, float]) -> tuple[float, float]:
        """Arc length (m) of the mid-line vertex closest to ``xy`` and the mid-line heading
        there (rad)."""
        index = int(self.centre_tree.query(xy)[1])
        ahead = min(index + 1, len(self.centre) - 1)
        behind = ahead - 1
        dx, dy = self.centre[ahead] - self.centre[behind]
        return float(self.centre_arc_m[index]), float(np.arctan2(dy, dx))


class MapLines:
    """Every border line string of a map, each once, in its stored orientation: vertices,
    samples every ``COARSE_STEP_M`` grouped in chunks of ``CHUNK_SAMPLES`` (to find the
    pieces of lines near a place), and samples every ``step_m`` with their KD-trees (of at
    most ``cache_size`` lines, the latest used, when given)."""

    def __init__(self, lanelet_map: Any, *, cache_size: int | None = None) -> None:
        from scipy.spatial import cKDTree

        self.slot_of_line: dict[int, int] = {}
        self.vertices: list[NDArrayFloat] = []
        for lanelet in lanelet_map.laneletLayer:
            for line in (lanelet.leftBound, lanelet.rightBound):
                if line.id not in self.slot_of_line:
                    self.slot_of_line[line.id] = len(self.vertices)
                    self.vertices.append(line_xy(line, f"lanelet {lanelet.id}"))
        if not self.vertices:
            raise MatchingError("lanelet map has no lanelets")
        coarse = resample_many(self.vertices, COARSE_STEP_M)
        #: Samples every COARSE_STEP_M of all lines, and the slot of each.
        self.coarse: NDArrayFloat = np.concatenate(coarse)
        self.coarse_owner: NDArrayInt = np.repeat(np.arange(len(coarse)), [len(c) for c in coarse])
        sizes = np.array([len(c) for c in coarse])
        chunks = -(-sizes // CHUNK_SAMPLES)
        within = np.concatenate([np.arange(0, size, CHUNK_SAMPLES) for size in sizes])
        line_start = np.repeat(np.cumsum(sizes) - sizes, chunks)
        self._chunk_start = line_start + within
        self._chunk_stop = line_start + np.minimum(within + CHUNK_SAMPLES, np.repeat(sizes, chunks))
        counts = self._chunk_stop - self._chunk_start
        centres = np.add.reduceat(self.coarse, self._chunk_start, axis=0) / counts[:, None].astype(np.float64)
        self._chunk_radius = float(np.max(np.hypot(*(self.coarse - np.repeat(centres, counts, axis=0)).T)))
        self._chunk_tree = cKDTree(centres)
        self._samples: OrderedDict[tuple[int, float], NDArrayFloat] = OrderedDict()
        self._trees: OrderedDict[tuple[int, float], cKDTree] = OrderedDict()
        self._cache_size = cache_size

    def slots(self, lines: set[int]) -> NDArrayInt:
        """Slots of the given line string ids that belong to the map."""
        return np.array([self.slot_of_line[line] for line in lines if line in self.slot_of_line], dtype=np.int64)

    def coarse_near(self, points: NDArrayFloat, reach_m: float) -> NDArrayInt:
        """Indices into ``coarse`` of every sample within ``reach_m`` of a point (and of
        some farther ones: whole chunks are returned)."""
        near = self._chunk_tree.query_ball_point(points, reach_m + self._chunk_radius)
        chunks = np.unique(np.concatenate([np.asarray(n, dtype=np.int64) for n in near]))
        if len(chunks) == 0:
            return np.empty(0, dtype=np.int64)
        lengths = self._chunk_stop[chunks] - self._chunk_start[chunks]
        first = np.cumsum(lengths) - lengths
        return np.repeat(self._chunk_start[chunks] - first, lengths) + np.arange(lengths.sum())

    def tree(self, slot: int, step_m: float) -> cKDTree:
        """KD-tree of the samples every ``step_m`` of line ``slot`` (cached)."""
        from scipy.spatial import cKDTree

        return lru_get(self._trees, (slot, step_m), lambda: cKDTree(self.samples(slot, step_m)), self._cache_size)

    def samples(self, slot: int, step_m: float) -> NDArrayFloat:
        """Points every ``step_m`` along line ``slot`` (cached)."""
        return lru_get(self._samples, (slot, step_m), lambda: resample(self.vertices[slot], step_m)[0],
                       self._cache_size)
