"""Numpy geometry of a Lanelet2 map, extracted once per map: lanelet borders and
mid-lines, and every border line string of the map with its bounding box and samples."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from gt_matching.errors import MatchingError
from gt_matching.polyline import NDArrayFloat, NDArrayInt, arc_lengths, mid_line, resample

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Sampling distance of lanelet mid-lines (scoring lanelet sequences), m.
CENTRE_STEP_M: Final = 0.1

LaneletKey = tuple[int, bool]
"""A lanelet as (id, inverted): a bidirectional lanelet is driven in either orientation."""


def line_xy(line: Any, owner: str) -> NDArrayFloat:
    """x, y of a Lanelet2 line string as an ``(N, 2)`` array in its own orientation."""
    points = np.array([(p.x, p.y) for p in line], dtype=np.float64).reshape(-1, 2)
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

    def centre_distances(self, points: NDArrayFloat) -> NDArrayFloat:
        """Distance of each point to the closest ``centre`` vertex, m: at most
        ``sqrt(d**2 + (CENTRE_STEP_M / 2)**2)`` for a distance d to the mid-line."""
        distances: NDArrayFloat = self.centre_tree.query(points)[0]
        return distances

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
    bounding boxes, and samples every ``step_m`` and their KD-trees built on first use."""

    def __init__(self, lanelet_map: Any) -> None:
        self.slot_of_line: dict[int, int] = {}
        self.vertices: list[NDArrayFloat] = []
        for lanelet in lanelet_map.laneletLayer:
            for line in (lanelet.leftBound, lanelet.rightBound):
                if line.id not in self.slot_of_line:
                    self.slot_of_line[line.id] = len(self.vertices)
                    self.vertices.append(line_xy(line, f"lanelet {lanelet.id}"))
        if not self.vertices:
            raise MatchingError("lanelet map has no lanelets")
        self.boxes: NDArrayFloat = np.array(
            [np.concatenate((v.min(axis=0), v.max(axis=0))) for v in self.vertices], dtype=np.float64
        )
        self._samples: dict[tuple[int, float], NDArrayFloat] = {}
        self._trees: dict[tuple[int, float], cKDTree] = {}

    def slots(self, lines: set[int]) -> NDArrayInt:
        """Slots of the given line string ids that belong to the map."""
        return np.array([self.slot_of_line[line] for line in lines if line in self.slot_of_line], dtype=np.int64)

    def near(self, boxes: NDArrayFloat, reach_m: float) -> NDArrayInt:
        """Slots of the lines whose bounding box comes within ``reach_m`` of any of ``boxes``
        (``(K, 4)``: x min, y min, x max, y max)."""
        lo = boxes[:, None, :2] - reach_m
        hi = boxes[:, None, 2:] + reach_m
        overlap = np.all((self.boxes[None, :, :2] <= hi) & (self.boxes[None, :, 2:] >= lo), axis=2)
        return np.flatnonzero(np.any(overlap, axis=0))

    def tree(self, slot: int, step_m: float) -> cKDTree:
        """KD-tree of the samples every ``step_m`` of line ``slot`` (cached)."""
        from scipy.spatial import cKDTree

        key = (slot, step_m)
        found = self._trees.get(key)
        if found is None:
            found = self._trees[key] = cKDTree(self.samples(slot, step_m))
        return found

    def samples(self, slot: int, step_m: float) -> NDArrayFloat:
        """Points every ``step_m`` along line ``slot`` (cached)."""
        key = (slot, step_m)
        found = self._samples.get(key)
        if found is None:
            found = self._samples[key] = resample(self.vertices[slot], step_m)[0]
        return found
