"""Immutable model of an OpenDRIVE map (ASAM OpenDRIVE 1.4-1.8).

Every length is in metres, every angle in radians, every position in the OpenDRIVE
inertial frame (x east, y north, heading counter-clockwise from x) unless a field says
otherwise. Road coordinates are (s, t): s along the reference line from the road start,
t to the left of it.

The model is pure data: geometry is evaluated by the modules in
``cold_maps.opendrive.geometry``, ``reference_line`` and ``lanes``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, Literal, Mapping

GeometryKind = Literal["line", "arc", "spiral", "poly3", "paramPoly3"]
ContactPoint = Literal["start", "end"]
TrafficRule = Literal["RHT", "LHT"]


@dataclass(frozen=True, slots=True)
class CubicPoly:
    """One record of a piecewise cubic profile: f(s) = a + b·ds + c·ds² + d·ds³.

    Fields:
        s0: start of the record (m). Absolute road s for elevation and laneOffset; the
            ``sOffset`` relative to the lane-section start for lane width and border.
        a, b, c, d: coefficients (unit of f, per m, per m², per m³).
    """

    s0: float
    a: float
    b: float
    c: float
    d: float


@dataclass(frozen=True, slots=True)
class GeoReference:
    """Map projection of the inertial frame.

    Fields:
        proj: the PROJ string from ``<geoReference>`` (stripped), or "" when absent.
        offset_x, offset_y, offset_z: ``<offset>`` translation (m), 0 when absent.
        offset_hdg: ``<offset>`` rotation (rad), 0 when absent.
    """

    proj: str = ""
    offset_x: float = 0.0
    offset_y: float = 0.0
    offset_z: float = 0.0
    offset_hdg: float = 0.0


@dataclass(frozen=True, slots=True)
class Header:
    """The ``<header>`` element.

    Fields:
        rev_major, rev_minor: OpenDRIVE revision (e.g. 1, 4).
        name: map name ("" when absent).
        vendor: writing tool ("" when absent).
        north, south, east, west: bounding box (m) as written, NaN when absent.
        geo_reference: projection and offset.
    """

    rev_major: int
    rev_minor: int
    name: str = ""
    vendor: str = ""
    north: float = float("nan")
    south: float = float("nan")
    east: float = float("nan")
    west: float = float("nan")
    geo_reference: GeoReference = field(default_factory=GeoReference)


@dataclass(frozen=True, slots=True)
class Geometry:
    """One ``<planView><geometry>`` record.

    Fields:
        kind: "line", "arc", "spiral", "poly3" or "paramPoly3".
        s: start of the record along the reference line (m).
        x, y: start position in the inertial frame (m).
        hdg: start heading (rad, counter-clockwise from x).
        length: length along the reference line (m, > 0).
        curvature: arc curvature (1/m, positive = left turn); 0 otherwise.
        curv_start, curv_end: spiral curvature at start and end (1/m); 0 otherwise.
        a, b, c, d: poly3 coefficients of v(u) in the local (u, v) frame; 0 otherwise.
        au, bu, cu, du, av, bv, cv, dv: paramPoly3 coefficients of u(p), v(p); 0 otherwise.
        p_range: paramPoly3 "arcLength" (p in [0, length]) or "normalized" (p in [0, 1]).
    """

    kind: GeometryKind
    s: float
    x: float
    y: float
    hdg: float
    length: float
    curvature: float = 0.0
    curv_start: float = 0.0
    curv_end: float = 0.0
    a: float = 0.0
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0
    au: float = 0.0
    bu: float = 0.0
    cu: float = 0.0
    du: float = 0.0
    av: float = 0.0
    bv: float = 0.0
    cv: float = 0.0
    dv: float = 0.0
    p_range: Literal["arcLength", "normalized"] = "normalized"


ROAD_MARK_TYPES: Final[tuple[str, ...]] = (
    "none", "solid", "broken", "solid solid", "solid broken", "broken solid", "broken broken", "botts dots",
    "grass", "curb", "custom", "edge")
"""``<roadMark type>`` values (ASAM OpenDRIVE 1.8 e_roadMarkType)."""


@dataclass(frozen=True, slots=True)
class RoadMarkLine:
    """One ``<line>`` of a ``<roadMark><type>``: a repeated dash of a complex mark.

    Fields:
        length: length of one painted dash (m; the whole stretch when ``space`` is 0).
        space: gap between dashes (m).
        t_offset: lateral offset of the line from the border it marks (m, +t left).
        s_offset: start of the first dash from the mark's start (m).
        rule: "caution", "no passing", "none", or "" when absent.
        width: line width (m), None when absent.
        color: line colour, "" when absent (the mark's colour applies).
    """

    length: float
    space: float
    t_offset: float
    s_offset: float
    rule: str = ""
    width: float | None = None
    color: str = ""


@dataclass(frozen=True, slots=True)
class RoadMark:
    """One ``<roadMark>`` of a lane: the marking of the lane's OUTER border (for the centre
    lane, of the centre line) from ``s_offset`` to the next record's ``s_offset`` or the
    end of the lane section.

    Fields:
        s_offset: start relative to the lane-section start (m).
        type: one of ``ROAD_MARK_TYPES`` ("none": no marking).
        weight: "standard" or "bold" ("standard" when absent).
        color: "standard", "white", "yellow", ... ("standard" when absent).
        width: paint width (m), None when absent.
        lane_change: "increase", "decrease", "both" or "none" (crossing allowed towards
            higher / lower lane ids, both or neither); "both" when absent, as the spec says.
        material: surface material ("" when absent).
        height: height above the road (m), 0 when absent (a curb's height).
        type_name: the ``name`` of a ``<type>`` child ("" when none).
        lines: the ``<line>`` records of the ``<type>`` child (empty for plain marks).
    """

    s_offset: float
    type: str
    weight: str = "standard"
    color: str = "standard"
    width: float | None = None
    lane_change: str = "both"
    material: str = ""
    height: float = 0.0
    type_name: str = ""
    lines: tuple[RoadMarkLine, ...] = ()


VEHICLE_LANE_TYPES: Final[tuple[str, ...]] = (
    "driving", "entry", "exit", "onRamp", "offRamp", "connectingRamp", "slipLane")
"""OpenDRIVE lane types that motor vehicles drive along one way (ASAM OpenDRIVE 1.6
§9.5.3: "driving", the lanes into and out of a motorway and the ramps; 1.8's slip lane;
OSI classifies them as driving lanes): the lanes of the lane graph, the sensor, the
export and the ground-truth check by default."""


@dataclass(frozen=True, slots=True)
class Lane:
    """One ``<lane>`` of a lane section.

    Fields:
        id: lane id: > 0 left of the reference line, < 0 right, 0 the centre lane.
        type: OpenDRIVE lane type ("driving", "sidewalk", ...).
        level: the ``level`` attribute (keep on level, no superelevation).
        widths: ``<width>`` records, s0 relative to the section start; the lane's outer
            border is its inner border + width (outwards from the reference line).
        borders: ``<border>`` records, s0 relative to the section start: the outer
            border's t offset from the reference line (after laneOffset), used only when
            ``widths`` is empty (the spec forbids mixing them in one lane).
        predecessors, successors: ids of linked lanes in the previous / next section,
            or, at the road ends, in the linked road (empty when unlinked).
        direction: OpenDRIVE 1.7+ ``direction`` attribute ("standard", "reversed",
            "both") or "" when absent (standard); see ``Road.drives_along_s``.
        road_marks: ``<roadMark>`` records of the lane's outer border (the centre line for
            lane 0), ordered by ``s_offset``; empty when the file gives none.
    """

    id: int
    type: str
    level: bool = False
    widths: tuple[CubicPoly, ...] = ()
    borders: tuple[CubicPoly, ...] = ()
    predecessors: tuple[int, ...] = ()
    successors: tuple[int, ...] = ()
    direction: str = ""
    road_marks: tuple[RoadMark, ...] = ()


@dataclass(frozen=True, slots=True)
class LaneSection:
    """One ``<laneSection>``.

    Fields:
        s: start along the road (m).
        s_end: end along the road (m): next section's start or the road length.
        single_side: True when the ``singleSide`` attribute is "true".
        left: left lanes ordered from the reference line outwards (ids 1, 2, ...).
        center: the centre lane (id 0).
        right: right lanes ordered from the reference line outwards (ids -1, -2, ...).
    """

    s: float
    s_end: float
    single_side: bool
    left: tuple[Lane, ...]
    center: Lane
    right: tuple[Lane, ...]

    def lane(self, lane_id: int) -> Lane:
        """The lane with this id (KeyError when the section has none)."""
        if lane_id == 0:
            return self.center
        side = self.left if lane_id > 0 else self.right
        index = abs(lane_id) - 1
        if index < len(side) and side[index].id == lane_id:
            return side[index]
        raise KeyError(f"lane {lane_id} not in section at s={self.s}")

    @property
    def lanes(self) -> tuple[Lane, ...]:
        """All non-centre lanes, left then right."""
        return self.left + self.right


@dataclass(frozen=True, slots=True)
class RoadLink:
    """A road's ``<predecessor>`` or ``<successor>``.

    Fields:
        element_type: "road" or "junction".
        element_id: id of the linked road or junction.
        contact_point: "start" or "end" of the linked road; None for junctions.
    """

    element_type: Literal["road", "junction"]
    element_id: str
    contact_point: ContactPoint | None = None


@dataclass(frozen=True, slots=True)
class Road:
    """One ``<road>``.

    Fields:
        id: road id (string, as in the file).
        name: road name ("" when absent).
        length: reference-line length (m).
        junction: id of the junction this road belongs to, "-1" when none.
        rule: traffic rule, "RHT" (default) or "LHT". In RHT the right lanes (id < 0)
            drive along +s; in LHT the left lanes (id > 0) do.
        predecessor, successor: road links, None when absent.
        plan_view: reference-line geometry records ordered by s.
        elevation: elevationProfile records (z in m), s0 absolute.
        lane_offsets: laneOffset records (t shift of lane 0 in m), s0 absolute.
        lane_sections: ordered by s; each knows its end.
        line: source line of the ``<road>`` element (for error messages; 0 when unknown or
            past ``errors.LXML_LINE_CAP``, where lxml cannot tell it).
        superelevation: ``<lateralProfile><superelevation>`` records (roll angle of the
            cross section in rad, positive = the left side (+t) higher), s0 absolute.
    """

    id: str
    name: str
    length: float
    junction: str
    rule: TrafficRule
    predecessor: RoadLink | None
    successor: RoadLink | None
    plan_view: tuple[Geometry, ...]
    elevation: tuple[CubicPoly, ...]
    lane_offsets: tuple[CubicPoly, ...]
    lane_sections: tuple[LaneSection, ...]
    line: int = 0
    superelevation: tuple[CubicPoly, ...] = ()

    def drives_along_s(self, lane_id: int, section: int | None = None) -> bool:
        """True when traffic in this lane moves towards increasing s.

        With ``section`` (index into ``lane_sections``) the lane's OpenDRIVE 1.7+
        ``direction`` applies: "reversed" drives against its side's rule; "both" (either
        way) is read as the side's direction, the one the lane graph follows.
        """
        along = (lane_id < 0) == (self.rule == "RHT")
        if section is not None and lane_id != 0:
            return along != (self.lane_sections[section].lane(lane_id).direction == "reversed")
        return along


@dataclass(frozen=True, slots=True)
class LaneLink:
    """A junction connection's ``<laneLink>``: lane ``from_lane`` of the incoming road
    continues into lane ``to_lane`` of the connecting road."""

    from_lane: int
    to_lane: int


@dataclass(frozen=True, slots=True)
class Connection:
    """A junction ``<connection>``.

    Fields:
        id: connection id.
        incoming_road: id of the road entering the junction.
        connecting_road: id of the road inside the junction.
        contact_point: "start" or "end" of the connecting road where it touches the
            incoming road.
        lane_links: lane pairs (incoming lane, connecting-road lane).
    """

    id: str
    incoming_road: str
    connecting_road: str
    contact_point: ContactPoint
    lane_links: tuple[LaneLink, ...]


@dataclass(frozen=True, slots=True)
class Junction:
    """A ``<junction>``.

    Fields:
        id: junction id.
        name: junction name ("" when absent).
        connections: its connections in file order.
        type: "default", or (OpenDRIVE 1.7+) "direct", "virtual" or "crossing". In a
            direct junction a connection's ``connecting_road`` is the ``linkedRoad``,
            a road outside the junction.
    """

    id: str
    name: str
    connections: tuple[Connection, ...]
    type: str = "default"


@dataclass(frozen=True, slots=True)
class OpenDriveMap:
    """A whole OpenDRIVE file.

    Fields:
        path: the file read ("" for in-memory input).
        header: the header.
        roads: road id → road, in file order.
        junctions: junction id → junction, in file order.
    """

    path: str
    header: Header
    roads: Mapping[str, Road]
    junctions: Mapping[str, Junction]
