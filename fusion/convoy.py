"""Convoy fusion (paper sec. III-A) of one border pair in the world frame."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from fusion.geometry import cumulative_length, project_point
from fusion.types import NDArrayFloat, NDArrayInt8, Source

_HEADING_HALF_WINDOW: Final[int] = 5


@dataclass(frozen=True)
class OverlapStart:
    """Where a coop border starts on an ego border (world frame).

    Fields: ``s_ego`` arc length of every ego vertex [m]; ``s0`` arc length of the foot of
    the coop start on the ego border [m]; ``offset_m`` its distance from the border [m];
    ``heading_diff_rad`` angle between the two borders there [rad].
    """

    s_ego: NDArrayFloat
    s0: float
    offset_m: float
    heading_diff_rad: float


def overlap_start(ego: NDArrayFloat, coop: NDArrayFloat) -> OverlapStart:
    """Project the coop border start onto the ego border (see :class:`OverlapStart`)."""
    s_ego = cumulative_length(ego)
    s0, offset, k = project_point(coop[0], ego, s_ego)
    n = ego.shape[0]
    a, b = ego[max(0, k - _HEADING_HALF_WINDOW)], ego[min(n - 1, k + 1 + _HEADING_HALF_WINDOW)]
    de = b - a
    dc = coop[min(coop.shape[0] - 1, 2 * _HEADING_HALF_WINDOW)] - coop[0]
    diff = math.atan2(de[0] * dc[1] - de[1] * dc[0], de[0] * dc[0] + de[1] * dc[1])
    return OverlapStart(s_ego, s0, offset, abs(diff))


def convoy_border(ego: NDArrayFloat, coop: NDArrayFloat, start: OverlapStart, coop_weight: float,
                  blend_offset_m: float) -> tuple[NDArrayFloat, NDArrayInt8]:
    """Fuse one ego border with the coop border that starts inside it.

    The coop start projects onto the ego border at arc length s0 (``start``). Ego points before s0
    are kept; each ego point in the overlap, at arc length s, is paired with the coop point
    at arc length s − s0 along the coop border (arc-length pairing, not array index) and
    replaced by (1 − w)·P_ego + w·P_coop with w = ``coop_weight``; the rest of the coop
    border is appended. When the borders are more than ``blend_offset_m`` apart at s0, w
    instead rises linearly from 0 at the overlap start to 1 at its end, so the result has
    no jump. Returns the points and their :class:`Source` labels.
    """
    s_ego, s0, offset = start.s_ego, start.s0, start.offset_m
    s_coop = cumulative_length(coop)
    first = int(np.searchsorted(s_ego, s0, side="left"))
    u = s_ego[first:] - s0
    overlap_end = min(float(s_ego[-1]) - s0, float(s_coop[-1]))
    n_ov = int(np.searchsorted(u, overlap_end, side="right"))
    u = u[:n_ov]
    paired = np.empty((n_ov, 2))
    paired[:, 0] = np.interp(u, s_coop, coop[:, 0])
    paired[:, 1] = np.interp(u, s_coop, coop[:, 1])
    if offset > blend_offset_m and overlap_end > 0.0:
        w = (u / overlap_end)[:, None]
    else:
        w = coop_weight
    fused = ego[first:first + n_ov] * (1.0 - w) + paired * w
    tail_ego = ego[first + n_ov:]
    tail_coop = coop[int(np.searchsorted(s_coop, overlap_end, side="right")):]
    if tail_ego.shape[0]:
        tail, tail_src = tail_ego, Source.EGO
    else:
        tail, tail_src = tail_coop, Source.COOP
    points = np.concatenate((ego[:first], fused, tail))
    labels = np.empty(points.shape[0], dtype=np.int8)
    labels[:first] = Source.EGO
    labels[first:first + n_ov] = Source.FUSED
    labels[first + n_ov:] = tail_src
    return points, labels
