"""Deterministic generator of the bundled OpenDRIVE 1.6 scenario maps (``maps/*.xodr``).

Usage: ``python tools/make_maps.py [--out DIR] [--check]``. ``--check`` writes nothing and
exits 1 when a file in DIR differs byte for byte from what would be generated.

Every reference-line record starts exactly at the analytically computed end pose of the
previous one (line, arc, clothoid via Fresnel integrals); connecting roads start and end
on the reference-line ends of the roads they link. Numbers are printed with
``SIGNIFICANT_DIGITS`` significant digits in positional notation, so the output is
byte-identical across runs and machines. All lanes are ``LANE_WIDTH_M`` wide (the paper's
4 m) except a lane that opens from zero width. Frames: OpenDRIVE inertial (x east, y north,
heading counter-clockwise from x), right-hand traffic.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Final, Literal, Mapping, Sequence

from cold_maps.opendrive.model import Connection, ContactPoint, CubicPoly, Junction, LaneLink, RoadLink

if TYPE_CHECKING:
    from lxml import etree

LANE_WIDTH_M: Final[float] = 4.0
DATE: Final[str] = "2026-01-01T00:00:00"
VENDOR: Final[str] = "cold-maps tools/make_maps.py"
SIGNIFICANT_DIGITS: Final[int] = 12
DEFAULT_OUT_DIR: Final[Path] = Path(__file__).resolve().parents[1] / "maps"
RURAL_GEO_REFERENCE: Final[str] = (
    "+proj=tmerc +lat_0=48.137 +lon_0=11.575 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
)

SegmentKind = Literal["line", "arc", "spiral"]


def fmt(value: float) -> str:
    """A float as fixed positional text with ``SIGNIFICANT_DIGITS`` significant digits."""
    if not math.isfinite(value):
        raise ValueError(f"cannot write non-finite number {value!r}")
    text = f"{value:.{SIGNIFICANT_DIGITS}g}"
    if "e" in text:
        text = format(Decimal(text), "f")
    return "0" if float(text) == 0.0 else text


def normalize_angle(angle: float) -> float:
    """The angle (rad) wrapped into (-π, π]."""
    wrapped = math.remainder(angle, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


@dataclass(frozen=True, slots=True)
class Pose:
    """A point on a reference line: x, y (m, inertial) and heading hdg (rad)."""

    x: float
    y: float
    hdg: float


@dataclass(frozen=True, slots=True)
class Segment:
    """One planView record before placement.

    Fields:
        kind: "line", "arc" or "spiral".
        length: arc length (m, > 0).
        curv_start, curv_end: curvature at start and end (1/m, positive = left turn);
            both 0 for a line, equal for an arc.
    """

    kind: SegmentKind
    length: float
    curv_start: float = 0.0
    curv_end: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.length) and self.length > 0.0):
            raise ValueError(f"{self.kind} segment: length must be > 0 m, got {self.length!r}")
        if self.kind != "spiral" and self.curv_start != self.curv_end:
            raise ValueError(f"{self.kind} segment: constant curvature expected")


def line(length: float) -> Segment:
    """A straight record of ``length`` m."""
    return Segment("line", length)


def arc(length: float, curvature: float) -> Segment:
    """A circular record of ``length`` m and ``curvature`` 1/m (positive = left)."""
    if curvature == 0.0:
        raise ValueError("arc segment: curvature must be non-zero")
    return Segment("arc", length, curvature, curvature)


def spiral(length: float, curv_start: float, curv_end: float) -> Segment:
    """A clothoid of ``length`` m with curvature linear from ``curv_start`` to ``curv_end``."""
    if curv_start == curv_end:
        raise ValueError("spiral segment: start and end curvature must differ")
    return Segment("spiral", length, curv_start, curv_end)


def end_pose(start: Pose, seg: Segment) -> Pose:
    """Pose at the end of ``seg`` placed at ``start`` (closed forms, no sampling)."""
    k0, length = seg.curv_start, seg.length
    if seg.kind == "line":
        return Pose(
            start.x + length * math.cos(start.hdg), start.y + length * math.sin(start.hdg), start.hdg
        )
    if seg.kind == "arc":
        hdg = start.hdg + k0 * length
        return Pose(
            start.x + (math.sin(hdg) - math.sin(start.hdg)) / k0,
            start.y - (math.cos(hdg) - math.cos(start.hdg)) / k0,
            hdg,
        )
    from scipy.special import fresnel

    # θ(s) = hdg + k0 s + c s²/2 = φ + (c/2)(s + k0/c)²; substituting τ = (s + k0/c)·√(|c|/π)
    # turns ∫exp(iθ) ds into √(π/|c|)·exp(iφ)·[C(τ) ± i S(τ)] between the end values of τ.
    rate = (seg.curv_end - k0) / length
    scale = math.sqrt(math.pi / abs(rate))
    sign = 1.0 if rate > 0.0 else -1.0
    s_at_zero_curvature = k0 / rate
    phi = start.hdg - k0 * k0 / (2.0 * rate)
    fresnel_s, fresnel_c = fresnel(
        [s_at_zero_curvature / scale, (length + s_at_zero_curvature) / scale]
    )
    delta_c = float(fresnel_c[1] - fresnel_c[0])
    delta_s = sign * float(fresnel_s[1] - fresnel_s[0])
    return Pose(
        start.x + scale * (math.cos(phi) * delta_c - math.sin(phi) * delta_s),
        start.y + scale * (math.sin(phi) * delta_c + math.cos(phi) * delta_s),
        start.hdg + k0 * length + 0.5 * rate * length * length,
    )


def chain_end(start: Pose, segments: Sequence[Segment]) -> Pose:
    """Pose at the end of ``segments`` laid out one after another from ``start``."""
    pose = start
    for seg in segments:
        pose = end_pose(pose, seg)
    return pose


def reverse(pose: Pose) -> Pose:
    """The same point facing the other way."""
    return Pose(pose.x, pose.y, pose.hdg + math.pi)


def smooth_step(s_from: float, length: float, value_from: float, value_to: float) -> tuple[CubicPoly, ...]:
    """Records holding ``value_from`` until ``s_from``, a C¹ cubic to ``value_to`` over
    ``length`` m, then ``value_to``; starts at s0 = 0 (a leading constant record when
    ``s_from`` > 0)."""
    delta = value_to - value_from
    ramp = CubicPoly(s_from, value_from, 0.0, 3.0 * delta / length**2, -2.0 * delta / length**3)
    hold = CubicPoly(s_from + length, value_to, 0.0, 0.0, 0.0)
    lead = (CubicPoly(0.0, value_from, 0.0, 0.0, 0.0),) if s_from > 0.0 else ()
    return lead + (ramp, hold)


def constant(value: float) -> tuple[CubicPoly, ...]:
    """A single constant record from s0 = 0."""
    return (CubicPoly(0.0, value, 0.0, 0.0, 0.0),)


@dataclass(frozen=True, slots=True)
class LaneSpec:
    """One lane of a lane section.

    Fields:
        id: OpenDRIVE lane id (non-zero).
        widths: width records, s0 relative to the section start (m).
        mark: roadMark type of the lane's outer border ("solid", "broken", "none").
        predecessor, successor: linked lane id in the previous / next section or linked
            road (None when unlinked).
        type: OpenDRIVE lane type.
    """

    id: int
    widths: tuple[CubicPoly, ...]
    mark: str
    predecessor: int | None = None
    successor: int | None = None
    type: str = "driving"


@dataclass(frozen=True, slots=True)
class SectionSpec:
    """A lane section: start s (m along the road), centre-line roadMark, and its lanes."""

    s: float
    center_mark: str
    lanes: tuple[LaneSpec, ...]


@dataclass(frozen=True, slots=True)
class RoadSpec:
    """A road before serialisation.

    Fields:
        id, name: road id and name.
        start: pose of the reference-line start (inertial).
        segments: planView records in order.
        sections: lane sections ordered by s.
        road_type, speed_kmh: ``<type>`` and its maximum speed (km/h).
        predecessor, successor: road links (None when open).
        junction: id of the junction the road belongs to, "-1" when none.
        lane_offsets: laneOffset records, s0 absolute (m); empty for none.
        rule: traffic rule, "RHT" or "LHT" (left lanes drive along +s).
    """

    id: str
    name: str
    start: Pose
    segments: tuple[Segment, ...]
    sections: tuple[SectionSpec, ...]
    road_type: str
    speed_kmh: float
    predecessor: RoadLink | None = None
    successor: RoadLink | None = None
    junction: str = "-1"
    lane_offsets: tuple[CubicPoly, ...] = ()
    rule: str = "RHT"

    @property
    def length(self) -> float:
        """Reference-line length (m)."""
        return math.fsum(seg.length for seg in self.segments)

    @property
    def end(self) -> Pose:
        """Pose at the reference-line end."""
        return chain_end(self.start, self.segments)


@dataclass(frozen=True, slots=True)
class MapSpec:
    """A whole map: file stem, roads, junctions, an optional PROJ geoReference string and
    the header's vendor (what made it)."""

    name: str
    roads: tuple[RoadSpec, ...]
    junctions: tuple[Junction, ...] = ()
    geo_reference: str = ""
    vendor: str = VENDOR


def carriageway_lanes(
    left: int,
    right: int,
    *,
    link_back: bool = True,
    link_ahead: bool = True,
    opening_m: float = 0.0,
) -> tuple[LaneSpec, ...]:
    """``left`` lanes (ids 1..left) and ``right`` lanes (ids -1..-right), each
    ``LANE_WIDTH_M`` wide, linked to the same id behind/ahead when asked; broken marks
    between lanes, solid on the outer edges. With ``opening_m`` > 0 the outermost right
    lane is new: it opens from zero width over ``opening_m`` m and has no predecessor."""
    lanes = []
    for count, sign in ((left, 1), (right, -1)):
        for index in range(1, count + 1):
            lane_id = sign * index
            opens = opening_m > 0.0 and lane_id == -right
            lanes.append(
                LaneSpec(
                    lane_id,
                    smooth_step(0.0, opening_m, 0.0, LANE_WIDTH_M) if opens else constant(LANE_WIDTH_M),
                    "solid" if index == count else "broken",
                    predecessor=lane_id if link_back and not opens else None,
                    successor=lane_id if link_ahead else None,
                )
            )
    return tuple(lanes)


def build_straight() -> MapSpec:
    """1 km straight road, two driving lanes per direction."""
    road = RoadSpec(
        "1", "straight", Pose(0.0, 0.0, 0.0), (line(1000.0),),
        (SectionSpec(0.0, "solid", carriageway_lanes(2, 2, link_back=False, link_ahead=False)),),
        "rural", 100.0,
    )
    return MapSpec("straight", (road,))


CURVE_RADIUS_M: Final[float] = 20.0
CURVE_STRAIGHT_M: Final[float] = 150.0


def build_curve90() -> MapSpec:
    """Straight, 90° right curve of reference-line radius 20 m, straight; one lane per direction."""
    segments = (
        line(CURVE_STRAIGHT_M),
        arc(0.5 * math.pi * CURVE_RADIUS_M, -1.0 / CURVE_RADIUS_M),
        line(CURVE_STRAIGHT_M),
    )
    road = RoadSpec(
        "1", "curve90", Pose(0.0, 0.0, 0.0), segments,
        (SectionSpec(0.0, "solid", carriageway_lanes(1, 1, link_back=False, link_ahead=False)),),
        "town", 50.0,
    )
    return MapSpec("curve90", (road,))


def clothoid_curve(radius: float, arc_length: float, spiral_in: float, spiral_out: float) -> tuple[Segment, ...]:
    """Spiral from straight into an arc of signed ``radius`` (m, positive = left), the arc,
    and a spiral back to straight."""
    curvature = 1.0 / radius
    return (
        spiral(spiral_in, 0.0, curvature),
        arc(arc_length, curvature),
        spiral(spiral_out, curvature, 0.0),
    )


def build_rural() -> MapSpec:
    """A 1.7 km winding two-lane road: clothoid-eased left and right arcs of radius
    30-300 m, straights, and an S-bend; carries a tmerc geoReference."""
    segments = (
        line(150.0),
        *clothoid_curve(150.0, 100.0, 40.0, 40.0),
        line(120.0),
        *clothoid_curve(-80.0, 90.0, 50.0, 50.0),
        line(80.0),
        spiral(40.0, 0.0, 1.0 / 60.0),
        arc(60.0, 1.0 / 60.0),
        spiral(60.0, 1.0 / 60.0, -1.0 / 100.0),
        arc(80.0, -1.0 / 100.0),
        spiral(40.0, -1.0 / 100.0, 0.0),
        line(150.0),
        *clothoid_curve(-300.0, 150.0, 30.0, 30.0),
        line(100.0),
        *clothoid_curve(30.0, 40.0, 30.0, 30.0),
        line(150.0),
    )
    road = RoadSpec(
        "1", "rural", Pose(0.0, 0.0, 0.0), segments,
        (SectionSpec(0.0, "broken", carriageway_lanes(1, 1, link_back=False, link_ahead=False)),),
        "rural", 80.0,
    )
    return MapSpec("rural", (road,), geo_reference=RURAL_GEO_REFERENCE)


JUNCTION_ID: Final[str] = "100"
JUNCTION_HALF_SIZE_M: Final[float] = 15.0
ARM_LENGTH_M: Final[float] = 150.0
ARM_NAMES: Final[tuple[str, ...]] = ("east", "north", "west", "south")


def build_junction() -> MapSpec:
    """Four-way junction: four 150 m two-lane arms (east and north arms start at the
    junction, west and south arms end there) and 12 one-lane connecting roads (right turn
    and left turn arcs of reference radius 15 m, 30 m straight lines)."""
    junction_link = RoadLink("junction", JUNCTION_ID)
    arms: list[RoadSpec] = []
    starts_at_junction = (True, True, False, False)
    for index, (name, at_start) in enumerate(zip(ARM_NAMES, starts_at_junction)):
        out_angle = index * 0.5 * math.pi
        near = Pose(JUNCTION_HALF_SIZE_M * math.cos(out_angle), JUNCTION_HALF_SIZE_M * math.sin(out_angle), out_angle)
        far = end_pose(near, line(ARM_LENGTH_M))
        start = near if at_start else reverse(far)
        lanes = carriageway_lanes(1, 1, link_back=False, link_ahead=False)
        arms.append(
            RoadSpec(
                str(index + 1), f"arm_{name}", start, (line(ARM_LENGTH_M),),
                (SectionSpec(0.0, "solid", lanes),), "town", 50.0,
                predecessor=junction_link if at_start else None,
                successor=None if at_start else junction_link,
            )
        )

    connecting: list[RoadSpec] = []
    connections: list[Connection] = []
    movements = ((1, "right", -1.0), (2, "straight", 0.0), (3, "left", 1.0))
    for i, arm_in in enumerate(arms):
        contact_in: ContactPoint = "start" if starts_at_junction[i] else "end"
        lane_in = 1 if starts_at_junction[i] else -1
        entry = reverse(arm_in.start) if starts_at_junction[i] else arm_in.end
        for step, movement, turn in movements:
            j = (i + step) % 4
            contact_out: ContactPoint = "start" if starts_at_junction[j] else "end"
            lane_out = -1 if starts_at_junction[j] else 1
            if turn == 0.0:
                segment = line(2.0 * JUNCTION_HALF_SIZE_M)
            else:
                segment = arc(0.5 * math.pi * JUNCTION_HALF_SIZE_M, turn / JUNCTION_HALF_SIZE_M)
            road_id = str(101 + 3 * i + step - 1)
            lane = LaneSpec(-1, constant(LANE_WIDTH_M), "solid", predecessor=lane_in, successor=lane_out)
            connecting.append(
                RoadSpec(
                    road_id, f"{ARM_NAMES[i]}_{movement}_{ARM_NAMES[j]}", entry, (segment,),
                    (SectionSpec(0.0, "none", (lane,)),), "town", 30.0 if turn else 50.0,
                    predecessor=RoadLink("road", arm_in.id, contact_in),
                    successor=RoadLink("road", arms[j].id, contact_out),
                    junction=JUNCTION_ID,
                )
            )
            connections.append(Connection(str(len(connections)), arm_in.id, road_id, "start", (LaneLink(lane_in, -1),)))
    junction = Junction(JUNCTION_ID, "crossroads", tuple(connections))
    return MapSpec("junction", tuple(arms) + tuple(connecting), (junction,))


HIGHWAY_LANE_OFFSET_M: Final[float] = 2.0
EXIT_SECTION_S_M: Final[float] = 400.0
EXIT_OPENING_M: Final[float] = 100.0
RAMP_CURVATURE: Final[float] = -1.0 / 150.0


def build_highway() -> MapSpec:
    """Three lanes per direction with a laneOffset shift, a fourth right lane opening from
    zero width, and a junction where the main carriageway continues and the exit lane
    diverges onto a ramp curving away to the right."""
    junction_id = "100"
    junction_link = RoadLink("junction", junction_id)
    main_in = RoadSpec(
        "1", "main_before_exit", Pose(0.0, 0.0, 0.0),
        (line(150.0), spiral(80.0, 0.0, 1.0 / 800.0), arc(90.0, 1.0 / 800.0), spiral(80.0, 1.0 / 800.0, 0.0), line(200.0)),
        (
            SectionSpec(0.0, "solid", carriageway_lanes(3, 3, link_back=False)),
            SectionSpec(EXIT_SECTION_S_M, "solid", carriageway_lanes(3, 4, link_ahead=False, opening_m=EXIT_OPENING_M)),
        ),
        "motorway", 130.0,
        successor=junction_link,
        lane_offsets=smooth_step(150.0, 100.0, 0.0, HIGHWAY_LANE_OFFSET_M),
    )
    # The exit lane -4 spans t in [offset - 4w, offset - 3w] on road 1; the ramp roads keep
    # their reference line on road 1's and shift their single lane there by a laneOffset.
    ramp_offset = HIGHWAY_LANE_OFFSET_M - 3.0 * LANE_WIDTH_M
    through = RoadSpec(
        "10", "main_through_exit", main_in.end, (line(30.0),),
        (SectionSpec(0.0, "solid", carriageway_lanes(3, 3)),),
        "motorway", 130.0,
        predecessor=RoadLink("road", "1", "end"), successor=RoadLink("road", "2", "start"),
        junction=junction_id, lane_offsets=constant(HIGHWAY_LANE_OFFSET_M),
    )
    exit_lane = LaneSpec(-1, constant(LANE_WIDTH_M), "solid", predecessor=-4, successor=-1)
    diverge = RoadSpec(
        "11", "exit_diverge", main_in.end, (spiral(40.0, 0.0, RAMP_CURVATURE),),
        (SectionSpec(0.0, "solid", (exit_lane,)),),
        "motorway", 80.0,
        predecessor=RoadLink("road", "1", "end"), successor=RoadLink("road", "3", "start"),
        junction=junction_id, lane_offsets=constant(ramp_offset),
    )
    main_out = RoadSpec(
        "2", "main_after_exit", through.end, (line(300.0),),
        (SectionSpec(0.0, "solid", carriageway_lanes(3, 3, link_back=False, link_ahead=False)),),
        "motorway", 130.0,
        predecessor=junction_link,
        lane_offsets=smooth_step(100.0, 100.0, HIGHWAY_LANE_OFFSET_M, 0.0),
    )
    ramp = RoadSpec(
        "3", "exit_ramp", diverge.end,
        (arc(80.0, RAMP_CURVATURE), spiral(40.0, RAMP_CURVATURE, 0.0), line(150.0)),
        (SectionSpec(0.0, "solid", (LaneSpec(-1, constant(LANE_WIDTH_M), "solid"),)),),
        "motorway", 80.0,
        predecessor=junction_link, lane_offsets=constant(ramp_offset),
    )
    connections = (
        Connection("0", "1", "10", "start", tuple(LaneLink(-i, -i) for i in (1, 2, 3))),
        Connection("1", "1", "11", "start", (LaneLink(-4, -1),)),
        Connection("2", "2", "10", "end", tuple(LaneLink(i, i) for i in (1, 2, 3))),
    )
    junction = Junction(junction_id, "exit", connections)
    return MapSpec("highway", (main_in, main_out, ramp, through, diverge), (junction,))


BUILDERS: Final[Mapping[str, Callable[[], MapSpec]]] = {
    "straight": build_straight,
    "curve90": build_curve90,
    "rural": build_rural,
    "junction": build_junction,
    "highway": build_highway,
}


def _attrs(element: etree._Element, **values: object) -> None:
    for key, value in values.items():
        element.set(key, fmt(value) if isinstance(value, float) else str(value))


def _poly(parent: etree._Element, tag: str, poly: CubicPoly, s_name: str) -> None:
    from lxml import etree

    _attrs(etree.SubElement(parent, tag), **{s_name: poly.s0}, a=poly.a, b=poly.b, c=poly.c, d=poly.d)


def _road_mark(parent: etree._Element, mark: str) -> None:
    from lxml import etree

    _attrs(
        etree.SubElement(parent, "roadMark"), sOffset=0.0, type=mark, weight="standard",
        color="standard", width=0.12 if mark != "none" else 0.0,
        laneChange="both" if mark == "broken" else "none",
    )


def _lane(parent: etree._Element, lane: LaneSpec) -> None:
    from lxml import etree

    element = etree.SubElement(parent, "lane")
    _attrs(element, id=lane.id, type=lane.type, level="false")
    link = etree.SubElement(element, "link")
    if lane.predecessor is not None:
        _attrs(etree.SubElement(link, "predecessor"), id=lane.predecessor)
    if lane.successor is not None:
        _attrs(etree.SubElement(link, "successor"), id=lane.successor)
    for width in lane.widths:
        _poly(element, "width", width, "sOffset")
    _road_mark(element, lane.mark)


def _road_link(parent: etree._Element, tag: str, link: RoadLink | None) -> None:
    from lxml import etree

    if link is None:
        return
    element = etree.SubElement(parent, tag)
    _attrs(element, elementType=link.element_type, elementId=link.element_id)
    if link.contact_point is not None:
        element.set("contactPoint", link.contact_point)


def _road(parent: etree._Element, road: RoadSpec) -> None:
    from lxml import etree

    element = etree.SubElement(parent, "road")
    _attrs(element, name=road.name, length=road.length, id=road.id, junction=road.junction, rule=road.rule)
    link = etree.SubElement(element, "link")
    _road_link(link, "predecessor", road.predecessor)
    _road_link(link, "successor", road.successor)
    road_type = etree.SubElement(element, "type")
    _attrs(road_type, s=0.0, type=road.road_type)
    _attrs(etree.SubElement(road_type, "speed"), max=road.speed_kmh, unit="km/h")

    plan_view = etree.SubElement(element, "planView")
    pose, s = road.start, 0.0
    for seg in road.segments:
        geometry = etree.SubElement(plan_view, "geometry")
        _attrs(geometry, s=s, x=pose.x, y=pose.y, hdg=normalize_angle(pose.hdg), length=seg.length)
        if seg.kind == "line":
            etree.SubElement(geometry, "line")
        elif seg.kind == "arc":
            _attrs(etree.SubElement(geometry, "arc"), curvature=seg.curv_start)
        else:
            _attrs(etree.SubElement(geometry, "spiral"), curvStart=seg.curv_start, curvEnd=seg.curv_end)
        pose, s = end_pose(pose, seg), s + seg.length

    _poly(etree.SubElement(element, "elevationProfile"), "elevation", CubicPoly(0.0, 0.0, 0.0, 0.0, 0.0), "s")
    etree.SubElement(element, "lateralProfile")
    lanes = etree.SubElement(element, "lanes")
    for offset in road.lane_offsets:
        _poly(lanes, "laneOffset", offset, "s")
    for section in road.sections:
        section_element = etree.SubElement(lanes, "laneSection")
        _attrs(section_element, s=section.s)
        left = sorted((lane for lane in section.lanes if lane.id > 0), key=lambda lane: -lane.id)
        right = sorted((lane for lane in section.lanes if lane.id < 0), key=lambda lane: -lane.id)
        if left:
            side = etree.SubElement(section_element, "left")
            for lane in left:
                _lane(side, lane)
        center = etree.SubElement(etree.SubElement(section_element, "center"), "lane")
        _attrs(center, id=0, type="none", level="false")
        _road_mark(center, section.center_mark)
        if right:
            side = etree.SubElement(section_element, "right")
            for lane in right:
                _lane(side, lane)


def to_xodr(spec: MapSpec) -> bytes:
    """The OpenDRIVE 1.6 document of ``spec`` (UTF-8, two-space indentation)."""
    from lxml import etree

    root = etree.Element("OpenDRIVE")
    header = etree.SubElement(root, "header")
    _attrs(header, revMajor=1, revMinor=6, name=spec.name, version="1.0", date=DATE, vendor=spec.vendor)
    if spec.geo_reference:
        etree.SubElement(header, "geoReference").text = etree.CDATA(spec.geo_reference)
    for road in spec.roads:
        _road(root, road)
    for junction in spec.junctions:
        element = etree.SubElement(root, "junction")
        _attrs(element, id=junction.id, name=junction.name)
        for connection in junction.connections:
            connection_element = etree.SubElement(element, "connection")
            _attrs(
                connection_element, id=connection.id, incomingRoad=connection.incoming_road,
                connectingRoad=connection.connecting_road, contactPoint=connection.contact_point,
            )
            for link in connection.lane_links:
                _attrs(etree.SubElement(connection_element, "laneLink"), **{"from": link.from_lane, "to": link.to_lane})
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def generate() -> dict[str, bytes]:
    """File name → document for every bundled map."""
    return {f"{name}.xodr": to_xodr(build()) for name, build in BUILDERS.items()}


def _write_atomically(path: Path, data: bytes) -> None:
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp_name, 0o644)
        os.replace(tmp_name, path)
    except BaseException:
        os.unlink(tmp_name)
        raise


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry point; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT_DIR, help="output directory (default: maps/)")
    parser.add_argument("--check", action="store_true", help="exit 1 when files in --out differ from the generated ones")
    args = parser.parse_args(argv)
    documents = generate()
    out: Path = args.out
    if args.check:
        stale = [name for name, data in documents.items() if not _same_bytes(out / name, data)]
        if stale:
            print(f"make_maps: out of date in {out}: {', '.join(stale)}", file=sys.stderr)
            return 1
        return 0
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, data in documents.items():
            _write_atomically(out / name, data)
    except OSError as error:
        print(f"make_maps: cannot write maps to {out}: {error.strerror or error}", file=sys.stderr)
        return 1
    return 0


def _same_bytes(path: Path, data: bytes) -> bool:
    try:
        return path.read_bytes() == data
    except OSError:
        return False


if __name__ == "__main__":
    sys.exit(main())
