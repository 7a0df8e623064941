"""Small hand-built OpenDRIVE maps (model objects) for the lane-graph, routing and CLI tests.

Every lane is 3.5 m wide; reference lines are straight lines or arcs, so lane lengths and
border positions have closed forms.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

from cold_maps.opendrive.model import (
    Connection,
    CubicPoly,
    Geometry,
    Header,
    Junction,
    Lane,
    LaneLink,
    LaneSection,
    OpenDriveMap,
    Road,
    RoadLink,
)

LANE_WIDTH_M = 3.5


def lane(
    lane_id: int,
    *,
    type: str = "driving",
    pred: Sequence[int] = (),
    succ: Sequence[int] = (),
    width: float = LANE_WIDTH_M,
) -> Lane:
    return Lane(
        id=lane_id,
        type=type,
        widths=(CubicPoly(0.0, width, 0.0, 0.0, 0.0),),
        predecessors=tuple(pred),
        successors=tuple(succ),
    )


def section(s: float, s_end: float, left: Sequence[Lane] = (), right: Sequence[Lane] = ()) -> LaneSection:
    """``left``/``right`` ordered from the reference line outwards."""
    return LaneSection(
        s=s, s_end=s_end, single_side=False, left=tuple(left), center=Lane(0, "none"), right=tuple(right)
    )


def road(
    road_id: str,
    length: float,
    sections: Sequence[LaneSection],
    *,
    x: float = 0.0,
    y: float = 0.0,
    hdg: float = 0.0,
    curvature: float = 0.0,
    pred: RoadLink | None = None,
    succ: RoadLink | None = None,
    junction: str = "-1",
    rule: str = "RHT",
) -> Road:
    kind = "arc" if curvature else "line"
    geometry = Geometry(kind=kind, s=0.0, x=x, y=y, hdg=hdg, length=length, curvature=curvature)
    return Road(
        id=road_id,
        name="",
        length=length,
        junction=junction,
        rule=rule,  # type: ignore[arg-type]
        predecessor=pred,
        successor=succ,
        plan_view=(geometry,),
        elevation=(),
        lane_offsets=(),
        lane_sections=tuple(sections),
    )


def to_road(road_id: str, contact: str) -> RoadLink:
    return RoadLink("road", road_id, contact)  # type: ignore[arg-type]


def to_junction(junction_id: str) -> RoadLink:
    return RoadLink("junction", junction_id)


def odr_map(roads: Sequence[Road], junctions: Sequence[Junction] = ()) -> OpenDriveMap:
    return OpenDriveMap(
        path="",
        header=Header(1, 6, name="hand-built"),
        roads={r.id: r for r in roads},
        junctions={j.id: j for j in junctions},
    )


def with_rule(odr: OpenDriveMap, rule: str) -> OpenDriveMap:
    """The same map with every road's traffic rule set to ``rule``."""
    return replace(odr, roads={k: replace(r, rule=rule) for k, r in odr.roads.items()})


def multi_section_map() -> OpenDriveMap:
    """One 100 m road along +x with three sections.

    Section 0 [0, 40): lanes 1 | -1, -2 (no links: same-id fallback).
    Section 1 [40, 70): lanes 1 | -1, -2, -3 (-3 starts here, unlinked).
    Section 2 [70, 100]: lanes 1 | -1, -2; lane -3 of section 1 merges into -2
        (declared only as section 2 lane -2's predecessors -2 and -3).
    A sidewalk lane -4 runs through section 1 only.
    """
    s0 = section(0, 40, left=[lane(1)], right=[lane(-1), lane(-2)])
    s1 = section(
        40, 70, left=[lane(1)], right=[lane(-1), lane(-2), lane(-3), lane(-4, type="sidewalk")]
    )
    s2 = section(70, 100, left=[lane(1)], right=[lane(-1), lane(-2, pred=[-2, -3])])
    return odr_map([road("1", 100.0, [s0, s1, s2])])


def contact_points_map(links_on: str = "both") -> OpenDriveMap:
    """Road A along +x on [0, 100]; road B from (0, 0) towards -x (start/start contact);
    road C from (300, 0) towards -x, ending at A's end (end/end contact).

    ``links_on`` = "both", "A" or "others": which roads declare the links.
    """
    a_links = links_on in ("both", "A")
    o_links = links_on in ("both", "others")

    def two_way(road_id: str, length: float, links: bool, ends: Sequence[str], **kw) -> Road:
        """Lanes 1 and -1, each linked to the other id at the listed road ends."""
        at = {end: links and end in ends for end in ("start", "end")}
        lanes = [
            lane(i, pred=[-i] if at["start"] else [], succ=[-i] if at["end"] else []) for i in (1, -1)
        ]
        return road(road_id, length, [section(0, length, left=lanes[:1], right=lanes[1:])], **kw)

    a = two_way(
        "A",
        100.0,
        a_links,
        ("start", "end"),
        pred=to_road("B", "start") if a_links else None,
        succ=to_road("C", "end") if a_links else None,
    )
    b = two_way("B", 50.0, o_links, ("start",), hdg=math.pi, pred=to_road("A", "start") if o_links else None)
    c = two_way(
        "C", 200.0, o_links, ("end",), x=300.0, hdg=math.pi, succ=to_road("A", "end") if o_links else None
    )
    return odr_map([a, b, c])


JUNCTION_RADIUS_M = 10.0


def junction_map() -> OpenDriveMap:
    """A four-arm junction "J" centred at (10, 0); arms 100 m long, one lane each way.

    Incoming road "W" along +x ends at (0, 0). Outgoing roads start at the box edge:
    "E" at (20, 0) along +x, "N" at (10, 10) along +y, "S" at (10, -10) along -y.
    Connecting roads, all from W's right lane -1:
      "right" (contact start): arc of radius 10 from (0, 0) to S, lane -1;
      "left" (contact start): arc of radius 10 from (0, 0) to N, lane -1;
      "straight" (contact END): line from (20, 0) to (0, 0) along -x, its lane 1
        (left of its reference line, driving against s) carries traffic W → E.
    """
    quarter = JUNCTION_RADIUS_M * math.pi / 2
    one_way = lambda: [section(0, 100, left=[lane(1)], right=[lane(-1)])]  # noqa: E731
    w = road("W", 100.0, one_way(), x=-100.0, succ=to_junction("J"))
    e = road("E", 100.0, one_way(), x=20.0, pred=to_junction("J"))
    n = road("N", 100.0, one_way(), x=10.0, y=10.0, hdg=math.pi / 2, pred=to_junction("J"))
    s = road("S", 100.0, one_way(), x=10.0, y=-10.0, hdg=-math.pi / 2, pred=to_junction("J"))
    def turn(road_id: str, curvature: float, arm: str) -> Road:
        return road(
            road_id,
            quarter,
            [section(0, quarter, right=[lane(-1, pred=[-1], succ=[-1])])],
            curvature=curvature,
            pred=to_road("W", "end"),
            succ=to_road(arm, "start"),
            junction="J",
        )

    right = turn("right", -1 / JUNCTION_RADIUS_M, "S")
    left = turn("left", 1 / JUNCTION_RADIUS_M, "N")
    straight = road(
        "straight",
        20.0,
        [section(0, 20, left=[lane(1, pred=[-1], succ=[-1])])],
        x=20.0,
        hdg=math.pi,
        pred=to_road("E", "start"),
        succ=to_road("W", "end"),
        junction="J",
    )
    junction = Junction(
        "J",
        "four-arm",
        (
            Connection("0", "W", "right", "start", (LaneLink(-1, -1),)),
            Connection("1", "W", "left", "start", (LaneLink(-1, -1),)),
            Connection("2", "W", "straight", "end", (LaneLink(-1, 1),)),
        ),
    )
    return odr_map([w, e, n, s, right, left, straight], [junction])
