"""Small OpenDRIVE maps that stress what public maps do to a run (issue 17): a road just
long enough for a test drive, a one-lane ring whose lap is shorter than the sensor range
plus a spline gap, and links whose ``contactPoint`` contradicts the geometry.

Each builder returns the XML text of one map (``tests/adversarial_maps.py`` writes the
records); lane widths are 3.5 m, reference lines lines and arcs, so lengths and positions
have closed forms.
"""

from __future__ import annotations

import math
from typing import Final

from adversarial_maps import (
    LANE_WIDTH_M,
    LaneSpec,
    RoadSpec,
    SectionSpec,
    document,
    geometry,
    road_link,
)

RING_REFERENCE_RADIUS_M: Final[float] = 4.4
"""Reference-line radius (m) of :func:`small_ring`; lane -1 (right of it, outside the
counter-clockwise ring) has its centre at 4.4 + 1.75 = 6.15 m: a 38.6 m lap."""
CONTRADICTING_ROAD_M: Final[float] = 50.0
"""Length (m) of roads 1 and 2 of :func:`contradicting_links`."""
CONNECTING_ROAD_M: Final[float] = 20.0
"""Length (m) of the connecting road 3 of :func:`contradicting_links`."""
EXIT_ROAD_M: Final[float] = 100.0
"""Length (m) of road 4 of :func:`contradicting_links`."""


def ring_lap_m(radius_m: float = RING_REFERENCE_RADIUS_M) -> float:
    """Centreline lap (m) of lane -1 of :func:`small_ring`."""
    return 2.0 * math.pi * (radius_m + LANE_WIDTH_M / 2)


def straight_road(length_m: float = 200.0) -> str:
    """One straight two-way road (lanes 1 and -1) of ``length_m`` along +x from the origin."""
    section = SectionSpec(0.0, (LaneSpec(1), LaneSpec(-1)))
    return document([RoadSpec("1", (geometry(0.0, 0.0, 0.0, 0.0, length_m, "<line/>"),), length_m, (section,))],
                    name="straight-road")


def small_ring(radius_m: float = RING_REFERENCE_RADIUS_M, pieces: int = 2) -> str:
    """A one-way, one-lane ring: ``pieces`` equal arc roads (counter-clockwise reference
    arcs of ``radius_m`` around the origin, lane -1 outside), each the next one's
    predecessor."""
    piece = 2.0 * math.pi * radius_m / pieces
    roads = []
    for index in range(pieces):
        angle = 2.0 * math.pi * index / pieces
        x, y, hdg = radius_m * math.cos(angle), radius_m * math.sin(angle), angle + math.pi / 2
        before, after = str((index - 1) % pieces + 1), str((index + 1) % pieces + 1)
        section = SectionSpec(0.0, (LaneSpec(-1, predecessor=-1, successor=-1),))
        roads.append(RoadSpec(str(index + 1), (geometry(0.0, x, y, hdg, piece, f'<arc curvature="{1 / radius_m!r}"/>'),),
                              piece, (section,), predecessor=road_link("predecessor", "road", before, "end"),
                              successor=road_link("successor", "road", after, "start")))
    return document(roads, name="small-ring")


def contradicting_links(*, contradict: bool = True) -> str:
    """Roads 1 → 2 → junction 9 → connecting road 3 → road 4, driven along +x on one lane
    (220 m in all), with ``contactPoint``s that contradict the geometry when ``contradict``:

    - road 1 (x 0..50, along +x, lane -1) ends where road 2 *ends*: road 2 is drawn
      backwards (x 100..50, lane 1 drives along +x), yet road 1's successor and road 2's
      successor name the other's ``start`` (50 m away);
    - road 2's start (x 100) leads into junction 9, whose connecting road 3 (x 100..120,
      lane -1) starts there; the connection names its ``end`` (20 m away);
    - road 4 (x 120..220, two-way) follows road 3.

    Lane links agree with the geometry. With ``contradict`` False every contact point is
    the one the geometry says.
    """
    wrong = "start" if contradict else "end"
    road_m, link_m, exit_m = CONTRADICTING_ROAD_M, CONNECTING_ROAD_M, EXIT_ROAD_M
    roads = [
        RoadSpec("1", (geometry(0.0, 0.0, 0.0, 0.0, road_m, "<line/>"),), road_m,
                 (SectionSpec(0.0, (LaneSpec(-1, successor=1),)),),
                 successor=road_link("successor", "road", "2", wrong)),
        RoadSpec("2", (geometry(0.0, 2 * road_m, 0.0, math.pi, road_m, "<line/>"),), road_m,
                 (SectionSpec(0.0, (LaneSpec(1, successor=-1),)),),
                 predecessor=road_link("predecessor", "junction", "9"),
                 successor=road_link("successor", "road", "1", wrong)),
        RoadSpec("3", (geometry(0.0, 2 * road_m, 0.0, 0.0, link_m, "<line/>"),), link_m,
                 (SectionSpec(0.0, (LaneSpec(-1, predecessor=1, successor=-1),)),), junction="9",
                 predecessor=road_link("predecessor", "road", "2", "start"),
                 successor=road_link("successor", "road", "4", "start")),
        RoadSpec("4", (geometry(0.0, 2 * road_m + link_m, 0.0, 0.0, exit_m, "<line/>"),), exit_m,
                 (SectionSpec(0.0, (LaneSpec(1), LaneSpec(-1, predecessor=-1))),),
                 predecessor=road_link("predecessor", "road", "3", "end")),
    ]
    contact = "end" if contradict else "start"
    junction = (f'<junction id="9" name="j"><connection id="0" incomingRoad="2" connectingRoad="3" '
                f'contactPoint="{contact}"><laneLink from="1" to="-1"/></connection></junction>')
    return document(roads, junctions=junction, name="contradicting-links")


REVERSED_ROAD_M: Final[float] = 300.0
"""Length (m) of the road of :func:`reversed_lane_road` (along +x from the origin)."""
REVERSED_LEFT_WIDTH_M: Final[float] = 4.0
"""Width (m) of lane 1 of :func:`reversed_lane_road`."""
REVERSED_RIGHT_WIDTH_M: Final[float] = 3.0
"""Width (m) of lane -1 (``direction="reversed"``) of :func:`reversed_lane_road`."""


def reversed_lane_road(*, lht_predecessor: bool = False) -> str:
    """One straight RHT road 1 (x 0..300 along +x): lane 1 driving (4 m, y 0..4), lane -1
    driving with ``direction="reversed"`` (3 m, y -3..0), so both are driven along -x.

    With ``lht_predecessor`` an LHT road 2 (x -300..0 along +x) precedes it: its lane -1
    (3 m, y -3..0) is driven along -x by its rule and continues lane -1 of road 1, whose
    borders meet it exactly.
    """
    length = REVERSED_ROAD_M
    widths = {1: REVERSED_LEFT_WIDTH_M, -1: REVERSED_RIGHT_WIDTH_M}
    lanes = (
        LaneSpec(1, widths=((0.0, widths[1], 0.0, 0.0, 0.0),)),
        LaneSpec(-1, widths=((0.0, widths[-1], 0.0, 0.0, 0.0),), direction="reversed",
                 predecessor=-1 if lht_predecessor else None),
    )
    link = road_link("predecessor", "road", "2", "end") if lht_predecessor else ""
    roads = [RoadSpec("1", (geometry(0.0, 0.0, 0.0, 0.0, length, "<line/>"),), length, (SectionSpec(0.0, lanes),),
                      predecessor=link)]
    if lht_predecessor:
        before = SectionSpec(0.0, (LaneSpec(-1, widths=((0.0, widths[-1], 0.0, 0.0, 0.0),), successor=-1),))
        roads.append(RoadSpec("2", (geometry(0.0, -length, 0.0, 0.0, length, "<line/>"),), length, (before,),
                              rule="LHT", successor=road_link("successor", "road", "1", "start")))
    return document(roads, name="reversed-lane")


HELIX_RADIUS_M: Final[float] = 20.0
"""Reference-line radius (m) of :func:`helical_ramp`."""
HELIX_RISE_M: Final[float] = 3.0
"""Height (m) :func:`helical_ramp` climbs per turn."""
HELIX_APPROACH_M: Final[float] = 100.0
"""Length (m) of the straight roads before and after the turns of :func:`helical_ramp`."""


def helical_ramp(turns: int = 2) -> str:
    """A one-lane parking ramp: road 1 (100 m along +x to (0, -20)), ``turns`` counter-
    clockwise turns of radius 20 m around the origin in quarter-turn roads 10, 11, ...
    climbing 3 m per turn (the turns lie on one another in x, y), then road 2 (100 m along
    +x from (0, -20) at the top). Lane -1 (outside the turns) is driven."""
    radius, quarter = HELIX_RADIUS_M, math.pi * HELIX_RADIUS_M / 2
    slope = HELIX_RISE_M / (2.0 * math.pi * radius)
    pieces = [str(10 + k) for k in range(4 * turns)]
    order = ["1", *pieces, "2"]

    def links(road_id: str) -> dict[str, str]:
        at = order.index(road_id)
        found = {}
        if at > 0:
            found["predecessor"] = road_link("predecessor", "road", order[at - 1], "end")
        if at + 1 < len(order):
            found["successor"] = road_link("successor", "road", order[at + 1], "start")
        return found

    def lanes(road_id: str) -> tuple[SectionSpec, ...]:
        at = order.index(road_id)
        lane = LaneSpec(-1, predecessor=-1 if at > 0 else None, successor=-1 if at + 1 < len(order) else None)
        return (SectionSpec(0.0, (lane,)),)

    approach = HELIX_APPROACH_M
    roads = [RoadSpec("1", (geometry(0.0, -approach, -radius, 0.0, approach, "<line/>"),), approach, lanes("1"),
                      **links("1"))]
    heights = {"1": (0.0, 0.0), "2": (turns * HELIX_RISE_M, 0.0)}
    for k, road_id in enumerate(pieces):
        angle = -math.pi / 2 + k * math.pi / 2
        record = geometry(0.0, radius * math.cos(angle), radius * math.sin(angle), angle + math.pi / 2, quarter,
                          f'<arc curvature="{1 / radius!r}"/>')
        roads.append(RoadSpec(road_id, (record,), quarter, lanes(road_id), **links(road_id)))
        heights[road_id] = (k * quarter * slope, slope)
    roads.append(RoadSpec("2", (geometry(0.0, 0.0, -radius, 0.0, approach, "<line/>"),), approach, lanes("2"),
                          **links("2")))
    text = document(roads, name="helical-ramp")
    for road_id, (a, b) in heights.items():
        end = text.index("</planView>", text.index(f'<road id="{road_id}" ')) + len("</planView>")
        text = (text[:end] + f'<elevationProfile><elevation s="0" a="{a!r}" b="{b!r}" c="0" d="0"/>'
                "</elevationProfile>" + text[end:])
    return text
