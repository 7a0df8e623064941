"""CommonRoad lanelets → a standard Lanelet2 OSM document in the inertial frame.

Built here rather than by crdesigner's CR2LaneletConverter, which (0.8.5) shares the
first/last nodes of a lanelet with its CommonRoad predecessor/successor without checking
the distance (Town01: lanelets whose first point jumps 224 m) and shares adjacent ways on
``max(signed difference) < tol``. Here points closer than ``MERGE_TOLERANCE_M`` are
merged (so consecutive and adjacent lanelets share points and ways, which Lanelet2
routing needs), and no point moves farther than that, except where linked lane ends
are joined across a small gap (``converters.joins``: snapped to shared nodes within
``JOIN_TOLERANCE_M``). A border shorter than that merge (the inner border of a lane
turning about its own edge) keeps its last point as a node of its own. Each way is then
thinned (Douglas-Peucker, ``SIMPLIFY_TOLERANCE_M``): Town04 drops from 135 k to 69 k points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt
from lxml import etree

from converters import frame
from converters.crdesigner_bridge import NDArrayFloat, SourceLanelet
from converters.errors import ConversionError
from converters.joins import join_ends, successor_gaps
from gt_matching.polyline import simplify

NDArrayInt = npt.NDArray[np.int64]

MERGE_TOLERANCE_M: Final[float] = 1e-3
"""Points of different borders closer than this (m) become one OSM node."""

SIMPLIFY_TOLERANCE_M: Final[float] = 1e-4
"""Way vertices whose removal moves the polyline by at most this (m) are dropped
(Douglas-Peucker); crdesigner's fixed 0.5 m sampling is mostly redundant on straights."""

_SUBTYPES: Final[tuple[tuple[str, str], ...]] = (
    ("sidewalk", "walkway"),
    ("crosswalk", "crosswalk"),
    ("bicycleLane", "bicycle_lane"),
    ("busLane", "bus_lane"),
    ("border", "emergency_lane"),
    ("shoulder", "emergency_lane"),
    ("restricted", "emergency_lane"),
    ("highway", "highway"),
    ("interstate", "highway"),
)
"""CommonRoad lanelet type → Lanelet2 subtype, most specific first; default "road"."""

_MARKINGS: Final[dict[str, dict[str, str]]] = {
    "dashed": {"type": "line_thin", "subtype": "dashed"},
    "dashed_dashed": {"type": "line_thin", "subtype": "dashed"},
    "broad_dashed": {"type": "line_thick", "subtype": "dashed"},
    "solid": {"type": "line_thin", "subtype": "solid"},
    "broad_solid": {"type": "line_thick", "subtype": "solid"},
    "solid_solid": {"type": "line_thin", "subtype": "solid_solid"},
    "solid_dashed": {"type": "line_thin", "subtype": "solid_solid"},
    "dashed_solid": {"type": "line_thin", "subtype": "solid_solid"},
    "curb": {"type": "curbstone", "subtype": "high"},
    "lowered_curb": {"type": "curbstone", "subtype": "low"},
    "no_marking": {"type": "virtual"},
}
"""CommonRoad line marking → Lanelet2 way tags (lane changes follow from these under
lanelet2's traffic rules). Mixed solid/dashed become solid_solid: CommonRoad does not
say which side is which. "unknown" gets no tags (no lane change)."""

TYPES_TAG: Final[str] = "commonroad:types"
"""Lanelet tag listing the CommonRoad lanelet types (comma-separated, sorted)."""

OPENDRIVE_TAG: Final[str] = "opendrive:lanes"
"""Lanelet tag listing the OpenDRIVE lanes it covers: "road:section:lane" joined by ";"."""


def opendrive_lanes_tag(lanes: Sequence[tuple[str, int, int]]) -> str:
    """The ``OPENDRIVE_TAG`` value of these (road id, section index, lane id)."""
    return ";".join(f"{road}:{section}:{lane}" for road, section, lane in lanes)


def parse_opendrive_lanes_tag(value: str) -> tuple[tuple[str, int, int], ...]:
    """Inverse of ``opendrive_lanes_tag`` (road ids may contain ":"; the last two fields are ints)."""
    lanes = []
    for item in filter(None, value.split(";")):
        road, section, lane = item.rsplit(":", 2)
        lanes.append((road, int(section), int(lane)))
    return tuple(lanes)


def lanelet_attributes(lanelet: SourceLanelet) -> dict[str, str]:
    """Lanelet2 tags of a lanelet: type, subtype and location from its CommonRoad types,
    the types themselves and the OpenDRIVE lanes it covers (when known)."""
    subtype = next((l2 for cr, l2 in _SUBTYPES if cr in lanelet.types), "road")
    urban = "urban" in lanelet.types or "intersection" in lanelet.types
    tags = {
        "type": "lanelet",
        "subtype": subtype,
        "location": "urban" if urban else "nonurban",
        "one_way": "yes",
        TYPES_TAG: ",".join(sorted(lanelet.types)),
    }
    if lanelet.opendrive_lanes:
        tags[OPENDRIVE_TAG] = opendrive_lanes_tag(lanelet.opendrive_lanes)
    return tags


def merge_points(points: NDArrayFloat, tolerance: float) -> NDArrayInt:
    """Index of each point's representative: the first earlier-or-same point within
    ``tolerance`` (m) that represents itself. Every point is within ``tolerance`` of
    its representative."""
    from scipy.spatial import cKDTree

    neighbours = cKDTree(points).query_ball_point(points, r=tolerance)
    representative = np.full(len(points), -1, dtype=np.int64)
    for index, near in enumerate(neighbours):
        if representative[index] >= 0:
            continue
        representative[index] = index
        for other in near:
            if representative[other] < 0:
                representative[other] = index
    return representative


def left_on_left(lanelet: SourceLanelet) -> SourceLanelet:
    """``lanelet`` with its borders swapped when its left border lies on the driver's
    right. crdesigner 0.8.5 does that for every lane of an LHT road (it reverses the
    vertex order for the driving direction but keeps inner as left); Lanelet2's loader
    would then invert both borders and flip the driving direction."""
    if len(lanelet.left) != len(lanelet.right) or len(lanelet.left) < 2:
        return lanelet
    centre = 0.5 * (lanelet.left + lanelet.right)
    tangent = np.gradient(centre, axis=0)
    across = lanelet.left - lanelet.right
    leftness = np.sum(tangent[:, 0] * across[:, 1] - tangent[:, 1] * across[:, 0])
    if leftness >= 0.0:
        return lanelet
    return replace(
        lanelet,
        left=lanelet.right,
        right=lanelet.left,
        left_marking=lanelet.right_marking,
        right_marking=lanelet.left_marking,
    )


def _without_repeats(ids: NDArrayInt) -> tuple[int, ...]:
    keep = np.ones(len(ids), dtype=bool)
    keep[1:] = ids[1:] != ids[:-1]
    return tuple(int(i) for i in ids[keep])


def _joined_ends(lanelets: Sequence[SourceLanelet], starts: NDArrayInt) -> list[tuple[int, int]]:
    """(border end, successor's border start) point pairs, as indices into the stacked
    borders (left of lanelet i at 2i, right at 2i + 1), of the successor relations joined
    across a gap (``converters.joins.successor_gaps``)."""
    slot = {lanelet.id: index for index, lanelet in enumerate(lanelets)}
    pairs = []
    for gap in successor_gaps(lanelets, MERGE_TOLERANCE_M):
        if gap.joined:
            before, after = slot[gap.lanelet], slot[gap.successor]
            for side in (0, 1):
                pairs.append((int(starts[2 * before + side + 1]) - 1, int(starts[2 * after + side])))
    return pairs


def _keep_short_borders(representative: NDArrayInt, starts: NDArrayInt) -> NDArrayInt:
    """``representative`` with the last point of each border that the merge reduced to a
    single node made a node of its own, so every border keeps two nodes."""
    kept = representative.copy()
    for first, end in zip(starts[:-1], starts[1:]):
        if end - first >= 2 and np.all(representative[first:end] == representative[first]):
            kept[end - 1] = end - 1
    return kept


def build_osm(lanelets: Sequence[SourceLanelet], *, geo_reference: str = "", source: str = "") -> bytes:
    """The OSM document (UTF-8 bytes) of ``lanelets``, in our frame convention.

    Raises ConversionError naming ``source`` when a lanelet has a border with fewer
    than two distinct points, or when nothing is left to write.
    """
    lanelets = [left_on_left(lanelet) for lanelet in lanelets]
    borders = [border for lanelet in lanelets for border in (lanelet.left, lanelet.right)]
    if not borders:
        raise ConversionError(source, "no lanelets to write")
    stacked = np.vstack(borders)
    starts = np.cumsum([0] + [len(border) for border in borders])
    representative, positions = join_ends(stacked, merge_points(stacked, MERGE_TOLERANCE_M),
                                          _joined_ends(lanelets, starts))
    representative = _keep_short_borders(representative, starts)
    unique, point_index = np.unique(representative, return_inverse=True)
    coordinates = positions[unique]
    ways: dict[tuple[int, ...], int] = {}
    way_points: list[NDArrayInt] = []
    way_tags: list[dict[str, str]] = []
    members: list[tuple[int, int]] = []
    for index, lanelet in enumerate(lanelets):
        pair = []
        for side, position, marking in (
            ("left", 2 * index, lanelet.left_marking),
            ("right", 2 * index + 1, lanelet.right_marking),
        ):
            points = _without_repeats(point_index[starts[position] : starts[position + 1]])
            if len(points) < 2:
                raise ConversionError(source, f"lanelet {lanelet.id}: {side} border shorter than {MERGE_TOLERANCE_M} m")
            way = ways.get(points, ways.get(points[::-1]))
            if way is None:
                way = ways[points] = len(way_points)
                chain = np.asarray(points)
                way_points.append(chain[simplify(coordinates[chain], SIMPLIFY_TOLERANCE_M)])
                way_tags.append({})
            if not way_tags[way]:
                way_tags[way] = _MARKINGS.get(marking, {})
            pair.append(way)
        members.append((pair[0], pair[1]))
    used = np.unique(np.concatenate(way_points))
    first_id = max(lanelet.id for lanelet in lanelets) + 1
    node_id = np.full(len(coordinates), -1, dtype=np.int64)
    node_id[used] = first_id + np.arange(len(used))
    way_id_base = first_id + len(used)

    root = etree.Element("osm", version="0.6", generator=frame.GENERATOR)
    root.append(etree.Comment(_recipe_comment(geo_reference)))
    projector = frame.projector()
    from lanelet2.core import BasicPoint3d

    for point in used:
        gps = projector.reverse(BasicPoint3d(float(coordinates[point, 0]), float(coordinates[point, 1]), 0.0))
        etree.SubElement(root, "node", id=str(node_id[point]), lat=repr(gps.lat), lon=repr(gps.lon))
    for way, chain in enumerate(way_points):
        element = etree.SubElement(root, "way", id=str(way_id_base + way))
        for point in chain:
            etree.SubElement(element, "nd", ref=str(node_id[point]))
        for key, value in way_tags[way].items():
            etree.SubElement(element, "tag", k=key, v=value)
    for lanelet, (left, right) in zip(lanelets, members):
        element = etree.SubElement(root, "relation", id=str(lanelet.id))
        etree.SubElement(element, "member", type="way", role="left", ref=str(way_id_base + left))
        etree.SubElement(element, "member", type="way", role="right", ref=str(way_id_base + right))
        for key, value in lanelet_attributes(lanelet).items():
            etree.SubElement(element, "tag", k=key, v=value)
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def _recipe_comment(geo_reference: str) -> str:
    text = (
        f" Written by {frame.GENERATOR}: x, y are the OpenDRIVE inertial frame. Load with "
        f"lanelet2.io.load(path, lanelet2.projection.{frame.PROJECTOR_CLASS}(lanelet2.io.Origin("
        f"{frame.ORIGIN_LAT_DEG!r}, {frame.ORIGIN_LON_DEG!r}))); lat/lon are not geographic. "
        f"Source geoReference (not applied): {geo_reference or '(none)'} "
    )
    return text.replace("--", "- -")


def read_generator(path: Path) -> str:
    """The ``generator`` attribute of an OSM file's root ("" when absent).

    Raises ConversionError naming ``path`` for an unreadable file or non-OSM root.
    """
    try:
        for _, element in etree.iterparse(str(path), events=("start",), resolve_entities=False, no_network=True):
            if element.tag != "osm":
                raise ConversionError(str(path), f"root element is <{element.tag}>, not <osm>")
            return str(element.get("generator", ""))
    except OSError as exc:
        raise ConversionError(str(path), f"cannot read the OSM file: {exc}") from exc
    except etree.XMLSyntaxError as exc:
        raise ConversionError(str(path), f"not well-formed XML: {exc}") from exc
    raise ConversionError(str(path), "empty OSM file")
