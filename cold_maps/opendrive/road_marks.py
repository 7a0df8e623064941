"""Lane markings: which ``<roadMark>`` applies where, and what a camera sees at a lane border.

A lane's ``<roadMark>`` records mark its outer border (the centre lane's mark the centre
line), each from its ``sOffset`` to the next record or the section end. A border is seen
from the lane a vehicle drives in: it is *detectable* where it is painted (a mark whose
type is not "none") or where it is a physical edge of the road. Classified like ASAM OSI's
``LaneBoundary.Classification.Type`` (``BoundaryType``):

- painted: "solid" and the double marks with a solid line → ``SOLID_LINE``, "broken" and
  "broken broken" → ``DASHED_LINE``, "botts dots" → ``BOTTS_DOTS``, "curb" → ``CURB``,
  "grass" → ``GRASS_EDGE``, "edge" → ``ROAD_EDGE``, "custom" → ``OTHER``;
- unpainted, with the first lane beyond the border (zero-width lanes skipped, their
  borders coincide and their marks count) of a drivable type (``DRIVABLE_LANE_TYPES``) →
  ``NO_LINE``: not detected (two lanes of one surface, typical inside junctions);
- unpainted, beyond a sidewalk, curb or walking lane → ``CURB``; beyond any other lane
  type (shoulder, border, median, none, ...) → ``ROAD_EDGE``;
- unpainted with no lane beyond: ``ROAD_EDGE`` outside junctions; inside a junction
  (``Road.junction`` != "-1") ``NO_LINE``, since other connecting roads share the surface.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.lanes import section_borders, section_of
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, Lane, LaneSection, Road, RoadMark

NDArrayInt = npt.NDArray[np.int64]


class BoundaryType(IntEnum):
    """ASAM OSI 3 ``LaneBoundary.Classification.Type`` (same numbers)."""

    UNKNOWN = 0
    OTHER = 1
    NO_LINE = 2
    SOLID_LINE = 3
    DASHED_LINE = 4
    BOTTS_DOTS = 5
    ROAD_EDGE = 6
    SNOW_EDGE = 7
    GRASS_EDGE = 8
    GRAVEL_EDGE = 9
    SOIL_EDGE = 10
    GUARD_RAIL = 11
    CURB = 12
    STRUCTURE = 13
    BARRIER = 14
    SOUND_BARRIER = 15


DRIVABLE_LANE_TYPES: Final[frozenset[str]] = frozenset(
    VEHICLE_LANE_TYPES + ("bidirectional", "parking", "biking", "bus", "taxi", "HOV", "restricted", "roadWorks",
                          "tram", "rail", "shared"))
"""Lane types with a road surface that continues without a physical edge: an unpainted
border towards one of them is invisible to a camera."""
CURB_LANE_TYPES: Final[frozenset[str]] = frozenset({"sidewalk", "curb", "walking"})
"""Lane types beyond an unpainted border that make it a curb."""
ZERO_WIDTH_M: Final[float] = 1e-3
"""A lane narrower than this (m) at some s is skipped there: its two borders coincide."""
PAINTED_TYPES: Final[dict[str, BoundaryType]] = {
    "solid": BoundaryType.SOLID_LINE, "solid solid": BoundaryType.SOLID_LINE,
    "solid broken": BoundaryType.SOLID_LINE, "broken solid": BoundaryType.SOLID_LINE,
    "broken": BoundaryType.DASHED_LINE, "broken broken": BoundaryType.DASHED_LINE,
    "botts dots": BoundaryType.BOTTS_DOTS, "curb": BoundaryType.CURB, "grass": BoundaryType.GRASS_EDGE,
    "edge": BoundaryType.ROAD_EDGE, "custom": BoundaryType.OTHER,
}
"""``<roadMark type>`` → boundary type, for every type but "none"."""
NO_MARK: Final[int] = -1
"""``mark_index`` where no ``<roadMark>`` applies."""


def mark_indices(lane: Lane, ds: NDArrayFloat) -> NDArrayInt:
    """Index into ``lane.road_marks`` of the record in force at each ``ds`` (m from the
    section start), ``NO_MARK`` before the first record or when the lane has none."""
    starts = np.array([mark.s_offset for mark in lane.road_marks], dtype=np.float64)
    return np.searchsorted(starts, np.asarray(ds, dtype=np.float64), side="right").astype(np.int64) - 1


def mark_type(mark: RoadMark) -> BoundaryType:
    """The boundary type of a painted mark; ``NO_LINE`` for type "none"."""
    return PAINTED_TYPES.get(mark.type, BoundaryType.NO_LINE)


@dataclass(frozen=True)
class BorderMarking:
    """What marks one border of a lane at each station s.

    Fields:
        type: (N,) ``BoundaryType`` values; ``NO_LINE`` where a camera cannot see it.
        owner: (N,) id of the lane whose ``<roadMark>`` applies (0: the centre line),
            valid where ``mark_index`` is not ``NO_MARK``.
        mark_index: (N,) index into that lane's ``road_marks``, ``NO_MARK`` where the
            border is unpainted (no record, or only records of type "none").
    """

    type: NDArrayInt
    owner: NDArrayInt
    mark_index: NDArrayInt

    @property
    def detectable(self) -> npt.NDArray[np.bool_]:
        """(N,) True where the border is painted or a physical edge."""
        return self.type != BoundaryType.NO_LINE

    def mark(self, road: Road, section_index: int, i: int) -> RoadMark | None:
        """The ``<roadMark>`` in force at station ``i``, None where unpainted."""
        if self.mark_index[i] == NO_MARK:
            return None
        lane = road.lane_sections[section_index].lane(int(self.owner[i]))
        return lane.road_marks[int(self.mark_index[i])]


def _walk(road: Road, section: LaneSection, lane_id: int, side: Literal["inner", "outer"]
          ) -> tuple[list[int], int, int]:
    """The owners of the section's borders from the leftmost to the rightmost (lane id, 0:
    the centre line), the index of lane ``lane_id``'s ``side`` border among them and the
    step (±1) away from the lane."""
    owners = [lane.id for lane in reversed(section.left)] + [0] + [lane.id for lane in section.right]
    position = {owner: i for i, owner in enumerate(owners)}
    if lane_id > 0:
        return (owners, position[lane_id], -1) if side == "outer" else (owners, position[lane_id - 1], 1)
    if lane_id < 0:
        return (owners, position[lane_id], 1) if side == "outer" else (owners, position[lane_id + 1], -1)
    raise ValueError(f"road {road.id}: lane 0 has no area and no borders to classify")


def _edge_type(road: Road) -> BoundaryType:
    """Boundary type of an unpainted border with no lane beyond it (module docstring)."""
    return BoundaryType.NO_LINE if road.junction != "-1" else BoundaryType.ROAD_EDGE


def uniform_marking(road: Road, section_index: int, lane_id: int, side: Literal["inner", "outer"]
                    ) -> BorderMarking | None:
    """``classify_border``'s marking at the section's start (one station) when the section's
    records make it the same at every s of the section: the ``<roadMark>`` of the border's
    own lane in force at the start holds to the section's end, and either paints the border
    or leaves no border beyond it; None otherwise (the marking may change along s)."""
    section = section_of(road, section_index)
    owners, start, step = _walk(road, section, lane_id, side)
    lane = section.lane(owners[start])
    index, last = mark_indices(lane, np.array([0.0, section.s_end - section.s])).tolist()
    if index != last:
        return None
    kind = mark_type(lane.road_marks[index]) if index != NO_MARK else BoundaryType.NO_LINE
    if kind != BoundaryType.NO_LINE:
        return BorderMarking(np.array([kind], dtype=np.int64), np.array([owners[start]], dtype=np.int64),
                             np.array([index], dtype=np.int64))
    if 0 <= start + step < len(owners):
        return None
    return BorderMarking(np.array([_edge_type(road)], dtype=np.int64), np.zeros(1, dtype=np.int64),
                         np.array([NO_MARK], dtype=np.int64))


def classify_border(road: Road, section_index: int, lane_id: int, side: Literal["inner", "outer"],
                    s: NDArrayFloat, borders: dict[int, tuple[NDArrayFloat, NDArrayFloat]] | None = None
                    ) -> BorderMarking:
    """The marking of lane ``lane_id``'s ``side`` border ("inner": towards lane 0, "outer":
    away from it) at each road ``s`` (m) of the section, seen from inside the lane;
    ``borders``: ``section_borders`` of every lane at ``s``, if already known."""
    section = section_of(road, section_index)
    s = np.asarray(s, dtype=np.float64)
    owners, start, step = _walk(road, section, lane_id, side)
    borders = section_borders(road, section_index, s) if borders is None else borders
    # Borders across the section from the leftmost to the rightmost: (owner lane id, t).
    slots = [(owner, borders[owner][1]) for owner in owners]
    # The lane between slots i and i + 1: left lanes lie outside their inner slot.
    between = [slots[i][0] if slots[i][0] > 0 else slots[i + 1][0] for i in range(len(slots) - 1)]
    n = s.shape[0]
    kind = np.full(n, BoundaryType.UNKNOWN, dtype=np.int64)
    owner = np.zeros(n, dtype=np.int64)
    index = np.full(n, NO_MARK, dtype=np.int64)
    open_ = np.ones(n, dtype=bool)  # stations whose chain of coinciding borders goes on
    ds = s - section.s
    slot = start
    while True:
        slot_owner, t = slots[slot]
        lane = section.lane(slot_owner)
        marks = mark_indices(lane, ds)
        painted = open_ & (marks != NO_MARK)
        if painted.any():
            types = np.array([mark_type(m) for m in lane.road_marks] + [BoundaryType.NO_LINE], dtype=np.int64)
            painted &= types[marks] != BoundaryType.NO_LINE
            kind[painted], owner[painted], index[painted] = types[marks[painted]], slot_owner, marks[painted]
            open_ &= ~painted
        after = slot + step
        if not 0 <= after < len(slots):
            kind[open_] = _edge_type(road)
            break
        beyond = section.lane(between[min(slot, after)])
        wide = open_ & (np.abs(slots[after][1] - t) >= ZERO_WIDTH_M)
        kind[wide] = _unpainted_towards(beyond.type)
        open_ &= ~wide
        if not open_.any():
            break
        slot = after
    return BorderMarking(kind, owner, index)


def _unpainted_towards(lane_type: str) -> BoundaryType:
    """Boundary type of an unpainted border with a lane of ``lane_type`` beyond it."""
    if lane_type in DRIVABLE_LANE_TYPES:
        return BoundaryType.NO_LINE
    return BoundaryType.CURB if lane_type in CURB_LANE_TYPES else BoundaryType.ROAD_EDGE
