"""One continuous GT border assembled along a sequence of lanelets, and the closest-point
distances of detected points to it."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from gt_matching.geometry import BorderIndex
from gt_matching.polyline import NDArrayBool, NDArrayFloat, NDArrayInt, windowed_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree


@dataclass(frozen=True)
class BorderDistances:
    """Closest-point distances of detected points to a GT border.

    Fields:
        distances: per point, m (exact or to the resampled GT).
        arc_m: per point, arc length of its closest GT point along the border, m.
        other_closer: per point, True when a border of another lane (not the GT border,
            not a lanelet overlapping the route) is closer than the GT border by more than
            the configured margin (both resampled).
    """

    distances: NDArrayFloat
    arc_m: NDArrayFloat
    other_closer: NDArrayBool


class RouteBorder:
    """The left or right GT border of a lanelet sequence: the borders' vertices joined in
    driving order, and their samples from the ``BorderIndex`` (spacing <= ``step_m``)."""

    def __init__(self, index: BorderIndex, parts: list[tuple[int, bool]], overlapping: set[int]) -> None:
        """``parts``: (line string id, reversed) per lanelet in driving order;
        ``overlapping``: line string ids of lanelets that overlap the route (the other
        branches of a junction), which never count as another lane's border."""
        self._index = index
        self._overlapping = np.zeros(len(index.vertices), dtype=bool)
        self._overlapping[[index.slot_of_line[line] for line in overlapping]] = True
        vertices, samples, segments = [], [], []
        self._position = np.full(len(index.vertices), -1, dtype=np.int64)
        offsets, counts, starts, reversed_ = [], [], [], []
        vertex_offset = sample_offset = 0
        for position, (line, reversed_part) in enumerate(parts):
            slot = index.slot_of_line[line]
            if self._position[slot] < 0:
                self._position[slot] = position
            line_vertices = index.vertices[slot]
            first, count = index.start[slot], index.count[slot]
            line_samples = index.samples[first : first + count]
            line_segments = index.sample_segment[first : first + count]
            if reversed_part:
                line_vertices = line_vertices[::-1]
                line_samples = line_samples[::-1]
                line_segments = (len(line_vertices) - 2 - line_segments)[::-1]
            vertices.append(line_vertices)
            samples.append(line_samples)
            segments.append(line_segments + vertex_offset)
            offsets.append(sample_offset)
            counts.append(count)
            starts.append(first)
            reversed_.append(reversed_part)
            vertex_offset += len(line_vertices)
            sample_offset += count
        self.vertices: NDArrayFloat = np.concatenate(vertices)
        self.samples: NDArrayFloat = np.concatenate(samples)
        self.sample_segment: NDArrayInt = np.concatenate(segments)
        cum = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(self.vertices, axis=0).T))))
        self.sample_arc: NDArrayFloat = cum[self.sample_segment] + np.hypot(
            *(self.samples - self.vertices[self.sample_segment]).T
        )
        self._offset = np.array(offsets, dtype=np.int64)
        self._count = np.array(counts, dtype=np.int64)
        self._start = np.array(starts, dtype=np.int64)
        self._reversed = np.array(reversed_, dtype=bool)

    @cached_property
    def tree(self) -> cKDTree:
        """KD-tree of the samples, built on first use."""
        from scipy.spatial import cKDTree

        return cKDTree(self.samples)

    def distances(
        self, points: NDArrayFloat, *, exact: bool, other_margin_m: float
    ) -> BorderDistances:
        """Closest-point distances of ``points`` (world frame, m) to this border.

        The map-wide KD-tree gives each point's closest sample; when that sample is on this
        border it is the answer, otherwise this border's own KD-tree is asked. Exact mode
        refines with point-to-segment distances to the segments within one resampling step
        (arc length) of the closest sample, which hold the closest point wherever the
        border's radius of curvature exceeds the distance.
        """
        index = self._index
        near_distance, near_sample = index.tree.query(points)
        slot = index.owner[near_sample]
        position = self._position[slot]
        on_route = position >= 0
        sample = np.empty(len(points), dtype=np.int64)
        pos = position[on_route]
        local = near_sample[on_route] - self._start[pos]
        sample[on_route] = self._offset[pos] + np.where(self._reversed[pos], self._count[pos] - 1 - local, local)
        distances = near_distance.copy()
        other_closer = np.zeros(len(points), dtype=bool)
        off_route = ~on_route
        if np.any(off_route):
            route_distance, route_sample = self.tree.query(points[off_route])
            sample[off_route] = route_sample
            distances[off_route] = route_distance
            other_closer[off_route] = (near_distance[off_route] < route_distance - other_margin_m) & ~self._overlapping[
                slot[off_route]
            ]
        if exact:
            distances, arc = windowed_distances(points, self.vertices, self.sample_arc[sample], self._index.step_m)
        else:
            arc = self.sample_arc[sample]
        return BorderDistances(distances=distances, arc_m=arc, other_closer=other_closer)
