"""OpenDRIVE 1.4-1.8 reader: hardened XML in, immutable ``OpenDriveMap`` out.

The tree is walked once, child by child; elements the model does not need (objects,
signals, userData, lateral shape, surface, railroad, controllers, a road mark's
``<explicit>`` and ``<sway>``, ...) are skipped. Invalid input raises ``OpenDriveError`` naming the file, the element and
its source line.

Errors: malformed XML, entity declarations, wrong root, no header or roads, revMajor
other than 1, missing or non-numeric (NaN, inf) required attributes, unknown
enumeration values (contactPoint, elementType, rule, pRange, direction, junction type),
negative geometry or road length, a ``<geometry>`` without exactly one known
kind, a road without geometry or lane section or with two ``<planView>``/``<lanes>``/
``<link>``/``<elevationProfile>`` or two predecessors/successors, lane ids that are not
consecutive from the reference line, a centre that is not exactly lane 0, a lane
section starting before 0 or after the road end, duplicate road or junction ids, road
links, road ``junction`` attributes and junction connections to ids that do not exist
when ``strict`` (else dropped with one warning per map, as libOpenDRIVE reads them; a
road's ``junction`` attribute is kept). Tolerated: a geometry ``s`` that differs from
the running sum of lengths, a road length that differs from the sum of its geometry
lengths, records and sections out of order
(sorted by s, stably), zero-length geometry records (dropped: they cover no s),
zero-length lane sections, ``contactPoint`` on a link to a
junction (dropped: the model has none for junctions), a missing road ``junction``
attribute ("-1"), ``<border>`` next to ``<width>`` records (widths win, see ``Lane``),
a plain ``<!DOCTYPE OpenDRIVE>``, a default XML namespace, any revMinor. Repaired with a
warning (refused when ``strict``): a road link or junction connection whose
``contactPoint`` names the far end of a road whose other end touches (``links``).
Numbers follow the XML Schema lexical form of a double or an integer (Python's digit
underscores and non-ASCII digits are refused; "INF" and "NaN" are refused as not finite).

Lenient by default, like mainstream readers (libOpenDRIVE): a polynomial coefficient,
curvature or record start that a record omits (RoadRunner writes ``<spiral curvEnd=".."/>``,
``<paramPoly3/>``, ``<elevation/>``, ``<superelevation/>``) is 0, the value an empty
record stands for (and ``pRange`` defaults to "normalized" as in the schema); one warning
per element kind and road names the attributes taken as 0. ``strict=True`` refuses them
("missing required attribute"). So is a centre lane without a ``type`` (taken as "none",
one warning per map), and a ``<roadMark>`` without a ``type`` or with one the schema does
not know (taken as "none" when absent, "custom" when unknown; one warning per map). A
road's last ``<paramPoly3>`` records that draw a single point (RoadRunner's empty
``<paramPoly3/>``) are read as absent, the road and its lanes ending where they start (one
warning per map; refused when strict, and anywhere but at the road's end).
"""

from __future__ import annotations

import logging
import math
import os
from contextlib import closing
from dataclasses import replace
from typing import Final, Iterable, Iterator, NamedTuple

from lxml import etree

from cold_maps.opendrive.errors import OpenDriveError, source_line
from cold_maps.opendrive.geometry.param_poly3 import is_single_point
from cold_maps.opendrive.lanes import wrong_side_lanes
from cold_maps.opendrive.links import repair_contact_points
from cold_maps.opendrive.model import (
    Connection,
    CubicPoly,
    GeoReference,
    Geometry,
    Header,
    Junction,
    Lane,
    LaneLink,
    LaneSection,
    OpenDriveMap,
    Road,
    RoadLink,
    RoadMark,
    RoadMarkLine,
    ROAD_MARK_TYPES,
)
from cold_maps.opendrive.validation import validate_road
from cold_maps.opendrive.xml_safety import iter_xml

MAX_FILE_BYTES: Final[int] = 256 * 1024 * 1024
"""Default input size limit (bytes) of ``load_opendrive``."""

SECTION_START_TOLERANCE_M: Final[float] = 1e-3
"""A lane section may start this far (m) past the road length (rounding in real maps)
before it is an error; such a section starts at the road length, with zero length."""

_GEOMETRY_KINDS: Final[frozenset[str]] = frozenset({"line", "arc", "spiral", "poly3", "paramPoly3"})
_CONTACT_POINTS: Final[tuple[str, ...]] = ("start", "end")
_RULES: Final[tuple[str, ...]] = ("RHT", "LHT")
_P_RANGES: Final[tuple[str, ...]] = ("arcLength", "normalized")
_JUNCTION_TYPES: Final[tuple[str, ...]] = ("default", "direct", "virtual", "crossing")
_LANE_DIRECTIONS: Final[tuple[str, ...]] = ("standard", "reversed", "both")
_LANE_CHANGES: Final[tuple[str, ...]] = ("increase", "decrease", "both", "none")
CENTRE_LANE_TYPE: Final[str] = "none"
"""Type of a centre lane (id 0, no width, its type means nothing) that has none: ASAM's
own Ex_Entry_Exit.xodr omits it on every road."""
_ONCE_PER_ROAD: Final[frozenset[str]] = frozenset(
    {"link", "planView", "elevationProfile", "lateralProfile", "lanes"}
)
_BOOLEANS: Final[dict[str, bool]] = {"true": True, "1": True, "false": False, "0": False}
_LOG: Final[logging.Logger] = logging.getLogger(__name__)


def load_opendrive(
    path: str | os.PathLike[str], *, max_bytes: int = MAX_FILE_BYTES, strict: bool = False
) -> OpenDriveMap:
    """Read and parse the OpenDRIVE file at ``path`` (``strict``: see ``parse_opendrive``).

    Files larger than ``max_bytes`` are rejected before they are read (size from
    ``os.stat``, and the read itself stops at ``max_bytes + 1``; it reserves the file's
    size, not ``max_bytes``, so a small map reads under a tight ``ulimit -v``). Unreadable
    files and invalid content raise ``OpenDriveError``; ``strict``: see ``parse_opendrive``.
    """
    name = os.fspath(path)
    try:
        size = os.stat(name).st_size
        if size > max_bytes:
            raise OpenDriveError(f"file is {size} bytes, more than the limit of {max_bytes} bytes", path=name)
        with open(name, "rb") as stream:
            data = stream.read(size + 1)  # not max_bytes + 1: read(n) reserves n bytes of address space
            if len(data) > size:  # grown since, or no size (a pipe)
                data += stream.read(max_bytes + 1 - len(data))
    except OSError as exc:
        raise OpenDriveError(f"cannot read file: {exc.strerror or exc}", path=name) from None
    if len(data) > max_bytes:
        raise OpenDriveError(f"file is more than the limit of {max_bytes} bytes", path=name)
    return parse_opendrive(data, path=name, strict=strict)


def parse_opendrive(data: bytes, *, path: str = "", strict: bool = False) -> OpenDriveMap:
    """Parse OpenDRIVE XML ``data``; ``path`` only names the source in errors and the map.

    ``strict``: refuse records that omit a coefficient, curvature or start (else they
    are 0 with a warning, see the module docstring), and road links and junction
    connections whose ``contactPoint`` contradicts the geometry (else repaired with a
    warning each, ``links.repair_contact_points``), and links to roads or junctions not in
    the file (else dropped with one warning).
    """
    with closing(iter_xml(data, ("header", "road", "junction"), path=path)) as elements:
        odr_map = _Reader(path, strict).read_map(elements)
    return repair_contact_points(odr_map, strict=strict)


def _strip_namespaces(root: etree._Element) -> None:
    """Replace namespaced tags by their local names (rare: OpenDRIVE has no namespace)."""
    for element in root.iter():
        tag = element.tag
        if isinstance(tag, str) and tag.startswith("{"):
            element.tag = tag.split("}", 1)[1]


class _Reader:
    """Converts the element tree of one file into the model; knows the file name."""

    def __init__(self, path: str, strict: bool = False) -> None:
        self.path = path
        self.strict = strict
        self.road_id = ""
        self.defaulted: dict[tuple[str, str], set[str]] = {}
        self.untyped_centres: dict[str, None] = {}
        """Roads (in file order) with a centre lane that has no type."""
        self.odd_marks: dict[str, str] = {}
        """Roads (in file order) with a ``<roadMark>`` type read leniently → the first such type."""
        self.single_points: dict[str, tuple[float, int]] = {}
        """Roads (in file order) cut before their last records that draw a single point →
        (s where the road now ends in m, how many records)."""
        self.no_contact: list[_Link] = []
        """Road links without ``contactPoint`` (refused unless the road they name is missing)."""

    # -- attribute access -------------------------------------------------------------

    def error(self, reason: str, element: etree._Element) -> OpenDriveError:
        tag = element.tag if isinstance(element.tag, str) else ""
        return self.error_at(reason, tag, source_line(element))

    def error_at(self, reason: str, tag: str, line: int | None) -> OpenDriveError:
        """The error for element ``tag`` at ``line``; names the road when the line is unknown."""
        if line is None and self.road_id and f"road {self.road_id!r}" not in reason:
            reason += f" (in road {self.road_id!r})"
        return OpenDriveError(reason, path=self.path, element=tag, line=line)

    def required(self, element: etree._Element, name: str) -> str:
        value = element.get(name)
        if value is None:
            raise self.error(f"missing required attribute '{name}'", element)
        return value

    def number(self, element: etree._Element, name: str, default: float | None = None) -> float:
        """A finite float attribute; ``default`` when absent (required when None)."""
        text = element.get(name)
        if text is None:
            if default is None:
                raise self.error(f"missing required attribute '{name}'", element)
            return default
        self.lexical_form(element, name, text, "a number")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise self.error(f"attribute '{name}' is not a finite number: {text[:40]!r}", element)
        return value

    def numbers(self, element: etree._Element, names: tuple[str, ...]) -> tuple[float, ...]:
        """Several required finite float attributes (fast path; errors from ``number``)."""
        texts = list(map(element.get, names))
        try:
            values = tuple(map(float, texts))  # type: ignore[arg-type]
        except (TypeError, ValueError):
            values = (math.nan,)
        if math.isfinite(sum(values)):  # any NaN or inf makes the sum non-finite
            joined = "".join(texts)  # type: ignore[arg-type]
            if joined.isascii() and "_" not in joined:  # the XML Schema form, see ``lexical_form``
                return values
        return tuple(self.number(element, name) for name in names)

    def lexical_form(self, element: etree._Element, name: str, text: str, kind: str) -> None:
        """Refuse what Python's ``float``/``int`` read beyond the XML Schema lexical form of a
        double or an integer: digit-group underscores ("1_0") and non-ASCII digits or spaces
        (full-width "１０"); for ASCII text without "_" the two forms agree."""
        if not text.isascii() or "_" in text:
            raise self.error(f"attribute '{name}' is not {kind} in the XML Schema form: {text[:40]!r}", element)

    def coefficients(self, element: etree._Element, names: tuple[str, ...]) -> tuple[float, ...]:
        """Finite float attributes that are 0 when absent, recorded for one warning per
        element kind and road; all required when strict."""
        missing = [name for name in names if element.get(name) is None]
        if not missing or self.strict:
            return self.numbers(element, names)
        self.defaulted.setdefault((str(element.tag), self.road_id), set()).update(missing)
        return tuple(self.number(element, name, 0.0) for name in names)

    def warn_defaults(self) -> None:
        """One warning per element kind and road whose records omitted attributes, and one
        for the centre lanes without a type."""
        for (tag, road_id), names in self.defaulted.items():
            _LOG.warning(
                "%s: road %s: <%s> without %s: taken as 0 (strict mode refuses it)",
                self.path or "<input>", road_id, tag, ", ".join(sorted(names)),
            )
        if self.untyped_centres:
            _LOG.warning(
                "%s: the centre <lane> of %d road(s) has no type (first: road %s): taken as \"%s\" (strict mode "
                "refuses it)", self.path or "<input>", len(self.untyped_centres), next(iter(self.untyped_centres)),
                CENTRE_LANE_TYPE,
            )
        if self.single_points:
            road_id, (end, count) = next(iter(self.single_points.items()))
            _LOG.warning(
                "%s: %d road(s) end in <paramPoly3> records that draw a single point (first: road %s, %d record(s) "
                "from s=%.6g m): read as absent, the road and its lanes end there (strict mode refuses them)",
                self.path or "<input>", len(self.single_points), road_id, count, end,
            )
        if self.odd_marks:
            road_id, mark_type = next(iter(self.odd_marks.items()))
            _LOG.warning(
                "%s: <roadMark>s of %d road(s) have no type or one OpenDRIVE does not define (first: road %s, %s): "
                "taken as \"none\" when absent, \"custom\" otherwise (strict mode refuses them)",
                self.path or "<input>", len(self.odd_marks), road_id, mark_type,
            )

    def warn_wrong_side(self, road: Road) -> None:
        """One warning per road whose lanes run over their inner neighbours
        (``lanes.wrong_side_lanes``)."""
        found = wrong_side_lanes(road)
        if not found:
            return
        worst = min(found, key=lambda lane: lane.width_m)
        hint = ("; we read a <border> as t from the centre lane (ASAM), a map that writes right lanes' borders as "
                "distances is drawn wrongly" if any(lane.from_borders for lane in found) else "")
        _LOG.warning(
            "%s: road %s: %d lane(s) have their outer border on the inner side of the inner one, so they run over "
            "the next lane inwards (worst: section %d lane %d, width %.3f m from its <%s> records)%s",
            self.path or "<input>", road.id, len(found), worst.section, worst.lane_id, worst.width_m,
            "border" if worst.from_borders else "width", hint,
        )

    def integer(self, element: etree._Element, name: str) -> int:
        text = self.required(element, name)
        self.lexical_form(element, name, text, "an integer")
        try:
            return int(text)
        except ValueError:
            raise self.error(f"attribute '{name}' is not an integer: {text[:40]!r}", element) from None

    def flag(self, element: etree._Element, name: str) -> bool:
        text = element.get(name)
        if text is None:
            return False
        value = _BOOLEANS.get(text.strip().lower())
        if value is None:
            raise self.error(f"attribute '{name}' is not a boolean: {text[:40]!r}", element)
        return value

    def choice(self, element: etree._Element, name: str, allowed: tuple[str, ...], default: str | None = None) -> str:
        """One of ``allowed`` (matched case-insensitively, returned as spelled there)."""
        text = element.get(name)
        if text is None:
            if default is None:
                raise self.error(f"missing required attribute '{name}'", element)
            return default
        folded = text.strip().lower()
        for option in allowed:
            if option.lower() == folded:
                return option
        raise self.error(f"attribute '{name}' is {text[:40]!r}, expected one of {', '.join(allowed)}", element)

    def cubic(self, element: etree._Element, s_name: str) -> CubicPoly:
        return CubicPoly(*self.coefficients(element, (s_name, "a", "b", "c", "d")))

    def cubics(self, elements: Iterable[etree._Element], s_name: str) -> tuple[CubicPoly, ...]:
        return tuple(sorted((self.cubic(e, s_name) for e in elements), key=_by_s0))

    # -- elements -----------------------------------------------------------------------

    def read_map(self, elements: Iterator[etree._Element]) -> OpenDriveMap:
        """The map from ``xml_safety.iter_xml``'s stream: the root, then its children."""
        root = next(elements)
        namespaced = isinstance(root.tag, str) and root.tag.startswith("{")
        if namespaced:
            _strip_namespaces(root)
        if root.tag != "OpenDRIVE":
            raise self.error("root element is not <OpenDRIVE>", root)
        header: Header | None = None
        roads: dict[str, Road] = {}
        junctions: dict[str, Junction] = {}
        links: list[_Link] = []
        for child in elements:
            if namespaced:
                _strip_namespaces(child)
            tag = child.tag
            self.road_id = ""
            if tag == "road":
                road = self.road(child, links)
                if road.id in roads:
                    raise self.error(f"duplicate road id {road.id!r}", child)
                roads[road.id] = road
            elif tag == "junction":
                junction = self.junction(child, links)
                if junction.id in junctions:
                    raise self.error(f"duplicate junction id {junction.id!r}", child)
                junctions[junction.id] = junction
            elif tag == "header":
                if header is not None:
                    raise self.error("more than one <header>", child)
                header = self.header(child)
        if header is None:
            raise self.error("no <header>", root)
        if not roads:
            raise self.error("the map has no <road>", root)
        for road in roads.values():
            validate_road(road, self.path)
            self.warn_wrong_side(road)
        dangling = [link for link in links if link.element_id not in (roads if link.element_type == "road" else junctions)]
        if dangling:
            roads, junctions = self.drop_dangling(dangling, roads, junctions)
        for link in self.no_contact:
            if link.element_id in roads:
                raise self.error_at("missing required attribute 'contactPoint'", link.tag, link.line)
        self.warn_defaults()
        return OpenDriveMap(path=self.path, header=header, roads=roads, junctions=junctions)

    def drop_dangling(
        self, dangling: list[_Link], roads: dict[str, Road], junctions: dict[str, Junction]
    ) -> tuple[dict[str, Road], dict[str, Junction]]:
        """Road links and junction connections that name a road or junction not in the
        file, dropped with one warning (libOpenDRIVE reads such maps); a road's
        ``junction`` attribute naming a missing junction is kept (nothing resolves it).
        Strict: refused at the first."""
        first = dangling[0]
        reason = f"links to {first.element_type} {first.element_id!r}, which does not exist"
        if self.strict:
            raise self.error_at(f"{reason} (strict mode refuses links to elements not in the file)", first.tag,
                                first.line)
        missing = {(link.element_type, link.element_id) for link in dangling}

        def kept(link: RoadLink | None) -> RoadLink | None:
            return None if link is not None and (link.element_type, link.element_id) in missing else link

        roads = {
            road_id: road if kept(road.predecessor) is road.predecessor and kept(road.successor) is road.successor
            else replace(road, predecessor=kept(road.predecessor), successor=kept(road.successor))
            for road_id, road in roads.items()
        }
        junctions = {
            junction_id: replace(junction, connections=tuple(
                c for c in junction.connections if c.incoming_road in roads and c.connecting_road in roads))
            for junction_id, junction in junctions.items()
        }
        _LOG.warning(
            "%s: %d link(s) name a road or junction that is not in the file (first: %s, line %s, %s): road links "
            "and junction connections dropped, a road's junction attribute kept (strict mode refuses them)",
            self.path or "<input>", len(dangling), first.owner, first.line or "unknown", reason,
        )
        return roads, junctions

    def header(self, element: etree._Element) -> Header:
        rev_major = self.integer(element, "revMajor")
        rev_minor = self.integer(element, "revMinor")
        if rev_major != 1:
            raise self.error(f"unsupported OpenDRIVE revision {rev_major}.{rev_minor}", element)
        proj = ""
        offset = (0.0, 0.0, 0.0, 0.0)
        for child in element:
            if child.tag == "geoReference":
                proj = (child.text or "").strip()
            elif child.tag == "offset":
                offset = self.numbers(child, ("x", "y", "z", "hdg"))
        nan = math.nan
        return Header(
            rev_major=rev_major,
            rev_minor=rev_minor,
            name=element.get("name", ""),
            vendor=element.get("vendor", ""),
            north=self.number(element, "north", nan),
            south=self.number(element, "south", nan),
            east=self.number(element, "east", nan),
            west=self.number(element, "west", nan),
            geo_reference=GeoReference(proj, *offset),
        )

    def road(self, element: etree._Element, links: list[_Link]) -> Road:
        road_id = self.required(element, "id")
        self.road_id = road_id
        length = self.number(element, "length")
        if length < 0.0:
            raise self.error(f"road {road_id!r} has negative length {length}", element)
        junction = element.get("junction", "-1")
        if junction != "-1":
            links.append(_link("junction", junction, element, f"road {road_id} junction attribute"))
        ends: dict[str, RoadLink | None] = {"predecessor": None, "successor": None}
        plan_view: list[Geometry] = []
        elevation: tuple[CubicPoly, ...] = ()
        superelevation: tuple[CubicPoly, ...] = ()
        lane_offsets: tuple[CubicPoly, ...] = ()
        sections: list[LaneSection] = []
        seen: set[str] = set()
        for child in element:
            tag = child.tag
            if tag in _ONCE_PER_ROAD:
                if tag in seen:
                    raise self.error(f"more than one <{tag}> in road {road_id!r}", child)
                seen.add(tag)
            if tag == "planView":
                plan_view = [geometry for g in child if g.tag == "geometry" and (geometry := self.geometry(g))]
            elif tag == "lanes":
                lane_offsets = self.cubics((e for e in child if e.tag == "laneOffset"), "s")
                sections = self.lane_sections(child, road_id, length)
            elif tag == "elevationProfile":
                elevation = self.cubics((e for e in child if e.tag == "elevation"), "s")
            elif tag == "lateralProfile":
                superelevation = self.cubics((e for e in child if e.tag == "superelevation"), "s")
            elif tag == "link":
                for link in child:
                    end = link.tag
                    if end in ends:
                        if ends[end] is not None:
                            raise self.error(f"more than one road {end}", link)
                        ends[end] = self.road_link(link, links, f"road {road_id} {end}")
        if not plan_view:
            raise self.error(f"road {road_id!r} has no <planView> geometry", element)
        if not sections:
            raise self.error(f"road {road_id!r} has no <laneSection>", element)
        plan_view.sort(key=_by_s)
        if is_single_point(plan_view[-1]):
            plan_view, sections, length = self.end_before_points(element, plan_view, sections)
        return Road(
            id=road_id,
            name=element.get("name", ""),
            length=length,
            junction=junction,
            rule=self.choice(element, "rule", _RULES, "RHT"),
            predecessor=ends["predecessor"],
            successor=ends["successor"],
            plan_view=tuple(plan_view),
            elevation=elevation,
            lane_offsets=lane_offsets,
            lane_sections=tuple(sections),
            line=source_line(element) or 0,
            superelevation=superelevation,
        )

    def end_before_points(
        self, element: etree._Element, plan_view: list[Geometry], sections: list[LaneSection]
    ) -> tuple[list[Geometry], list[LaneSection], float]:
        """The road without its last ``<geometry>`` records that draw a single point
        (``param_poly3.is_single_point``): it and its lanes end where the first of them
        starts (recorded for one warning per map); refused when strict or when no record
        is left."""
        kept = len(plan_view)
        while kept and is_single_point(plan_view[kept - 1]):
            kept -= 1
        first = plan_view[kept] if kept < len(plan_view) else plan_view[0]
        if self.strict or kept == 0:
            which = "every <geometry> record" if kept == 0 else f"the <geometry> at s={first.s:.6g}"
            mode = "; strict mode refuses it" if kept else ""
            raise self.error(f"road {self.road_id!r}: {which} is a <paramPoly3> that draws a single point (every "
                             f"coefficient but aU, aV is 0){mode}", element)
        end = first.s
        ended = [section for section in sections if section.s < end] or sections[:1]
        ended[-1] = replace(ended[-1], s_end=end)
        self.single_points.setdefault(self.road_id, (end, len(plan_view) - kept))
        return plan_view[:kept], ended, end

    def road_link(self, element: etree._Element, links: list[_Link], owner: str) -> RoadLink:
        element_type = self.choice(element, "elementType", ("road", "junction"))
        element_id = self.required(element, "elementId")
        links.append(_link(element_type, element_id, element, owner))
        if element_type == "junction":
            return RoadLink("junction", element_id, None)
        if element.get("contactPoint") is None:
            self.no_contact.append(links[-1])
            return RoadLink("road", element_id, None)
        return RoadLink("road", element_id, self.choice(element, "contactPoint", _CONTACT_POINTS))

    def geometry(self, element: etree._Element) -> Geometry | None:
        """The record, or None for a zero-length one (it covers no s; real exporters write them)."""
        start = self.numbers(element, ("s", "x", "y", "hdg", "length"))
        length = start[4]
        if length < 0.0:
            raise self.error(f"geometry length must be >= 0, got {length}", element)
        shapes = [child for child in element if child.tag in _GEOMETRY_KINDS]
        if len(shapes) != 1:
            found = "no known kind" if not shapes else f"{len(shapes)} shapes ({', '.join(str(s.tag) for s in shapes)})"
            expected = ", ".join(sorted(_GEOMETRY_KINDS))
            raise self.error(f"geometry has {found} (expected exactly one of {expected})", element)
        if length == 0.0:
            return None
        shape = shapes[0]
        kind = shape.tag
        if kind == "line":
            return Geometry("line", *start)
        coefficients = self.coefficients
        if kind == "arc":
            return Geometry("arc", *start, curvature=coefficients(shape, ("curvature",))[0])
        if kind == "spiral":
            curv_start, curv_end = coefficients(shape, ("curvStart", "curvEnd"))
            return Geometry("spiral", *start, curv_start=curv_start, curv_end=curv_end)
        if kind == "poly3":
            a, b, c, d = coefficients(shape, ("a", "b", "c", "d"))
            return Geometry("poly3", *start, a=a, b=b, c=c, d=d)
        au, bu, cu, du, av, bv, cv, dv = coefficients(shape, ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV"))
        return Geometry(
            "paramPoly3", *start,
            au=au, bu=bu, cu=cu, du=du, av=av, bv=bv, cv=cv, dv=dv,
            p_range=self.choice(shape, "pRange", _P_RANGES, "normalized"),
        )  # fmt: skip

    def lane_sections(self, lanes: etree._Element, road_id: str, length: float) -> list[LaneSection]:
        """The sections sorted by s, each ending where the next starts (the last at ``length``)."""
        sections = []
        for element in lanes:
            if element.tag == "laneSection":
                section = self.lane_section(element)
                if section.s > length + SECTION_START_TOLERANCE_M:
                    reason = f"lane section starts at s={section.s}, after the end of road {road_id!r} ({length})"
                    raise self.error(reason, element)
                sections.append(section)
        sections.sort(key=_by_s)
        starts = [min(section.s, length) for section in sections]
        ends = starts[1:] + [length]
        return [replace(section, s=s, s_end=s_end) for section, s, s_end in zip(sections, starts, ends)]

    def lane_section(self, element: etree._Element) -> LaneSection:
        """One section; ``s_end`` is NaN until ``lane_sections`` knows the next start."""
        s = self.number(element, "s")
        if s < 0.0:
            raise self.error(f"lane section starts at negative s={s}", element)
        left: list[Lane] = []
        center: list[Lane] = []
        right: list[Lane] = []
        for side in element:
            target = {"left": left, "center": center, "right": right}.get(side.tag)
            if target is not None:
                target.extend(self.lane(lane) for lane in side if lane.tag == "lane")
        left.sort(key=_by_id)
        right.sort(key=_by_id, reverse=True)
        self.check_lane_ids(left, 1, "left", element)
        self.check_lane_ids(right, -1, "right", element)
        if len(center) != 1 or center[0].id != 0:
            found = ", ".join(str(lane.id) for lane in center) or "none"
            raise self.error(f"lane section needs exactly one <center> lane with id 0, found: {found}", element)
        return LaneSection(s, math.nan, self.flag(element, "singleSide"), tuple(left), center[0], tuple(right))

    def check_lane_ids(self, lanes: list[Lane], sign: int, side: str, section: etree._Element) -> None:
        ids = [lane.id for lane in lanes]
        expected = [sign * (index + 1) for index in range(len(lanes))]
        if ids != expected:
            raise self.error(
                f"{side} lane ids must be {', '.join(map(str, expected))} (consecutive from the reference line), "
                f"found {', '.join(map(str, ids))}",
                section,
            )

    def lane(self, element: etree._Element) -> Lane:
        lane_id = self.integer(element, "id")
        widths: list[etree._Element] = []
        borders: list[etree._Element] = []
        predecessors: list[int] = []
        successors: list[int] = []
        marks: list[RoadMark] = []
        for child in element:
            tag = child.tag
            if tag == "width":
                widths.append(child)
            elif tag == "border":
                borders.append(child)
            elif tag == "roadMark":
                marks.append(self.road_mark(child))
            elif tag == "link":
                for link in child:
                    if link.tag == "predecessor":
                        predecessors.append(self.integer(link, "id"))
                    elif link.tag == "successor":
                        successors.append(self.integer(link, "id"))
        if lane_id == 0 and element.get("type") is None and not self.strict:
            self.untyped_centres[self.road_id] = None
            lane_type = CENTRE_LANE_TYPE
        else:
            lane_type = self.required(element, "type")
        return Lane(
            id=lane_id,
            type=lane_type,
            level=self.flag(element, "level"),
            widths=self.cubics(widths, "sOffset"),
            borders=self.cubics(borders, "sOffset"),
            predecessors=tuple(predecessors),
            successors=tuple(successors),
            direction=self.choice(element, "direction", _LANE_DIRECTIONS, ""),
            road_marks=tuple(sorted(marks, key=_by_s_offset)),
        )

    def road_mark(self, element: etree._Element) -> RoadMark:
        """One ``<roadMark>`` with the ``<line>``s of its ``<type>`` child."""
        mark_type = element.get("type")
        if self.strict or (mark_type is not None and mark_type.strip().lower() in ROAD_MARK_TYPES):
            mark_type = self.choice(element, "type", ROAD_MARK_TYPES)
        else:
            self.odd_marks.setdefault(self.road_id, "no type" if mark_type is None else repr(mark_type[:40]))
            mark_type = "none" if mark_type is None else "custom"
        type_element = next((child for child in element if child.tag == "type"), None)
        lines = () if type_element is None else tuple(
            RoadMarkLine(
                *self.coefficients(line, ("length", "space", "tOffset", "sOffset")),
                rule=line.get("rule", ""),
                width=self.optional_number(line, "width"),
                color=line.get("color", ""),
            )
            for line in type_element if line.tag == "line"
        )
        return RoadMark(
            s_offset=self.coefficients(element, ("sOffset",))[0],
            type=mark_type,
            weight=element.get("weight", "standard"),
            color=element.get("color", "standard"),
            width=self.optional_number(element, "width"),
            lane_change=self.choice(element, "laneChange", _LANE_CHANGES, "both"),
            material=element.get("material", ""),
            height=self.number(element, "height", 0.0),
            type_name="" if type_element is None else type_element.get("name", ""),
            lines=lines,
        )

    def optional_number(self, element: etree._Element, name: str) -> float | None:
        """A finite float attribute, None when absent."""
        return None if element.get(name) is None else self.number(element, name)

    def junction(self, element: etree._Element, links: list[_Link]) -> Junction:
        connections = []
        for child in element:
            if child.tag != "connection":
                continue
            incoming = self.required(child, "incomingRoad")
            connecting = child.get("connectingRoad") or child.get("linkedRoad")
            if connecting is None:
                raise self.error("missing required attribute 'connectingRoad'", child)
            owner = f"junction {element.get('id')} connection {child.get('id')}"
            links.append(_link("road", incoming, child, owner))
            links.append(_link("road", connecting, child, owner))
            lane_links = tuple(
                LaneLink(self.integer(link, "from"), self.integer(link, "to"))
                for link in child
                if link.tag == "laneLink"
            )
            connections.append(
                Connection(
                    id=self.required(child, "id"),
                    incoming_road=incoming,
                    connecting_road=connecting,
                    contact_point=self.choice(child, "contactPoint", _CONTACT_POINTS),
                    lane_links=lane_links,
                )
            )
        return Junction(
            id=self.required(element, "id"),
            name=element.get("name", ""),
            connections=tuple(connections),
            type=self.choice(element, "type", _JUNCTION_TYPES, "default"),
        )


class _Link(NamedTuple):
    """A reference to a road or junction by id, and where the file makes it (no element:
    the streamed tree drops each road once read).

    Fields:
        element_type: "road" or "junction".
        element_id: the id it names.
        tag, line: the element that names it and its source line (None when unknown).
        owner: who names it, e.g. ``road 1 predecessor``, ``junction 7 connection 3``.
    """

    element_type: str
    element_id: str
    tag: str
    line: int | None
    owner: str


def _link(element_type: str, element_id: str, element: etree._Element, owner: str) -> _Link:
    return _Link(element_type, element_id, str(element.tag), source_line(element), owner)


def _by_s0(record: CubicPoly) -> float:
    return record.s0


def _by_s_offset(record: RoadMark) -> float:
    return record.s_offset


def _by_s(record: Geometry | LaneSection) -> float:
    return record.s


def _by_id(lane: Lane) -> int:
    return lane.id
