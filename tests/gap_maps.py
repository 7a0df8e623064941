"""OpenDRIVE maps whose consecutive lane ends do not quite touch (issue 17's reproduction).

``branch_gap_map``: road 1, a 40 m straight along +x with one lane -1 (3.5 m), ends in
junction 100 with two connecting roads: road 2, a 20 m straight that starts ``straight_offset_m``
to the side of road 1's end (negative y = to the right) and runs into road 4, an 80 m
straight; road 3, a 10 m right arc (radius ``ARC_RADIUS_M``) that starts ``arc_offset_m``
to the side, optionally followed by road 5, an 80 m straight. Every lane is a 3.5 m lane
-1 driving along +s, so the lane ends are displaced by exactly the offsets.
"""

from __future__ import annotations

from typing import Final

from tests.adversarial_maps import LaneSpec, RoadSpec, SectionSpec, _arc_end, document, geometry, road_link

ROAD1_LENGTH_M: Final[float] = 40.0
STRAIGHT_LENGTH_M: Final[float] = 20.0
EXIT_LENGTH_M: Final[float] = 80.0
ARC_LENGTH_M: Final[float] = 10.0
ARC_RADIUS_M: Final[float] = 20.0
JUNCTION_ID: Final[str] = "100"


def _lane(predecessor: bool, successor: bool) -> SectionSpec:
    return SectionSpec(0.0, (LaneSpec(-1, predecessor=-1 if predecessor else None, successor=-1 if successor else None),))


def branch_gap_map(straight_offset_m: float = 0.02, arc_offset_m: float = 0.0, *, arc_exit: bool = False) -> str:
    """The junction of issue 17 with the connecting roads' starts displaced sideways by the
    offsets (m, to the left of road 1's driving direction when positive)."""
    to_junction = road_link("successor", "junction", JUNCTION_ID)
    from_junction = road_link("predecessor", "junction", JUNCTION_ID)
    roads = [
        RoadSpec("1", (geometry(0.0, 0.0, 0.0, 0.0, ROAD1_LENGTH_M, "<line/>"),), ROAD1_LENGTH_M,
                 (_lane(False, True),), successor=to_junction),
        RoadSpec("2", (geometry(0.0, ROAD1_LENGTH_M, straight_offset_m, 0.0, STRAIGHT_LENGTH_M, "<line/>"),),
                 STRAIGHT_LENGTH_M, (_lane(True, True),), junction=JUNCTION_ID,
                 predecessor=road_link("predecessor", "road", "1", "end"),
                 successor=road_link("successor", "road", "4", "start")),
        RoadSpec("4", (geometry(0.0, ROAD1_LENGTH_M + STRAIGHT_LENGTH_M, straight_offset_m, 0.0, EXIT_LENGTH_M,
                                "<line/>"),), EXIT_LENGTH_M, (_lane(True, False),), predecessor=from_junction),
    ]  # fmt: skip
    curvature = -1.0 / ARC_RADIUS_M
    x, y, hdg = _arc_end(ROAD1_LENGTH_M, arc_offset_m, 0.0, ARC_LENGTH_M, curvature)
    arc_successor = road_link("successor", "road", "5", "start") if arc_exit else ""
    roads.append(RoadSpec("3", (geometry(0.0, ROAD1_LENGTH_M, arc_offset_m, 0.0, ARC_LENGTH_M,
                                         f'<arc curvature="{curvature!r}"/>'),), ARC_LENGTH_M,
                          (_lane(True, arc_exit),), junction=JUNCTION_ID,
                          predecessor=road_link("predecessor", "road", "1", "end"), successor=arc_successor))  # fmt: skip
    if arc_exit:
        roads.append(RoadSpec("5", (geometry(0.0, x, y, hdg, EXIT_LENGTH_M, "<line/>"),), EXIT_LENGTH_M,
                              (_lane(True, False),), predecessor=from_junction))  # fmt: skip
    connections = "".join(
        f'<connection id="{i}" incomingRoad="1" connectingRoad="{road}" contactPoint="start">'
        '<laneLink from="-1" to="-1"/></connection>'
        for i, road in enumerate(("2", "3"))
    )
    return document(roads, junctions=f'<junction id="{JUNCTION_ID}" name="branch">{connections}</junction>',
                    name="branch-gap")

