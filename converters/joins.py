"""Lane ends that crdesigner links but that do not quite touch: joined, or reported.

Lanelet2 routing sees lanelet B after lanelet A only when A's left and right borders end
on the very nodes where B's start. OpenDRIVE maps often leave a small gap between linked
lane ends (1.5 cm to metres, from rounding or a heading kink), so the node merge within
``MERGE_TOLERANCE_M`` (1 mm) alone loses the successor. For every successor relation
crdesigner computed from the OpenDRIVE links, when both border ends lie within
``JOIN_TOLERANCE_M`` of the successor's starts, the end points are *snapped*: all points
joined at one border end become one node at their centroid.

Effect on the ground truth: a snapped node moves by at most the gap it closes (half of
it for a plain A → B join; on a split or merge it moves to the centroid of the ends it
joins), and the border's first or last segment (crdesigner samples borders every
~0.5 m or finer) tilts to reach it, so the GT deviates from the OpenDRIVE border by at
most the gap, fading to zero over that one segment. ``cold-maps check`` measures that
deviation like any other. Successor ends farther apart are not joined: they are
returned by ``successor_gaps`` (``joined`` False) and listed by ``cold-maps check``'s
connectivity test.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from converters.crdesigner_bridge import NDArrayFloat, SourceLanelet

NDArrayInt = npt.NDArray[np.int64]

JOIN_TOLERANCE_M: Final[float] = 0.5
"""Linked lane ends whose left and right border ends both lie this close (m) to the
successor's starts are snapped into shared nodes."""


@dataclass(frozen=True)
class EndGap:
    """A successor relation known to the converter whose lane ends do not touch.

    Fields:
        lanelet, successor: the lanelet ids (successor follows lanelet).
        left_m, right_m: distance (m) from the lanelet's left/right border end to the
            successor's left/right border start.
        joined: True when both are within ``JOIN_TOLERANCE_M`` (the ends are snapped).
    """

    lanelet: int
    successor: int
    left_m: float
    right_m: float
    joined: bool


def successor_distances(
    lanelets: Sequence[SourceLanelet],
) -> tuple[NDArrayInt, NDArrayInt, NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Every converter successor relation, in lanelet order: the lanelet's and the
    successor's index in ``lanelets``, the distances (m) from the lanelet's left and right
    border ends to the successor's left and right starts, and the larger of the two."""
    slot = {lanelet.id: index for index, lanelet in enumerate(lanelets)}
    pairs = [(index, slot[i]) for index, lanelet in enumerate(lanelets) for i in lanelet.successors if i in slot]
    before, after = np.array(pairs, dtype=np.int64).reshape(-1, 2).T
    involved = np.unique(np.concatenate((before, after))).tolist()
    ends = np.array([(lanelets[i].left[-1], lanelets[i].right[-1]) for i in involved], dtype=np.float64)
    starts = np.array([(lanelets[i].left[0], lanelets[i].right[0]) for i in involved], dtype=np.float64)
    gap = (ends[np.searchsorted(involved, before)] - starts[np.searchsorted(involved, after)]).reshape(-1, 2, 2)
    distance = np.hypot(gap[..., 0], gap[..., 1])  # (pair, left/right)
    left, right = distance[:, 0], distance[:, 1]
    return before, after, left, right, np.where(right > left, right, left)  # the larger as Python's max


def successor_gaps(
    lanelets: Sequence[SourceLanelet], merge_tolerance_m: float, join_tolerance_m: float = JOIN_TOLERANCE_M
) -> tuple[EndGap, ...]:
    """Every converter successor relation whose ends are farther apart than
    ``merge_tolerance_m`` (m) on either border, in lanelet order; ``joined`` when both
    lie within ``join_tolerance_m`` (m)."""
    before, after, left, right, largest = successor_distances(lanelets)
    gap, joined = gap_kinds(largest, merge_tolerance_m, join_tolerance_m)
    return tuple(
        EndGap(lanelets[b].id, lanelets[a].id, l, r, j)
        for b, a, l, r, j in zip(*(v[gap].tolist() for v in (before, after, left, right, joined)))
    )


def gap_kinds(
    largest: NDArrayFloat, merge_tolerance_m: float, join_tolerance_m: float
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Of each successor relation (``successor_distances``' larger end distance, m):
    whether its ends are farther apart than ``merge_tolerance_m`` on either border (a gap,
    ``successor_gaps``), and whether that gap is joined (both within ``join_tolerance_m``)."""
    gap = largest > merge_tolerance_m
    return gap, gap & (largest <= join_tolerance_m)


def join_ends(
    points: NDArrayFloat, representative: NDArrayInt, pairs: Sequence[tuple[int, int]]
) -> tuple[NDArrayInt, NDArrayFloat]:
    """Snap point pairs (indices into ``points``) together on top of the merge
    ``representative`` (index of each point's node): the nodes of a pair and every node
    joined to them become one node at the centroid of their positions. Returns the new
    representatives and the node positions (``points`` with each joined node moved)."""
    parent: dict[int, int] = {}

    def root(node: int) -> int:
        while parent.get(node, node) != node:
            parent[node] = parent.get(parent[node], parent[node])
            node = parent[node]
        return node

    for a, b in pairs:
        first, second = root(int(representative[a])), root(int(representative[b]))
        if first != second:
            parent[max(first, second)] = min(first, second)
    if not parent:
        return representative, points
    lookup = np.arange(len(points), dtype=np.int64)
    groups: dict[int, list[int]] = {}
    for node in set(parent) | set(parent.values()):
        lookup[node] = root(node)
        groups.setdefault(int(lookup[node]), []).append(node)
    positions = points.copy()
    for node, members in groups.items():
        positions[node] = points[members].mean(axis=0)
    return lookup[representative], positions
