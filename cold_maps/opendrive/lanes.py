"""Lateral position (t) of lane borders, vectorised over s.

Lane borders: t of lane 0 is laneOffset(s); each lane's outer border is its inner border
plus its width (left lanes towards +t, right lanes towards -t); lane n's inner border is
lane n∓1's outer border. Width records start at ``section.s + sOffset``; where no record
applies (before the first) the width is 0, so zero-width lanes coincide with their inner
border.

``<border>`` records: ASAM OpenDRIVE 1.8.1 §11.6.2 "Lane borders" (1.6/1.7 §9.5.2) defines
them as "the outer limits of a lane, independent of the parameters of their inner
borders", with ``a`` the "border position at @s"; widths and borders are mutually
exclusive and, if both are present, "the application shall use the information from the
<width> elements". The spec does not say in words whether laneOffset applies. It places
every lane relative to the centre lane and defines laneOffset (§11.4 "Lane offset") as
the shift of the centre lane away from the reference line, so we read a border as t
measured from the shifted centre lane: t_outer = laneOffset(s) + border(s), as the model's
``Lane.borders`` field documents. The next outer lane's inner border is that border.
A map written by a tool that reads borders from the reference line differs from ours by
exactly laneOffset(s) in such lanes (none in the CARLA towns, which use no ``<border>``).
commonroad-scenario-designer 0.8.5 also measures border records from the laneOffset
line, but negates them for right lanes (it reuses them as width magnitudes); we keep the
signed t the spec and ``Lane.borders`` describe.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from cold_maps.opendrive import cubic_poly
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import CubicPoly, Lane, LaneSection, Road
from cold_maps.opendrive.reference_line import check_s


def section_of(road: Road, section_index: int) -> LaneSection:
    """The road's lane section with this index; IndexError naming the road when absent."""
    if not 0 <= section_index < len(road.lane_sections):
        raise IndexError(
            f"road {road.id}: no lane section {section_index} (it has {len(road.lane_sections)})"
        )
    return road.lane_sections[section_index]


def lane_of(road: Road, section_index: int, lane_id: int) -> Lane:
    """The lane with this id in the section; KeyError naming the road when absent."""
    try:
        return section_of(road, section_index).lane(lane_id)
    except KeyError:
        raise KeyError(f"road {road.id}: lane section {section_index} has no lane {lane_id}") from None


def lane_offset(road: Road, s: NDArrayFloat, *, before: float | None = None) -> NDArrayFloat:
    """t of the centre lane (lane 0) at each s (m); ``before``: see ``cubic_poly.evaluate``."""
    return cubic_poly.evaluate(road.lane_offsets, s, before=before)


def _outer_border(
    lane: Lane, section: LaneSection, inner: NDArrayFloat, offset: NDArrayFloat, s: NDArrayFloat
) -> NDArrayFloat:
    """t of a lane's outer border given its inner border and the centre-lane offset."""
    if lane.widths or not lane.borders:
        side = 1.0 if lane.id > 0 else -1.0
        return inner + side * cubic_poly.evaluate(lane.widths, s, s_offset=section.s)
    return offset + cubic_poly.evaluate(lane.borders, s, s_offset=section.s)


def section_borders(
    road: Road, section_index: int, s: NDArrayFloat, *, outermost: int | None = None
) -> dict[int, tuple[NDArrayFloat, NDArrayFloat]]:
    """t of (inner, outer) border at each s for every lane of a section, keyed by lane id.

    The centre lane 0 maps to (laneOffset, laneOffset). At the section's end laneOffset is
    its limit from inside the section (a jump where the next section starts belongs to
    that section). ``outermost`` limits the lanes computed to |id| <= outermost on each
    side.
    """
    section = section_of(road, section_index)
    s = check_s(road, s)
    offset = lane_offset(road, s, before=section.s_end)
    borders = {0: (offset, offset)}
    for side in (section.left, section.right):
        inner = offset
        for lane in side[:outermost]:
            outer = _outer_border(lane, section, inner, offset, s)
            borders[lane.id] = (inner, outer)
            inner = outer
    return borders


WRONG_SIDE_TOLERANCE_M: Final[float] = 0.01
"""How far (m) a lane's outer border may lie on the inner side of its inner border
before ``wrong_side_lanes`` reports it."""
WRONG_SIDE_STEP_M: Final[float] = 1.0
"""Spacing (m) of the stations where ``wrong_side_lanes`` compares the borders (plus each
section's ends)."""


@dataclass(frozen=True)
class WrongSideLane:
    """A lane whose outer border lies on the inner side of its inner border somewhere.

    Fields:
        section: index of its lane section in the road.
        lane_id: its id.
        width_m: its most negative width (m, < -``WRONG_SIDE_TOLERANCE_M``).
        from_borders: drawn from ``<border>`` records (else ``<width>`` records).
    """

    section: int
    lane_id: int
    width_m: float
    from_borders: bool


def wrong_side_lanes(road: Road) -> list[WrongSideLane]:
    """The lanes of ``road`` that run over their inner neighbour: a ``<width>`` polynomial
    below zero (ASAM: widths are not negative), or ``<border>`` records that put the outer
    border on the inner side (a map that writes right lanes' borders as distances,
    positive as crdesigner reads them, instead of t shows it on every such lane)."""
    found = []
    for index, section in enumerate(road.lane_sections):
        bordered = [lane for lane in section.lanes if lane.id != 0 and lane.borders and not lane.widths]
        varying = [lane for lane in section.lanes if lane.widths and not _constant_non_negative(lane.widths)]
        if not bordered and not varying:
            continue
        s = np.unique(np.r_[np.arange(section.s, section.s_end, WRONG_SIDE_STEP_M), section.s_end])
        widths = {lane.id: cubic_poly.evaluate(lane.widths, s, s_offset=section.s) for lane in varying}
        if bordered:
            borders = section_borders(road, index, s)
            widths |= {lane.id: (borders[lane.id][1] - borders[lane.id][0]) * (1.0 if lane.id > 0 else -1.0)
                       for lane in bordered}
        for lane in (lane for lane in section.lanes if lane.id in widths):
            width = float(np.min(widths[lane.id]))
            if width < -WRONG_SIDE_TOLERANCE_M:
                found.append(WrongSideLane(index, lane.id, width, not lane.widths))
    return found


def _constant_non_negative(records: tuple[CubicPoly, ...]) -> bool:
    """Whether every record is a constant a >= 0 (no sampling needed)."""
    return all(r.b == 0.0 and r.c == 0.0 and r.d == 0.0 and r.a >= 0.0 for r in records)


def lane_border_offsets(
    road: Road, section_index: int, lane_id: int, s: NDArrayFloat
) -> tuple[NDArrayFloat, NDArrayFloat]:
    """t (m) of the lane's inner border (nearer lane 0) and outer border at each s (m).

    laneOffset is included. KeyError naming the road when the section has no such lane.
    """
    lane_of(road, section_index, lane_id)
    return section_borders(road, section_index, s, outermost=abs(lane_id))[lane_id]

