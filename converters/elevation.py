"""Heights (m) of lanelet vertices from the OpenDRIVE ``<elevationProfile>``, for the
OSM ``ele`` tag.

crdesigner's lanelets are 2-D. A vertex takes the elevation of its road's reference line
at the vertex's s: the reference line (crdesigner's parsed ``planView``) is sampled every
``REFERENCE_STEP_M``; a vertex's s is that of the nearest sample, moved along the
sample's tangent to the vertex's foot point. Only the roads the lanelet covers are
searched (a bridge over another road keeps its own height); lanelets that cover no known
road (crosswalks) search every road. Superelevation and lane height are not applied
(the CARLA towns have none); cold_maps' own sampling applies superelevation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

NDArrayFloat = npt.NDArray[np.float64]

REFERENCE_STEP_M: Final[float] = 0.5
"""Spacing (m) of the reference-line samples a vertex is projected onto."""


class _RoadLine:
    """One road's reference line sampled in s, with its elevation profile."""

    def __init__(self, road: Any) -> None:
        plan_view = road.plan_view
        length = float(plan_view.length)
        count = max(int(math.ceil(length / REFERENCE_STEP_M)), 1) + 1
        self.length = length
        self.s = np.linspace(0.0, length, count)
        poses = [plan_view.calc(float(s), compute_curvature=False, reverse=False) for s in self.s]
        self.xy = np.array([pose[0] for pose in poses], dtype=np.float64)
        heading = np.array([pose[1] for pose in poses], dtype=np.float64)
        self.tangent = np.column_stack((np.cos(heading), np.sin(heading)))
        records = sorted(road.elevation_profile.elevations, key=lambda record: float(record.start_pos))
        self.starts = np.array([float(record.start_pos) for record in records])
        self.coefficients = np.array(
            [[float(c) for c in record.polynomial_coefficients[:4]] for record in records], dtype=np.float64
        ).reshape(-1, 4)
        self._tree: cKDTree | None = None

    def tree(self) -> cKDTree:
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.xy)
        return self._tree

    def elevation(self, s: NDArrayFloat) -> NDArrayFloat:
        """z (m) at each s (m); 0 before the first record and without records."""
        if not len(self.starts):
            return np.zeros_like(s)
        index = np.searchsorted(self.starts, s, side="right") - 1
        applies = index >= 0
        c = self.coefficients[np.maximum(index, 0)]
        ds = s - self.starts[np.maximum(index, 0)]
        return np.where(applies, c[:, 0] + ds * (c[:, 1] + ds * (c[:, 2] + ds * c[:, 3])), 0.0)

    def locate(self, points: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
        """Distance (m) from each point to its nearest sample, and the point's s (m)."""
        distance, index = self.tree().query(points)
        along = np.einsum("ij,ij->i", points - self.xy[index], self.tangent[index])
        shift = np.clip(along, -REFERENCE_STEP_M, REFERENCE_STEP_M)
        return distance, np.clip(self.s[index] + shift, 0.0, self.length)


class RoadHeights:
    """Vertex heights over the roads of one crdesigner ``OpenDrive`` object (lazy per road)."""

    def __init__(self, opendrive: Any) -> None:
        self._roads = {str(road.id): road for road in opendrive.roads}
        self._lines: dict[str, _RoadLine] = {}

    def _line(self, road_id: str) -> _RoadLine:
        if road_id not in self._lines:
            self._lines[road_id] = _RoadLine(self._roads[road_id])
        return self._lines[road_id]

    def heights(self, points: NDArrayFloat, road_ids: Sequence[str]) -> NDArrayFloat:
        """z (m) of each (N, 2) point from the nearest reference line among ``road_ids``
        (every road when none of them is known)."""
        candidates = [road for road in dict.fromkeys(road_ids) if road in self._roads] or list(self._roads)
        best = np.full(len(points), np.inf)
        z = np.zeros(len(points))
        for road_id in candidates:
            line = self._line(road_id)
            distance, s = line.locate(points)
            closer = distance < best
            best = np.where(closer, distance, best)
            z = np.where(closer, line.elevation(s), z)
        return z
