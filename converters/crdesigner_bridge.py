"""OpenDRIVE → CommonRoad lanelets through commonroad-scenario-designer, in the inertial frame.

crdesigner re-projects every vertex from the map's geoReference to pseudo-Mercator
(``proj_string_odr``); we switch that off, so the CommonRoad vertices stay in the
OpenDRIVE inertial frame (nor is the header's ``<offset>``: crdesigner would subtract it
from every geometry record, so the copy it converts has none, see ``crdesigner_copy``).
We also skip its lane join/split "mirroring", which moves the borders of a lane that
opens or closes from zero width (bundled highway.xodr: lane -4 off by up to 4 m), so the
lanelets keep the OpenDRIVE borders. And we record, before crdesigner renumbers its
lanelets and forgets where they came from, the OpenDRIVE lanes each lanelet covers.
crdesigner 0.8.5 crashes (AttributeError ``has_unique_pred_succ_relation``) on every
lanelet with an opposite-direction right neighbour and a unique successor, i.e. on any
left-hand-traffic road with two lane sections or a road link: its right-side neighbour
check calls the network's method on the lanelet. We replace that check by the same check
called on the network (``_adjacent_consistent``, identical to its left-side twin).
crdesigner evaluates ``<paramPoly3>`` at p = s/length·pRange and ``<poly3>`` at u = s,
which is the arc length the spec's s stands for only at uniform parameter speed (lanes
off by dw/ds·Δs laterally, lanelet ends by Δs along track: 0.77 m on a 50 m curve with
speed 1 ± 30 %); we evaluate them at the parameter whose arc length is s
(``_arc_length_parameter``; for paramPoly3 scaled so the record still ends at p_end, as
``cold_maps.opendrive.geometry.param_poly3`` does).
crdesigner also reads road and junction ids as integers (OpenDRIVE ids are strings),
rejects spirals of (nearly, ``np.isclose``) constant curvature, divides by an arc's
curvature (``ZeroDivisionError`` on a straight ``<arc curvature="0">``), cleans an empty
``<geoReference>``'s None text (``TypeError``), reads only ``connectingRoad`` in
junction connections (``int(None)`` on a direct junction's ``linkedRoad``) and places
each ``<geometry>`` record at the running sum of the lengths before it, not at its ``s``
(raising "Tried to calculate a position outside of the borders of the reference path"
when the sum falls short of the road length): such maps are converted from a rewritten
copy (``crdesigner_copy``), and the lanelets' OpenDRIVE lanes name the original roads.
A signal whose country crdesigner has no sign catalogue or stop-line entry for
(``KeyError: 'SWE'``, ``KeyError: 'BEL'``) is read as its fallback country "ZAM" (signs
are not part of our output). Objects outlined with ``<cornerRoad>`` (crdesigner reads only
``<cornerLocal>``: shapely ``NotImplementedError``) are left out of the copy.
crdesigner and its dependencies are imported inside ``odr_to_lanelets`` only.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import tempfile
import threading
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from lxml import etree

from converters.elevation import RoadHeights
from converters.errors import ConversionError
from converters.regulatory import LaneletRegulations, regulations_of, road_speed_limits

NDArrayFloat = npt.NDArray[np.float64]

MAX_FILE_BYTES: Final[int] = 256 * 1024 * 1024
"""Largest OpenDRIVE file we hand to the converter (bytes)."""

_ONE_AT_A_TIME: Final[threading.Lock] = threading.Lock()
"""crdesigner keeps global state (an id counter) and we patch two of its functions
during a conversion: one conversion at a time per process."""


@dataclass(frozen=True)
class SourceLanelet:
    """One lanelet to write: a CommonRoad lanelet as converted by crdesigner, or a lane of
    one lane section built from another reader (the map engine) in the same terms.

    Fields:
        id: CommonRoad lanelet id (positive; kept as the Lanelet2 lanelet id).
        left, right: (N, 2) borders in the inertial frame (m), ordered in driving
            direction; ``left`` is on the left of a driver.
        types: CommonRoad lanelet type values, e.g. {"urban", "intersection"}.
        left_marking, right_marking: CommonRoad line markings of the borders ("dashed",
            "solid", "no_marking", "curb", ...; "unknown" when crdesigner has none).
        opendrive_lanes: the OpenDRIVE lanes the lanelet covers, in driving order, as
            (road id, lane-section index, lane id); empty for crosswalks.
        junctions: ids of the OpenDRIVE junctions its roads belong to.
        left_z, right_z: (N,) heights (m) of the border vertices from the road's
            elevation profile (``converters.elevation``); None when unknown.
        regulations: speed limit, traffic lights and right of way crdesigner assigned.
        successors: ids of the lanelets crdesigner links after this one (from the
            OpenDRIVE road, lane and junction links), whether or not their ends touch.
        left_tags, right_tags: Lanelet2 way tags (key, value) of the border; when given
            they replace the tags of ``left_marking`` / ``right_marking``.
    """

    id: int
    left: NDArrayFloat
    right: NDArrayFloat
    types: frozenset[str]
    left_marking: str = "unknown"
    right_marking: str = "unknown"
    opendrive_lanes: tuple[tuple[str, int, int], ...] = ()
    junctions: tuple[str, ...] = ()
    left_z: NDArrayFloat | None = None
    right_z: NDArrayFloat | None = None
    regulations: LaneletRegulations = LaneletRegulations()
    successors: tuple[int, ...] = ()
    left_tags: tuple[tuple[str, str], ...] = ()
    right_tags: tuple[tuple[str, str], ...] = ()


_HARDENED: Final[dict[str, bool]] = {
    "resolve_entities": False, "no_network": True, "load_dtd": False, "huge_tree": False, "remove_pis": True}
"""lxml parser options for untrusted maps: no entities, DTD or network, bounded trees."""


def _hardened_parser() -> etree.XMLParser:
    return etree.XMLParser(**_HARDENED)


def read_geo_reference(path: Path, *, header_only: bool = False) -> str:
    """Check that ``path`` is a readable OpenDRIVE file; return its geoReference ("" if none).

    With ``header_only`` the XML is parsed up to the end of the root's first ``<header>``
    (OpenDRIVE has one), the rest neither parsed nor checked: for a map converted already.
    Raises ConversionError for a missing, oversized or malformed file, a DOCTYPE (never
    needed by OpenDRIVE, and the only way in for entity attacks) or a non-OpenDRIVE root.
    """
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ConversionError(str(path), f"file is {size} bytes, more than the {MAX_FILE_BYTES} allowed")
        data = path.read_bytes()
    except OSError as exc:
        raise ConversionError(str(path), f"cannot read the map: {exc.strerror or exc}") from exc
    root_start = data.find(b"<OpenDRIVE")
    if b"<!DOCTYPE" in data[: root_start if root_start >= 0 else len(data)]:
        raise ConversionError(str(path), "a DOCTYPE is not allowed in an OpenDRIVE map")
    try:
        root, header = _read_to_header(data) if header_only else (etree.fromstring(data, _hardened_parser()), None)
    except etree.XMLSyntaxError as exc:
        raise ConversionError(str(path), f"not well-formed XML: {exc}") from exc
    if etree.QName(root).localname != "OpenDRIVE":
        raise ConversionError(str(path), f"root element is <{etree.QName(root).localname}>, not <OpenDRIVE>")
    geo = root.find("{*}header/{*}geoReference") if header is None else header.find("{*}geoReference")
    return "" if geo is None else " ".join((geo.text or "").split())


_HEADER_CHUNK_BYTES: Final[int] = 1 << 16
"""Bytes ``_read_to_header`` parses at a time."""


def _read_to_header(data: bytes) -> tuple[etree._Element, etree._Element | None]:
    """The root of the XML ``data`` and its first ``<header>`` child, parsed (hardened) up
    to that header's end; without a header (or under another root than ``<OpenDRIVE>``,
    given back at once), None for the header."""
    parser = etree.XMLPullParser(events=("start", "end"), **_HARDENED)
    root = None
    for first in range(0, len(data), _HEADER_CHUNK_BYTES):
        parser.feed(data[first : first + _HEADER_CHUNK_BYTES])
        for event, element in parser.read_events():
            if root is None:
                root = element
                if etree.QName(root).localname != "OpenDRIVE":
                    return root, None
            elif event == "end" and element.getparent() is root and etree.QName(element).localname == "header":
                return root, element
    return parser.close(), None


@contextlib.contextmanager
def _quiet(verbose: bool) -> Iterator[None]:
    """Silence crdesigner's warnings, log records and prints unless ``verbose``."""
    if verbose:
        yield
        return
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(previous)


def crdesigner_version() -> str:
    """Installed commonroad-scenario-designer version (part of the cache key)."""
    from importlib.metadata import version

    return version("commonroad-scenario-designer")


def odr_to_lanelets(path: Path, *, verbose: bool = False) -> tuple[list[SourceLanelet], str]:
    """Convert an OpenDRIVE file with crdesigner: lanelets in the inertial frame and the
    map's geoReference ("" if none).

    Raises ConversionError naming ``path`` when the file is unreadable, crdesigner fails
    or finds no lanelet.
    """
    geo_reference = read_geo_reference(path)
    renumbered = crdesigner_copy(path.read_bytes())
    with _quiet(verbose), tempfile.TemporaryDirectory(prefix="cold-maps-ids-") as folder:
        source = path
        if renumbered is not None:
            source = Path(folder) / path.name
            source.write_bytes(renumbered[0])
        try:
            scenario, sources, opendrive = _run_crdesigner(source)
        except Exception as exc:  # crdesigner raises anything from KeyError to IndexError
            kind = type(exc).__name__
            why = f"{kind}: {exc}" if str(exc) else f"{kind} without a message (-vv: where)"
            raise ConversionError(str(path), f"converter crashed: {why}") from exc
    heights = RoadHeights(opendrive)
    junction_of = {str(road.id): str(road.junction.id) for road in opendrive.roads if road.junction is not None}
    network = scenario.lanelet_network
    roads_of = {lanelet: [road for road, _, _ in lanes] for lanelet, lanes in sources.items()}  # crdesigner's ids
    speeds = road_speed_limits(opendrive)
    road_limits = {
        lanelet: min(speeds[road] for road in roads if road in speeds)
        for lanelet, roads in roads_of.items()
        if any(road in speeds for road in roads)
    }
    regulations = regulations_of(network, road_limits)
    junctions = {lanelet: tuple(sorted({junction_of[r] for r in roads if r in junction_of})) for lanelet, roads in roads_of.items()}

    def height(vertices: Any, lanelet_id: int) -> NDArrayFloat:
        return heights.heights(np.asarray(vertices, dtype=np.float64)[:, :2], roads_of.get(lanelet_id, []))

    if renumbered is not None:
        original = renumbered[1]
        sources = {
            lanelet: tuple((original.get(road, road), section, lane) for road, section, lane in lanes)
            for lanelet, lanes in sources.items()
        }
    lanelets = [
        SourceLanelet(
            id=int(lanelet.lanelet_id),
            left=np.asarray(lanelet.left_vertices, dtype=np.float64)[:, :2],
            right=np.asarray(lanelet.right_vertices, dtype=np.float64)[:, :2],
            types=frozenset(str(t.value) for t in lanelet.lanelet_type),
            left_marking=str(lanelet.line_marking_left_vertices.value),
            right_marking=str(lanelet.line_marking_right_vertices.value),
            opendrive_lanes=sources.get(int(lanelet.lanelet_id), ()),
            junctions=junctions.get(int(lanelet.lanelet_id), ()),
            left_z=height(lanelet.left_vertices, int(lanelet.lanelet_id)),
            right_z=height(lanelet.right_vertices, int(lanelet.lanelet_id)),
            regulations=regulations.get(int(lanelet.lanelet_id), LaneletRegulations()),
            successors=tuple(int(i) for i in lanelet.successor),
        )
        for lanelet in network.lanelets
    ]
    if not lanelets:
        raise ConversionError(str(path), "the converter produced no lanelets (no convertible lanes?)")
    for lanelet in lanelets:
        if not (np.isfinite(lanelet.left).all() and np.isfinite(lanelet.right).all()):
            raise ConversionError(str(path), f"the converter produced non-finite vertices in lanelet {lanelet.id}")
    return lanelets, geo_reference


ARC_TABLE_POINTS: Final[int] = 4097
"""Samples of |r'(p)| per paramPoly3/poly3 record for its arc-length table (trapezoid
rule; error ~ length·h²·max|speed''|/12, below 1e-8 m on road curves)."""


def _arc_length_parameter(
    record: Any, derivatives: tuple[Any, Any], p_end: float, arc: float, scale_to_end: bool
) -> float:
    """The parameter in [0, p_end] at arc length ``arc`` (m) along a crdesigner geometry
    record whose derivative coefficients (u', v') are given; with ``scale_to_end``,
    ``arc`` is a fraction of the record length, times the curve's own length. The table
    is kept on the record (crdesigner evaluates each record hundreds of times)."""
    table = record.__dict__.get("_cold_maps_arc_table")
    if table is None:
        p = np.linspace(0.0, p_end, ARC_TABLE_POINTS)
        speed = np.hypot(*(np.polynomial.polynomial.polyval(p, d) for d in derivatives))
        table = p, np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(p))))
        record.__dict__["_cold_maps_arc_table"] = table
    p, length = table
    return float(np.interp(arc * length[-1] if scale_to_end else arc, length, p))


def _param_poly3_by_arc_length(original: Any) -> Any:
    """crdesigner's ``ParamPoly3.calc_position`` with s read as arc length."""

    def calc_position(self: Any, s_pos: float, compute_curvature: bool = True) -> Any:
        p = _arc_length_parameter(self, (self.d_coeffs_u, self.d_coeffs_v), self._pRange, s_pos / self.length, True)
        return original(self, p / self._pRange * self.length, compute_curvature)

    return calc_position


def _poly3_by_arc_length(original: Any) -> Any:
    """crdesigner's ``Poly3.calc_position`` (u = its argument) with s read as arc length."""

    def calc_position(self: Any, s_pos: float, compute_curvature: bool = True) -> Any:
        u = _arc_length_parameter(self, ([1.0], self.d_coeffs), self.length, s_pos, False)
        return original(self, u, compute_curvature)

    return calc_position


_ROAD_REFERENCES: Final[tuple[tuple[str, str], ...]] = (
    ("connection", "incomingRoad"),
    ("connection", "connectingRoad"),
    ("connection", "linkedRoad"),
)


def _is_integer(text: str) -> bool:
    try:
        int(text)
    except ValueError:
        return False
    return True


def crdesigner_copy(data: bytes) -> tuple[bytes, dict[str, str]] | None:
    """The map ``data`` rewritten where crdesigner 0.8.5 rejects valid OpenDRIVE, and the
    map from new road id to original road id; None when nothing needs rewriting.

    Non-integer road and junction ids become fresh integers (crdesigner parses ids with
    ``int``), with every reference; spirals of constant curvature (crdesigner raises
    "Curvature at the start and at the end of a spiral must be different") become the
    arcs or lines they are, and arcs of zero curvature (crdesigner divides by it) lines;
    the header elements crdesigner mishandles are dropped (``_header_it_reads``); lane
    types it lacks become the nearest it knows (``_lane_types_it_knows``); a ``<signal>``
    whose s lies off its road (crdesigner places it on the reference line and raises) is
    moved to the nearer road end; a junction connection naming only a ``linkedRoad``
    (direct junction) names it as ``connectingRoad`` too; line, arc and spiral records are
    lengthened or shortened to end where the next record (or the road) starts
    (``_align_records``); crosswalks it cannot outline are dropped (``_crosswalks_it_reads``).
    A file in another encoding than UTF-8 (UTF-16, Latin-1) is
    written as UTF-8: crdesigner opens the file as text in the locale's encoding
    (``UnicodeDecodeError`` on a UTF-16 byte-order mark). ``data`` has been checked by
    ``read_geo_reference``.
    """
    root = etree.fromstring(data, _hardened_parser())
    original = _renumber(root)
    encoding = (root.getroottree().docinfo.encoding or "UTF-8").upper().replace("_", "-")
    rewrites = (_constant_spirals_to_arcs(root) + _straight_arcs_to_lines(root) + _header_it_reads(root)
                + _lane_types_it_knows(root) + _signals_on_their_roads(root) + _linked_as_connecting(root)
                + _align_records(root) + _crosswalks_it_reads(root) + (encoding not in ("UTF-8", "UTF8")))
    if original is None and not rewrites:
        return None
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8"), original or {}


def _local_name(element: etree._Element) -> str:
    """The tag without namespace; "" for comments and processing instructions."""
    return etree.QName(element).localname if isinstance(element.tag, str) else ""


def _renumber(root: etree._Element) -> dict[str, str] | None:
    """Give non-integer road and junction ids fresh integers above the largest integer id,
    rewrite road ``junction``, link ``elementId`` (by ``elementType``) and junction
    connection roads; new road id → original, or None when every id is an integer."""
    renames: dict[str, dict[str, str]] = {}
    for kind in ("road", "junction"):
        ids = [e.get("id", "") for e in root if _local_name(e) == kind]
        taken = [int(i) for i in ids if _is_integer(i)]
        fresh = iter(range(max(taken, default=0) + 1, 1 << 62))
        renames[kind] = {i: str(next(fresh)) for i in dict.fromkeys(ids) if not _is_integer(i)}
    road_ids, junction_ids = renames["road"], renames["junction"]
    if not road_ids and not junction_ids:
        return None
    for element in root:
        name = _local_name(element)
        if name in renames:
            element.set("id", renames[name].get(element.get("id", ""), element.get("id", "")))
    for element in root.iter():
        name = _local_name(element)
        if name == "road" and element.get("junction") in junction_ids:
            element.set("junction", junction_ids[element.get("junction")])
        if name in ("predecessor", "successor") and element.get("elementId") is not None:
            table = junction_ids if element.get("elementType") == "junction" else road_ids
            element.set("elementId", table.get(element.get("elementId"), element.get("elementId")))
        for tag, attribute in _ROAD_REFERENCES:
            if name == tag and element.get(attribute) in road_ids:
                element.set(attribute, road_ids[element.get(attribute)])
    return {new: old for old, new in road_ids.items()}


def _constant_spirals_to_arcs(root: etree._Element) -> int:
    """Replace each ``<spiral>`` whose curvStart and curvEnd crdesigner calls equal
    (``np.isclose``, as its parser tests them) by the ``<arc>`` of their mean curvature (or
    a ``<line>`` at zero curvature; the lateral difference is below Δκ·L²/8, 1e-4 m for a
    100 m spiral at κ = 0.01 1/m); the number replaced."""
    replaced = 0
    for spiral in list(root.iter("{*}spiral")):
        start, end = spiral.get("curvStart"), spiral.get("curvEnd")
        try:
            constant = bool(np.isclose(float(start), float(end)))  # type: ignore[arg-type]
        except (TypeError, ValueError):
            continue  # crdesigner names the bad attribute itself
        if not constant:
            continue
        curvature = 0.5 * (float(start) + float(end))  # type: ignore[arg-type]
        shape = etree.Element("arc", curvature=repr(curvature)) if curvature else etree.Element("line")
        spiral.getparent().replace(spiral, shape)
        replaced += 1
    return replaced


def _straight_arcs_to_lines(root: etree._Element) -> int:
    """Replace each ``<arc>`` of curvature 0 (crdesigner's arc divides by it) by the
    ``<line>`` it is; the number replaced."""
    replaced = 0
    for arc in list(root.iter("{*}arc")):
        try:
            straight = float(arc.get("curvature", "")) == 0.0
        except ValueError:
            continue  # crdesigner names the bad attribute itself
        if straight:
            arc.getparent().replace(arc, etree.Element("line"))
            replaced += 1
    return replaced


def _signals_on_their_roads(root: etree._Element) -> int:
    """Move each ``<signal>`` whose s lies outside [0, its road's length] to the nearer
    end (writers round: CommonRoad's USA_Lanker puts one 0.6 m past a 51.9 m road); the
    number moved. Signals carry no lane geometry, only the regulatory elements."""
    moved = 0
    for road in root.iter("{*}road"):
        try:
            length = float(road.get("length", ""))
        except ValueError:
            continue  # crdesigner names the bad attribute itself
        for signal in road.iterfind("{*}signals/{*}signal"):
            try:
                s = float(signal.get("s", ""))
            except ValueError:
                continue
            if not 0.0 <= s <= length:
                signal.set("s", repr(min(max(s, 0.0), length)))
                moved += 1
    return moved


CRDESIGNER_LANE_TYPES: Final[frozenset[str]] = frozenset({
    "none", "driving", "stop", "shoulder", "biking", "sidewalk", "border", "restricted", "parking", "bidirectional",
    "median", "special1", "special2", "special3", "roadWorks", "tram", "rail", "entry", "exit", "offRamp", "onRamp",
    "curb", "connectingRamp"})
"""Lane types crdesigner 0.8.5 accepts (``roadLanes.Lane.laneTypes``; any other raises an
``Exception`` without a message)."""
KNOWN_LANE_TYPE: Final[dict[str, str]] = {"slipLane": "driving", "walking": "sidewalk"}
"""Lane type given to crdesigner for a newer one it lacks ("none" for the rest: HOV, bus,
taxi, shared, ... are not converted)."""


def _lane_types_it_knows(root: etree._Element) -> int:
    """Give each lane whose type crdesigner does not know its ``KNOWN_LANE_TYPE`` (else
    "none"), and a centre lane without a type "none" (what our parser reads it as; ASAM's
    Ex_Entry_Exit omits it, crdesigner raises); the number retyped."""
    retyped = 0
    for lane in root.iter("{*}lane"):
        lane_type = lane.get("type")
        untyped_centre = lane_type is None and _local_name(lane.getparent()) == "center"
        if untyped_centre or (lane_type is not None and lane_type not in CRDESIGNER_LANE_TYPES):
            lane.set("type", KNOWN_LANE_TYPE.get(lane_type or "", "none"))
            retyped += 1
    return retyped


def _header_it_reads(root: etree._Element) -> int:
    """Remove the header's ``<offset>`` (crdesigner subtracts it from every record's x, y
    and hdg, which moves the lanelets out of the inertial frame and, with an hdg, bends
    them; ``cold_maps.opendrive.georeference`` applies it where it belongs) and a
    ``<geoReference>`` without text (crdesigner cleans its None text as a projection
    string; ``read_geo_reference`` reads it as ""); the number removed."""
    removed = 0
    for child in list(root.iterfind("{*}header/*")):
        name = _local_name(child)
        if name == "offset" or (name == "geoReference" and not (child.text or "").strip()):
            child.getparent().remove(child)
            removed += 1
    return removed


CONVERTED_LANE_TYPES: Final[tuple[str, ...]] = ("connectingRamp",)
"""OpenDRIVE lane types converted besides crdesigner's default ``filter_types`` (which
has driving, entry, exit, onRamp, offRamp but not the ramp between two motorways)."""

ALIGN_TOLERANCE_M: Final[float] = 1e-6
"""A ``<geometry>`` record ending farther than this (m) from where the next record (or
the road) starts is lengthened or shortened to end there."""


CROSSWALK_CORNERS_MIN: Final[int] = 4
"""Fewest ``<cornerLocal>`` corners of a crosswalk outline crdesigner converts."""


def _crosswalks_it_reads(root: etree._Element) -> int:
    """Remove each crosswalk ``<object>`` whose first outline has fewer than
    ``CROSSWALK_CORNERS_MIN`` ``<cornerLocal>`` corners (an outline of ``<cornerRoad>``s, or
    none): crdesigner reads only ``cornerLocal`` and fits a rectangle over the corners it
    finds (shapely ``NotImplementedError`` on none). Crosswalks are no lanes of the ground
    truth; the number removed."""
    removed = 0
    for crosswalk in [o for o in root.iter("{*}object") if o.get("type") == "crosswalk"]:
        outline = crosswalk.find("{*}outlines/{*}outline")
        if outline is None:
            outline = crosswalk.find("{*}outline")
        if outline is None or len(outline.findall("{*}cornerLocal")) < CROSSWALK_CORNERS_MIN:
            crosswalk.getparent().remove(crosswalk)
            removed += 1
    return removed


def _linked_as_connecting(root: etree._Element) -> int:
    """Give each junction ``<connection>`` with a ``linkedRoad`` and no ``connectingRoad``
    (OpenDRIVE 1.7 direct junction) that road as ``connectingRoad``; the number changed."""
    changed = 0
    for connection in root.iter("{*}connection"):
        if connection.get("connectingRoad") is None and connection.get("linkedRoad") is not None:
            connection.set("connectingRoad", connection.get("linkedRoad", ""))
            changed += 1
    return changed


def _align_records(root: etree._Element) -> int:
    """Make each line, arc or spiral record of a road end where the next record starts
    (the last: where the road ends), as the OpenDRIVE ``s`` attributes place them and as
    our reader evaluates them (a record covers s up to the next record's start); a
    spiral keeps its curvature rate. Other records and unreadable numbers are left to
    crdesigner. Returns the number of records changed."""
    changed = 0
    for road in root.iter("{*}road"):
        records = [g for g in road.iter("{*}geometry")]
        try:
            starts = [float(g.get("s", "")) for g in records]
            ends = [*starts[1:], float(road.get("length", ""))]
            lengths = [float(g.get("length", "")) for g in records]
        except ValueError:
            continue
        for record, start, end, length in zip(records, starts, ends, lengths):
            shape = next((_local_name(c) for c in record if _local_name(c)), "")
            target = end - start
            if shape not in ("line", "arc", "spiral") or target <= 0.0 or abs(target - length) <= ALIGN_TOLERANCE_M:
                continue
            if shape == "spiral":
                spiral = record.find("{*}spiral")
                try:
                    k0, k1 = float(spiral.get("curvStart", "")), float(spiral.get("curvEnd", ""))
                except ValueError:
                    continue
                spiral.set("curvEnd", repr(k0 + (k1 - k0) * target / length))
            record.set("length", repr(target))
            changed += 1
    return changed


STOP_LINE_COUNTRIES: Final[frozenset[str]] = frozenset({"DEU", "ZAM", "USA", "CHN", "ESP"})
"""Countries of crdesigner 0.8.5's stop-line sign table (``traffic_signals.py``, a local
dict): any other country raises ``KeyError`` there for every static sign, even one it has
a sign catalogue for (Belgium on CommonRoad's BEL_Wervik)."""


def _known_country(original: Any, catalogues: Any) -> Any:
    """crdesigner's ``get_signal_country`` answering "ZAM" (its fallback) for a country
    it has no traffic-sign catalogue or no stop-line entry for."""

    def get_signal_country(signal_country: str) -> str:
        country = original(signal_country)
        return country if country in catalogues and country in STOP_LINE_COUNTRIES else "ZAM"

    return get_signal_country


def _run_crdesigner(path: Path) -> tuple[Any, dict[int, tuple[tuple[str, int, int], ...]], Any]:
    """crdesigner's CommonRoad scenario of ``path``, per lanelet id its OpenDRIVE lanes, and
    crdesigner's parsed OpenDRIVE (for the elevation profiles)."""
    from crdesigner.common.config.general_config import GeneralConfig
    from crdesigner.common.config.opendrive_config import OpenDriveConfig
    from crdesigner.map_conversion.common.conversion_lanelet_network import ConversionLaneletNetwork
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_conversion import network as network_module
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_parser.elements.geometry import ParamPoly3, Poly3
    from commonroad.scenario.traffic_sign import TrafficSignIDCountries
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_conversion import utils as conversion_utils
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_parser.parser import parse_opendrive
    from unittest import mock  # here: it imports asyncio, which no run without crdesigner needs

    config = OpenDriveConfig()
    config.proj_string_odr = None
    config.filter_types = [*config.filter_types, *CONVERTED_LANE_TYPES]
    network = network_module.Network(config)
    sources: dict[int, tuple[tuple[str, int, int], ...]] = {}
    to_base = network_module.convert_to_base_lanelet_network

    def recording_to_base(conversion_network: Any) -> Any:
        for lanelet in conversion_network.lanelets:
            group = getattr(lanelet, "parametric_lane_group", None)
            ids = [] if group is None else [lane.id_ for lane in group.parametric_lanes]
            sources[int(lanelet.lanelet_id)] = tuple(dict.fromkeys(_opendrive_lane(i) for i in ids))
        return to_base(conversion_network)

    with (
        _ONE_AT_A_TIME,
        mock.patch.object(ConversionLaneletNetwork, "join_and_split_possible_lanes", _keep_borders),
        mock.patch.object(ConversionLaneletNetwork, "adj_right_consistent_nb", _right_consistent),
        mock.patch.object(network_module, "convert_to_base_lanelet_network", recording_to_base),
        mock.patch.object(ParamPoly3, "calc_position", _param_poly3_by_arc_length(ParamPoly3.calc_position)),
        mock.patch.object(Poly3, "calc_position", _poly3_by_arc_length(Poly3.calc_position)),
        mock.patch.object(conversion_utils, "get_signal_country",
                          _known_country(conversion_utils.get_signal_country, TrafficSignIDCountries)),
    ):
        opendrive = parse_opendrive(Path(os.fspath(path)), config)
        network.load_opendrive(opendrive)
        return network.export_commonroad_scenario(GeneralConfig(), config), sources, opendrive


def _opendrive_lane(parametric_lane_id: str) -> tuple[str, int, int]:
    """(road id, section index, lane id) of crdesigner's "road.section.lane.width.mark" id."""
    road, section, lane = parametric_lane_id.split(".")[:3]
    return road, int(section), int(lane)


def _adjacent_consistent(network: Any, lanelet: Any, side: str) -> bool:
    """crdesigner's ``adj_<side>_consistent_nb``: the ``side`` neighbour of the lanelet's
    successor is the successor (same direction) or predecessor (opposite direction) of
    the lanelet's ``side`` neighbour, and that relation is one-to-one."""
    successor = network.find_lanelet_by_id(lanelet.successor[0])
    neighbour = network.find_lanelet_by_id(getattr(lanelet, f"adj_{side}"))
    if not neighbour:
        return getattr(successor, f"adj_{side}") is None
    same = getattr(lanelet, f"adj_{side}_same_direction")
    if not network.has_unique_pred_succ_relation(1 if same else -1, neighbour):
        return False
    follower = neighbour.successor[0] if same else neighbour.predecessor[0]
    return follower == getattr(successor, f"adj_{side}")


def _right_consistent(network: Any, lanelet: Any) -> bool:
    """``adj_right_consistent_nb`` without crdesigner 0.8.5's AttributeError."""
    return _adjacent_consistent(network, lanelet, "right")


def _keep_borders(network: object) -> None:
    """Replaces crdesigner's join/split border mirroring: borders stay as in OpenDRIVE."""
