"""Small adversarial OpenDRIVE maps for the map engine, the converter and ``cold-maps check``.

Each builder returns the XML text of one map; ``write_maps(folder)`` writes them all.
The maps exercise what the CARLA towns lack: paramPoly3 in both pRanges with non-uniform
parameter speed, cubic lane widths, a lane closing to zero width, spiral chains with
curvature sign changes, poly3, a left-hand-traffic four-way junction, large false
easting/northing (tmerc and UTM geoReferences), ``<border>`` records, laneOffset and
singleSide sections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

Cubic = tuple[float, float, float, float, float]
"""(sOffset or s, a, b, c, d) of a cubic record."""

LANE_WIDTH_M: Final[float] = 3.5
TMERC: Final[str] = (
    "+proj=tmerc +lat_0=0 +lon_0=9 +k=0.9996 +x_0=500000 +y_0=-5000000 +ellps=WGS84 +units=m +no_defs"
)
UTM: Final[str] = "+proj=utm +zone=32 +ellps=WGS84 +datum=WGS84 +units=m +no_defs"
UTM_SOUTH: Final[str] = "+proj=utm +zone=33 +south +ellps=WGS84 +datum=WGS84 +units=m +no_defs"


@dataclass(frozen=True)
class LaneSpec:
    """One lane: id, type, width or border records (sOffset relative to the section), links,
    OpenDRIVE 1.7 ``direction`` ("" omits it)."""

    id: int
    widths: tuple[Cubic, ...] = ((0.0, LANE_WIDTH_M, 0.0, 0.0, 0.0),)
    borders: tuple[Cubic, ...] = ()
    type: str = "driving"
    predecessor: int | None = None
    successor: int | None = None
    direction: str = ""

    def xml(self) -> str:
        link = ""
        if self.predecessor is not None:
            link += f'<predecessor id="{self.predecessor}"/>'
        if self.successor is not None:
            link += f'<successor id="{self.successor}"/>'
        records = "".join(
            f'<{tag} sOffset="{r[0]!r}" a="{r[1]!r}" b="{r[2]!r}" c="{r[3]!r}" d="{r[4]!r}"/>'
            for tag, rows in (("width", self.widths if not self.borders else ()), ("border", self.borders))
            for r in rows
        )
        direction = f' direction="{self.direction}"' if self.direction else ""
        return (f'<lane id="{self.id}" type="{self.type}"{direction} level="false"><link>{link}</link>'
                f"{records}</lane>")


@dataclass(frozen=True)
class SectionSpec:
    """One lane section starting at ``s`` (m)."""

    s: float
    lanes: tuple[LaneSpec, ...]
    single_side: bool = False

    def xml(self) -> str:
        left = sorted((lane for lane in self.lanes if lane.id > 0), key=lambda lane: lane.id)
        right = sorted((lane for lane in self.lanes if lane.id < 0), key=lambda lane: -lane.id)
        sides = ""
        if left:
            sides += "<left>" + "".join(lane.xml() for lane in left) + "</left>"
        sides += '<center><lane id="0" type="none" level="false"/></center>'
        if right:
            sides += "<right>" + "".join(lane.xml() for lane in right) + "</right>"
        single = ' singleSide="true"' if self.single_side else ""
        return f'<laneSection s="{self.s!r}"{single}>{sides}</laneSection>'


@dataclass(frozen=True)
class RoadSpec:
    """One road: geometry records as XML fragments (built by the helpers below)."""

    id: str
    geometries: tuple[str, ...]
    length: float
    sections: tuple[SectionSpec, ...]
    rule: str = "RHT"
    junction: str = "-1"
    predecessor: str = ""
    successor: str = ""
    lane_offsets: tuple[Cubic, ...] = field(default=())

    def xml(self) -> str:
        offsets = "".join(
            f'<laneOffset s="{r[0]!r}" a="{r[1]!r}" b="{r[2]!r}" c="{r[3]!r}" d="{r[4]!r}"/>'
            for r in self.lane_offsets
        )
        return (
            f'<road id="{self.id}" length="{self.length!r}" junction="{self.junction}" rule="{self.rule}">'
            f"<link>{self.predecessor}{self.successor}</link>"
            f'<type s="0" type="town"/><planView>{"".join(self.geometries)}</planView>'
            f"<lanes>{offsets}{''.join(section.xml() for section in self.sections)}</lanes></road>"
        )


def road_link(end: str, element_type: str, element_id: str, contact: str | None = None) -> str:
    """A ``<predecessor>``/``<successor>`` element."""
    point = f' contactPoint="{contact}"' if contact else ""
    return f'<{end} elementType="{element_type}" elementId="{element_id}"{point}/>'


def geometry(s: float, x: float, y: float, hdg: float, length: float, shape: str) -> str:
    """A ``<geometry>`` record around one shape element."""
    return f'<geometry s="{s!r}" x="{x!r}" y="{y!r}" hdg="{hdg!r}" length="{length!r}">{shape}</geometry>'


def document(roads: list[RoadSpec], *, geo_reference: str = "", junctions: str = "", name: str = "adv") -> str:
    """A whole OpenDRIVE 1.6 file."""
    geo = f"<geoReference><![CDATA[{geo_reference}]]></geoReference>" if geo_reference else ""
    body = "".join(road.xml() for road in roads)
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<OpenDRIVE>'
        f'<header revMajor="1" revMinor="6" name="{name}" vendor="cold-maps tests">{geo}</header>'
        f"{body}{junctions}</OpenDRIVE>\n"
    )


ZERO_WIDTH_SECTION_S: Final[float] = 85.0
"""s (m) of the paramPoly3 road's last section, where lane -2 has zero width throughout."""


def param_poly3_map() -> str:
    """paramPoly3 (normalized, then arcLength), both with non-uniform parameter speed;
    four sections with cubic widths; lane -2 closes to zero width in the third section
    and stays at zero width over the fourth.

    Each record's length is the curve's own arc length, so no tool needs to rescale.
    """
    u1, v1 = (0.0, 30.0, 25.0, -15.0), (0.0, 0.0, 12.0, -6.0)
    first = _arc_length(u1, v1, 1.0)
    normalized = _param_poly3(u1, v1, "normalized")
    # arcLength: p in [0, length] and |r'(p)| = 1 only on average; p_end chosen so that
    # the arc length over [0, p_end] is p_end (speed 1 - 0.3·cos(2πp/p_end)-like wiggle)
    p_end = 50.0
    u2, v2 = (0.0, 1.2, -0.012, 0.00016), (0.0, 0.0, -0.004, 0.00004)
    scale = p_end / _arc_length(u2, v2, p_end)
    u2, v2 = tuple(c * scale for c in u2), tuple(c * scale for c in v2)
    arc = _param_poly3(u2, v2, "arcLength")
    x1, y1, h1 = _param_poly3_end(u1, v1, 1.0)
    ex, ey = _rot(x1, y1, 0.3)
    close = 20.0
    w = 2.5
    left_a = (0.0, 3.0, 0.02, -0.001, 2e-5)
    right_a = ((0.0, 3.2, 0.0, 0.002, -4e-5), (20.0, _cubic_at((0.0, 3.2, 0.0, 0.002, -4e-5), 20.0), 0.01, 0.0, 0.0))
    right_b = (0.0, _cubic_at(right_a[1], 35.0), -0.02, 0.001, -1e-5)
    left_end, right_end = _cubic_at(left_a, 35.0), _cubic_at(right_b, 25.0)
    sections = (
        SectionSpec(0.0, (
            LaneSpec(1, widths=(left_a,), successor=1),
            LaneSpec(-1, widths=right_a, successor=-1),
            LaneSpec(-2, widths=((0.0, w, 0.0, 0.0, 0.0),), successor=-2),
        )),
        SectionSpec(35.0, (
            LaneSpec(1, widths=((0.0, left_end, 0.0, 0.0, 0.0),), predecessor=1, successor=1),
            LaneSpec(-1, widths=(right_b,), predecessor=-1, successor=-1),
            LaneSpec(-2, widths=((0.0, w, 0.0, 0.0, 0.0),), predecessor=-2, successor=-2),
        )),
        SectionSpec(60.0, (
            LaneSpec(1, widths=((0.0, left_end, 0.0, 0.0, 0.0),), predecessor=1, successor=1),
            LaneSpec(-1, widths=((0.0, right_end, 0.0, 0.0, 0.0),), predecessor=-1, successor=-1),
            # w → 0 over ``close`` m (cubic ease, zero slope at both ends), then 0 m
            LaneSpec(-2, widths=((0.0, w, 0.0, -3 * w / close**2, 2 * w / close**3), (close, 0.0, 0.0, 0.0, 0.0)),
                     predecessor=-2, successor=-2),
        )),
        # lane -2 stays at zero width over the whole last section
        SectionSpec(ZERO_WIDTH_SECTION_S, (
            LaneSpec(1, widths=((0.0, left_end, 0.0, 0.0, 0.0),), predecessor=1),
            LaneSpec(-1, widths=((0.0, right_end, 0.0, 0.0, 0.0),), predecessor=-1),
            LaneSpec(-2, widths=((0.0, 0.0, 0.0, 0.0, 0.0),), predecessor=-2),
        )),
    )  # fmt: skip
    road = RoadSpec(
        "1",
        (geometry(0.0, 100.0, -50.0, 0.3, first, normalized), geometry(first, 100.0 + ex, -50.0 + ey, 0.3 + h1, p_end, arc)),
        first + p_end,
        sections,
    )
    return document([road], name="paramPoly3")


def _param_poly3(u: tuple[float, ...], v: tuple[float, ...], p_range: str) -> str:
    names = [f'{axis}U="{c!r}"' for axis, c in zip("abcd", u)] + [f'{axis}V="{c!r}"' for axis, c in zip("abcd", v)]
    return f'<paramPoly3 {" ".join(names)} pRange="{p_range}"/>'


def _cubic_at(record: Cubic, ds: float) -> float:
    """Value of a cubic record ``ds`` m after the section start (record sOffset included)."""
    x = ds - record[0]
    return record[1] + record[2] * x + record[3] * x**2 + record[4] * x**3


def _rot(u: float, v: float, hdg: float) -> tuple[float, float]:
    return u * math.cos(hdg) - v * math.sin(hdg), u * math.sin(hdg) + v * math.cos(hdg)


def _param_poly3_end(u: tuple[float, ...], v: tuple[float, ...], p: float) -> tuple[float, float, float]:
    """Local (u, v, heading) at parameter p."""
    value = [sum(c * p**k for k, c in enumerate(poly)) for poly in (u, v)]
    slope = [sum(k * c * p ** (k - 1) for k, c in enumerate(poly) if k) for poly in (u, v)]
    return value[0], value[1], math.atan2(slope[1], slope[0])


def _arc_length(u: tuple[float, ...], v: tuple[float, ...], p_end: float, steps: int = 20000) -> float:
    """Arc length of a cubic curve over [0, p_end] (midpoint rule)."""
    total = 0.0
    h = p_end / steps
    for i in range(steps):
        p = (i + 0.5) * h
        du = sum(k * c * p ** (k - 1) for k, c in enumerate(u) if k)
        dv = sum(k * c * p ** (k - 1) for k, c in enumerate(v) if k)
        total += math.hypot(du, dv) * h
    return total


def spiral_map() -> str:
    """A spiral chain line → κ 0→+0.04 → +0.04→-0.03 → -0.03→0 → line, and a poly3 road after it."""
    records = [("line", 10.0, 0.0, 0.0), ("spiral", 25.0, 0.0, 0.04), ("spiral", 40.0, 0.04, -0.03),
               ("spiral", 20.0, -0.03, 0.0), ("line", 10.0, 0.0, 0.0)]  # fmt: skip
    geometries = []
    s, x, y, hdg = 0.0, -20.0, 10.0, 0.5
    for kind, length, k0, k1 in records:
        shape = "<line/>" if kind == "line" else f'<spiral curvStart="{k0!r}" curvEnd="{k1!r}"/>'
        geometries.append(geometry(s, x, y, hdg, length, shape))
        x, y, hdg = _spiral_end(x, y, hdg, length, k0, k1)
        s += length
    lanes = (
        LaneSpec(2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), successor=2),
        LaneSpec(1, widths=((0.0, 3.5, 0.01, 0.0, 0.0), (30.0, 3.8, 0.0, -0.0004, 4e-6)), successor=1),
        LaneSpec(-1, successor=-1),
        LaneSpec(-2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), successor=-2),
    )
    spiral_road = RoadSpec("10", tuple(geometries), s, (SectionSpec(0.0, lanes),),
                           successor=road_link("successor", "road", "11", "start"))  # fmt: skip
    ds = s - 30.0  # lane 1 continues with the width and slope it ends with
    end_width, end_slope = 3.8 - 0.0004 * ds**2 + 4e-6 * ds**3, -0.0008 * ds + 1.2e-5 * ds**2
    poly3 = '<poly3 a="0" b="0" c="0.004" d="-0.00006"/>'
    poly_length = _arc_length((0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 0.004, -0.00006), 40.0)
    poly_lanes = (
        LaneSpec(2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), predecessor=2),
        LaneSpec(1, widths=((0.0, end_width, end_slope, 0.0, 0.0),), predecessor=1),
        LaneSpec(-1, predecessor=-1),
        LaneSpec(-2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), predecessor=-2),
    )
    poly_road = RoadSpec("11", (geometry(0.0, x, y, hdg, poly_length, poly3),), poly_length,
                         (SectionSpec(0.0, poly_lanes),), predecessor=road_link("predecessor", "road", "10", "end"))  # fmt: skip
    return document([spiral_road, poly_road], name="spirals")


def odd_geometry_map() -> str:
    """Records real exporters write: spirals of constant curvature (an arc, a line), a
    0.1 mm line, and an arcLength paramPoly3 whose parameter speed is about 2 (its record
    length is half its arc length)."""
    records = [
        (10.0, '<spiral curvStart="0.02" curvEnd="0.02"/>'),
        (1e-4, "<line/>"),
        (10.0, '<spiral curvStart="0.0" curvEnd="0.0"/>'),
    ]
    geometries = []
    s, x, y, hdg = 0.0, 0.0, 0.0, 0.0
    for length, shape in records:
        geometries.append(geometry(s, x, y, hdg, length, shape))
        curvature = 0.02 if "0.02" in shape else 0.0
        x, y, hdg = _spiral_end(x, y, hdg, length, curvature, curvature)
        s += length
    u, v, p_end = (0.0, 2.0, 0.0, 0.0), (0.0, 0.0, 0.01, 0.0), 20.0
    geometries.append(geometry(s, x, y, hdg, p_end, _param_poly3(u, v, "arcLength")))
    lanes = (LaneSpec(1, widths=((0.0, 3.0, 0.01, 0.0, 0.0),)), LaneSpec(-1, widths=((0.0, 3.5, -0.01, 0.0, 0.0),)))
    return document([RoadSpec("9", tuple(geometries), s + p_end, (SectionSpec(0.0, lanes),))], name="odd geometry")


def _spiral_end(x: float, y: float, hdg: float, length: float, k0: float, k1: float) -> tuple[float, float, float]:
    """End pose of a clothoid by the midpoint rule on its heading (fine enough: 1e-9 m)."""
    steps = 20000
    h = length / steps
    rate = (k1 - k0) / length
    for i in range(steps):
        s = (i + 0.5) * h
        theta = hdg + k0 * s + 0.5 * rate * s * s
        x += math.cos(theta) * h
        y += math.sin(theta) * h
    return x, y, hdg + k0 * length + 0.5 * rate * length * length


ARM_LENGTH_M: Final[float] = 50.0
JUNCTION_HALF_M: Final[float] = 10.0


ARM_SPLIT_M: Final[float] = 20.0
"""s (m) where each junction arm's second lane section starts."""


def lht_junction_map(prefix: str = "") -> str:
    """A left-hand-traffic four-way junction. Four arms leave the junction along +s (lane 1
    drives outwards, lane -1 towards the junction), each in two lane sections. Every arm
    has connecting roads turning left (short arc, reference radius 10 m) and right (long
    arc), drawn from the incoming arm with lane 1 (along +s, contactPoint start), and
    going straight, drawn backwards from the target arm with lane -1 (against +s,
    contactPoint end). Road and junction ids start with ``prefix``
    (non-integer ids when it is not empty)."""
    arms = []
    for k in range(4):
        theta = k * math.pi / 2
        x, y = JUNCTION_HALF_M * math.cos(theta), JUNCTION_HALF_M * math.sin(theta)
        sections = (
            SectionSpec(0.0, (LaneSpec(1, successor=1), LaneSpec(-1, successor=-1))),
            SectionSpec(ARM_SPLIT_M, (LaneSpec(1, predecessor=1), LaneSpec(-1, predecessor=-1))),
        )
        arms.append(RoadSpec(f"{prefix}{k + 1}", (geometry(0.0, x, y, theta, ARM_LENGTH_M, "<line/>"),), ARM_LENGTH_M,
                             sections, rule="LHT", predecessor=road_link("predecessor", "junction", f"{prefix}100")))  # fmt: skip
    connecting = []
    connections = []
    for k in range(4):
        theta = k * math.pi / 2
        start = (JUNCTION_HALF_M * math.cos(theta), JUNCTION_HALF_M * math.sin(theta))
        for turn, (target, curvature) in enumerate((((k + 1) % 4, -1 / JUNCTION_HALF_M), ((k + 3) % 4, 1 / JUNCTION_HALF_M))):
            road_id = f"{prefix}2{k}{turn}"
            connecting.append(RoadSpec(
                road_id, (geometry(0.0, start[0], start[1], theta + math.pi, math.pi / 2 * JUNCTION_HALF_M,
                                   f'<arc curvature="{curvature!r}"/>'),), math.pi / 2 * JUNCTION_HALF_M,
                (SectionSpec(0.0, (LaneSpec(1, predecessor=-1, successor=1),)),), rule="LHT", junction=f"{prefix}100",
                predecessor=road_link("predecessor", "road", f"{prefix}{k + 1}", "start"),
                successor=road_link("successor", "road", f"{prefix}{target + 1}", "start"),
            ))  # fmt: skip
            connections.append((k, road_id, "start", 1))
        target = (k + 2) % 4
        road_id = f"{prefix}2{k}2"
        end = (-start[0], -start[1])
        connecting.append(RoadSpec(
            road_id, (geometry(0.0, end[0], end[1], theta, 2 * JUNCTION_HALF_M, "<line/>"),), 2 * JUNCTION_HALF_M,
            (SectionSpec(0.0, (LaneSpec(-1, predecessor=1, successor=-1),)),), rule="LHT", junction=f"{prefix}100",
            predecessor=road_link("predecessor", "road", f"{prefix}{target + 1}", "start"),
            successor=road_link("successor", "road", f"{prefix}{k + 1}", "start"),
        ))  # fmt: skip
        connections.append((k, road_id, "end", -1))
    junction = "".join(
        f'<connection id="{i}" incomingRoad="{prefix}{k + 1}" connectingRoad="{road_id}" contactPoint="{contact}">'
        f'<laneLink from="-1" to="{lane}"/></connection>'
        for i, (k, road_id, contact, lane) in enumerate(connections)
    )
    return document(arms + connecting, junctions=f'<junction id="{prefix}100" name="lht">{junction}</junction>', name="lht-junction")


def georeferenced_map(proj: str, x0: float, y0: float) -> str:
    """Two linked roads (line, arc, spiral) far from the origin (x0, y0 in m), with ``proj``."""
    g1 = (geometry(0.0, x0, y0, 1.1, 30.0, "<line/>"),
          geometry(30.0, *_arc_end(x0, y0, 1.1, 30.0, 0.0), 40.0, '<arc curvature="0.02"/>'))  # fmt: skip
    x1, y1, h1 = _arc_end(*_arc_end(x0, y0, 1.1, 30.0, 0.0), 40.0, 0.02)
    lanes = (LaneSpec(1, successor=1), LaneSpec(-1, successor=-1), LaneSpec(-2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), successor=-2))
    first = RoadSpec("1", g1, 70.0, (SectionSpec(0.0, lanes),), successor=road_link("successor", "road", "2", "start"))
    lanes2 = (LaneSpec(1, predecessor=1), LaneSpec(-1, predecessor=-1), LaneSpec(-2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), predecessor=-2))
    second = RoadSpec("2", (geometry(0.0, x1, y1, h1, 30.0, '<spiral curvStart="0.02" curvEnd="-0.01"/>'),), 30.0,
                      (SectionSpec(0.0, lanes2),), predecessor=road_link("predecessor", "road", "1", "end"))  # fmt: skip
    return document([first, second], geo_reference=proj, name="georeferenced")


def _arc_end(x: float, y: float, hdg: float, length: float, k: float) -> tuple[float, float, float]:
    if k == 0.0:
        return x + length * math.cos(hdg), y + length * math.sin(hdg), hdg
    end = hdg + k * length
    return x + (math.sin(end) - math.sin(hdg)) / k, y - (math.cos(end) - math.cos(hdg)) / k, end


def border_map() -> str:
    """A road whose lanes are given by ``<border>`` records (cubic, measured from lane 0)."""
    lanes = (
        LaneSpec(1, borders=((0.0, 3.5, 0.01, 0.0, 0.0), (40.0, 3.9, 0.0, -0.0005, 0.0))),
        LaneSpec(-1, borders=((0.0, -3.5, 0.0, -0.001, 1e-5),)),
        LaneSpec(-2, borders=((0.0, -6.5, -0.02, 0.0, 0.0),)),
    )
    road = RoadSpec("7", (geometry(0.0, 0.0, 0.0, 0.2, 80.0, '<arc curvature="0.005"/>'),), 80.0, (SectionSpec(0.0, lanes),))
    return document([road], name="borders")


def lane_offset_map() -> str:
    """laneOffset (two continuous cubics, 0 → 0.8 m → 0.8 - 0.0002·ds²) and a singleSide section with right lanes only."""
    both = (LaneSpec(1), LaneSpec(-1, successor=-1), LaneSpec(-2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), successor=-2))
    right_only = (LaneSpec(-1, predecessor=-1), LaneSpec(-2, widths=((0.0, 3.0, 0.0, 0.0, 0.0),), predecessor=-2))
    road = RoadSpec(
        "5",
        (geometry(0.0, 0.0, 0.0, -0.4, 40.0, "<line/>"), geometry(40.0, 40 * math.cos(-0.4), 40 * math.sin(-0.4), -0.4, 50.0, '<arc curvature="-0.01"/>')),
        90.0,
        (SectionSpec(0.0, both), SectionSpec(45.0, right_only, single_side=True)),
        lane_offsets=((0.0, 0.0, 0.0, 0.0015, -2.5e-5), (40.0, 0.8, 0.0, -0.0002, 0.0)),
    )  # fmt: skip
    return document([road], name="laneOffset")


MAPS: Final[dict[str, object]] = {
    "param_poly3": param_poly3_map,
    "spirals": spiral_map,
    "odd_geometry": odd_geometry_map,
    "lht_junction": lht_junction_map,
    "named_ids": lambda: lht_junction_map("arm-"),
    "tmerc": lambda: georeferenced_map(TMERC, 512345.678, 412345.6),
    "utm": lambda: georeferenced_map(UTM, 691234.5, 5334567.8),
    "utm_south": lambda: georeferenced_map(UTM_SOUTH, 851234.5, 9912345.6),
    "no_geo": lambda: georeferenced_map("", 0.0, 0.0),
    "borders": border_map,
    "lane_offset": lane_offset_map,
}
"""Map name → builder of its XML text."""


def write_maps(folder: Path) -> dict[str, Path]:
    """Write every map of ``MAPS`` as ``<name>.xodr`` into ``folder``; name → path."""
    paths = {}
    for name, build in MAPS.items():
        path = folder / f"{name}.xodr"
        path.write_text(build())  # type: ignore[operator]
        paths[name] = path
    return paths
