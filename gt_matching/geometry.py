"""Numpy geometry of a Lanelet2 map, built once per map: lanelet centrelines and borders,
and every border of the map resampled into one KD-tree."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from gt_matching.errors import MatchingError
from gt_matching.polyline import NDArrayFloat, NDArrayInt, arc_lengths, mid_line, resample

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Sampling distance of lanelet centrelines (scoring lanelet sequences), m.
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
        centre: mid-line of the borders every <= ``CENTRE_STEP_M``, m (Lanelet2's own
            centreline costs O(N^2) on densely sampled borders).
        length_m: centreline length, m.
        left_line, right_line: ids of the left and right border line strings.
        left_reversed, right_reversed: True when the border runs against the stored
            orientation of its line string in the ``BorderIndex``.
        centre_tree: KD-tree of ``centre``.
    """

    lanelet: Any
    key: LaneletKey
    centre: NDArrayFloat
    length_m: float
    left_line: int
    right_line: int
    left_reversed: bool
    right_reversed: bool
    centre_tree: cKDTree

    def centre_distances(self, points: NDArrayFloat) -> NDArrayFloat:
        """Distance of each point to the closest ``centre`` vertex, m: at most
        ``sqrt(d**2 + (CENTRE_STEP_M / 2)**2)`` for a distance d to the mid-line."""
        distances: NDArrayFloat = self.centre_tree.query(points)[0]
        return distances


class BorderIndex:
    """Every border line string of a map (each once), resampled every ``step_m`` into one
    KD-tree, with the owner line string of each sample."""

    def __init__(self, lanelet_map: Any, step_m: float) -> None:
        from scipy.spatial import cKDTree

        self.step_m = step_m
        self.slot_of_line: dict[int, int] = {}
        self.vertices: list[NDArrayFloat] = []
        self.inverted: list[bool] = []
        samples: list[NDArrayFloat] = []
        segments: list[NDArrayInt] = []
        for lanelet in lanelet_map.laneletLayer:
            for line in (lanelet.leftBound, lanelet.rightBound):
                if line.id in self.slot_of_line:
                    continue
                self.slot_of_line[line.id] = len(self.vertices)
                vertices = line_xy(line, f"lanelet {lanelet.id}")
                self.vertices.append(vertices)
                self.inverted.append(bool(line.inverted()))
                points, seg = resample(vertices, step_m)
                samples.append(points)
                segments.append(seg)
        if not samples:
            raise MatchingError("lanelet map has no lanelets")
        counts = np.array([len(s) for s in samples], dtype=np.int64)
        self.count: NDArrayInt = counts
        self.start: NDArrayInt = np.concatenate(([0], np.cumsum(counts)[:-1]))
        self.owner: NDArrayInt = np.repeat(np.arange(len(samples), dtype=np.int64), counts)
        self.samples: NDArrayFloat = np.concatenate(samples)
        self.sample_segment: NDArrayInt = np.concatenate(segments)
        self.tree: cKDTree = cKDTree(self.samples)

    def lanelet_geometry(self, lanelet: Any) -> LaneletGeometry:
        """Numpy geometry of a Lanelet2 lanelet (either orientation)."""
        left, right = lanelet.leftBound, lanelet.rightBound
        centre = mid_line(line_xy(left, f"lanelet {lanelet.id}"), line_xy(right, f"lanelet {lanelet.id}"), CENTRE_STEP_M)
        for line in (left, right):
            if line.id not in self.slot_of_line:
                raise MatchingError(f"lanelet {lanelet.id}: border {line.id} is not in the lanelet map")
        from scipy.spatial import cKDTree

        return LaneletGeometry(
            lanelet=lanelet,
            key=(int(lanelet.id), bool(lanelet.inverted())),
            centre=centre,
            length_m=float(arc_lengths(centre)[-1]),
            left_line=int(left.id),
            right_line=int(right.id),
            left_reversed=bool(left.inverted()) != self.inverted[self.slot_of_line[left.id]],
            right_reversed=bool(right.inverted()) != self.inverted[self.slot_of_line[right.id]],
            centre_tree=cKDTree(centre),
        )
