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

Tags follow the Lanelet2 tagging specification: every node carries ``ele`` (m, from the
OpenDRIVE elevation profile, ``converters.elevation``) when the lanelets know their
heights; walkways and crosswalks are two-way (``one_way=no``), other lanelets one-way;
``location`` is ``urban`` on every lanelet of an OpenDRIVE road or junction that
crdesigner marks urban anywhere (sidewalks and shoulders included), else ``nonurban``; a border without a
known marking is ``type=virtual`` with ``lane_change=no`` (no lane change, as before).
Two tags outside the specification, both namespaced: ``commonroad:types`` (the
CommonRoad lanelet types, ``TYPES_TAG``) and ``opendrive:lanes`` (the OpenDRIVE lanes a
lanelet covers, ``OPENDRIVE_TAG``). Regulatory elements: ``converters.regulatory``.
"""

from __future__ import annotations

import itertools
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
from converters.joins import JOIN_TOLERANCE_M, gap_kinds, join_ends, successor_distances
from converters.regulatory import LaneletExit, append_regulatory_elements
from gt_matching.polyline import arc_lengths, simplify

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
    "unknown": {"type": "virtual", "lane_change": "no"},
}
"""CommonRoad line marking → Lanelet2 way tags (lane changes follow from these under
lanelet2's traffic rules). Mixed solid/dashed become solid_solid: CommonRoad does not
say which side is which. "unknown" is virtual without lane change (every way needs a type)."""

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


_TWO_WAY_SUBTYPES: Final[frozenset[str]] = frozenset({"walkway", "crosswalk"})
"""Lanelet2 subtypes walked in both directions (``one_way=no``)."""


def is_urban(lanelet: SourceLanelet) -> bool:
    """True when crdesigner marks the lanelet urban (or as part of an intersection)."""
    return "urban" in lanelet.types or "intersection" in lanelet.types


def _places(lanelet: SourceLanelet) -> set[str]:
    """Keys of the OpenDRIVE roads and junctions a lanelet lies on."""
    return {f"road {road}" for road, _, _ in lanelet.opendrive_lanes} | {f"junction {j}" for j in lanelet.junctions}


def urban_places(lanelets: Sequence[SourceLanelet]) -> frozenset[str]:
    """Roads and junctions (``_places`` keys) with an urban lanelet: every lanelet on them is urban."""
    return frozenset(place for lanelet in lanelets if is_urban(lanelet) for place in _places(lanelet))


def lanelet_attributes(lanelet: SourceLanelet, urban: frozenset[str] = frozenset()) -> dict[str, str]:
    """Lanelet2 tags of a lanelet: type, subtype and one_way from its CommonRoad types,
    location (urban when it is, or lies on a road or junction of ``urban_places``), the
    types themselves and the OpenDRIVE lanes it covers (when known)."""
    subtype = next((l2 for cr, l2 in _SUBTYPES if cr in lanelet.types), "road")
    in_town = is_urban(lanelet) or not _places(lanelet).isdisjoint(urban)
    tags = {
        "type": "lanelet",
        "subtype": subtype,
        "location": "urban" if in_town else "nonurban",
        "one_way": "no" if subtype in _TWO_WAY_SUBTYPES else "yes",
        TYPES_TAG: ",".join(sorted(lanelet.types)),
    }
    if lanelet.opendrive_lanes:
        tags[OPENDRIVE_TAG] = opendrive_lanes_tag(lanelet.opendrive_lanes)
    return tags


def merge_points(points: NDArrayFloat, tolerance: float) -> NDArrayInt:
    """Index of each point's representative: the first earlier-or-same point within
    ``tolerance`` (m) that represents itself. Every point is within ``tolerance`` of
    its representative; with ``tolerance`` 0 only equal points share one."""
    if tolerance == 0.0:
        hashed = _first_equal_by_hash(points)
        if hashed is not None:
            return hashed
        # equal rows are neighbours in lexicographic order (stable: the first comes first)
        order = np.argsort(np.ascontiguousarray(points, dtype=np.float64).view(np.complex128)[:, 0], kind="stable")
        ordered = points[order]
        starts = np.ones(len(points), dtype=bool)
        starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
        representative = np.empty(len(points), dtype=np.int64)
        representative[order] = order[np.flatnonzero(starts)[np.cumsum(starts) - 1]]
        return representative
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


def _first_equal_by_hash(points: NDArrayFloat) -> NDArrayInt | None:
    """``merge_points(points, 0.0)`` from a 64-bit hash of each point (-0.0 as 0.0): only
    the points whose hash another shares are compared (most points of a map are unique,
    and sorting hashes is cheaper than sorting points); None when two different points
    share a hash or a NaN point does."""
    xy = np.ascontiguousarray(points, dtype=np.float64) + 0.0
    bits = xy.view(np.uint64)
    key = _mixed(_mixed(bits[:, 0]) ^ bits[:, 1])
    ordered = np.sort(key)
    shared = np.unique(ordered[1:][ordered[1:] == ordered[:-1]])
    representative = np.arange(len(points), dtype=np.int64)
    if not len(shared):
        return representative
    slot = np.minimum(np.searchsorted(shared, key), len(shared) - 1)
    members = np.flatnonzero(shared[slot] == key)
    members = members[np.argsort(slot[members], kind="stable")]  # by hash, each hash's points in index order
    group = slot[members]
    first = np.ones(len(members), dtype=bool)
    first[1:] = group[1:] != group[:-1]
    leader = members[first][np.cumsum(first) - 1]
    if not (xy[members] == xy[leader]).all():
        return None
    representative[members] = leader
    return representative


def _mixed(values: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """splitmix64's finaliser of each value (a bijection that spreads every input bit)."""
    values = (values ^ (values >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    values = (values ^ (values >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return values ^ (values >> np.uint64(31))


def left_on_left(lanelet: SourceLanelet) -> SourceLanelet:
    """``lanelet`` with its borders swapped when its left border lies on the driver's
    right. crdesigner 0.8.5 does that for every lane of an LHT road (it reverses the
    vertex order for the driving direction but keeps inner as left); Lanelet2's loader
    would then invert both borders and flip the driving direction."""
    return lefts_on_left([lanelet])[0]


def lefts_on_left(lanelets: Sequence[SourceLanelet]) -> list[SourceLanelet]:
    """``left_on_left`` of each lanelet: the sum over its vertices of the mid-line's
    tangent (``np.gradient``) crossed with the left-minus-right offset, negative on the
    right; the products of all lanelets in one pass, each lanelet's sum as ``np.sum`` of
    its own (only lanelets whose borders have the same two or more vertices are judged)."""
    judged = [index for index, lanelet in enumerate(lanelets) if len(lanelet.left) == len(lanelet.right) >= 2]
    result = list(lanelets)
    if not judged:
        return result
    left = np.concatenate([lanelets[index].left for index in judged])
    right = np.concatenate([lanelets[index].right for index in judged])
    ends = np.cumsum([len(lanelets[index].left) for index in judged])
    begins = np.concatenate(([0], ends[:-1]))
    centre = 0.5 * (left + right)
    tangent = np.empty_like(centre)  # np.gradient along each lanelet (unit spacing, first-order ends)
    tangent[1:-1] = (centre[2:] - centre[:-2]) / 2.0
    tangent[begins] = centre[begins + 1] - centre[begins]
    tangent[ends - 1] = centre[ends - 1] - centre[ends - 2]
    across = left - right
    products = tangent[:, 0] * across[:, 1] - tangent[:, 1] * across[:, 0]
    for index, first, end in zip(judged, begins.tolist(), ends.tolist()):
        if not np.sum(products[first:end]) >= 0.0:  # a NaN sum swaps too
            lanelet = lanelets[index]
            result[index] = replace(
                lanelet,
                left=lanelet.right,
                right=lanelet.left,
                left_marking=lanelet.right_marking,
                right_marking=lanelet.left_marking,
                left_tags=lanelet.right_tags,
                right_tags=lanelet.left_tags,
                left_z=lanelet.right_z,
                right_z=lanelet.left_z,
            )
    return result


def _without_repeats(ids: NDArrayInt, starts: NDArrayInt) -> tuple[NDArrayInt, list[int]]:
    """``ids`` of the borders that begin at ``starts`` (the last: the end) without a
    border's repeats of its previous id, and where each border begins in the result."""
    keep = np.ones(len(ids), dtype=bool)
    keep[1:] = ids[1:] != ids[:-1]
    keep[starts[:-1][starts[:-1] < len(ids)]] = True
    kept_before = np.concatenate(([0], np.cumsum(keep)))
    return ids[keep], kept_before[starts].tolist()


def _dense(values: NDArrayInt) -> tuple[NDArrayInt, NDArrayInt]:
    """``np.unique(values, return_inverse=True)`` of non-negative integers below ``len``-ish
    bounds, by counting (no sort)."""
    present = np.zeros(int(values.max(initial=-1)) + 1, dtype=bool)
    present[values] = True
    return np.flatnonzero(present), (np.cumsum(present) - 1)[values]


def _joined_ends(
    lanelets: Sequence[SourceLanelet], starts: NDArrayInt, merge_tolerance_m: float, join_tolerance_m: float
) -> list[tuple[int, int]]:
    """(border end, successor's border start) point pairs, as indices into the stacked
    borders (left of lanelet i at 2i, right at 2i + 1), of the successor relations joined
    across a gap (``converters.joins.successor_gaps``' joined ones)."""
    before, after, _, _, largest = successor_distances(lanelets)
    _, joined = gap_kinds(largest, merge_tolerance_m, join_tolerance_m)
    sides = np.arange(2)
    ends = starts[2 * before[joined, None] + sides + 1] - 1  # (relation, left/right)
    begins = starts[2 * after[joined, None] + sides]
    return list(zip(ends.ravel().tolist(), begins.ravel().tolist()))


def _keep_short_borders(representative: NDArrayInt, starts: NDArrayInt) -> NDArrayInt:
    """``representative`` with the last point of each border that the merge reduced to a
    single node made a node of its own, so every border keeps two nodes."""
    kept = representative.copy()
    if not len(representative):
        return kept
    sizes = np.diff(starts)
    filled = sizes > 0
    firsts = starts[:-1][filled]  # a border's span in reduceat runs to the next non-empty border
    single = np.minimum.reduceat(representative, firsts) == np.maximum.reduceat(representative, firsts)
    ends = starts[1:][filled][single & (sizes[filled] >= 2)]
    kept[ends - 1] = ends - 1
    return kept


def build_osm(
    lanelets: Sequence[SourceLanelet],
    *,
    geo_reference: str = "",
    source: str = "",
    merge_tolerance_m: float = MERGE_TOLERANCE_M,
    join_tolerance_m: float = JOIN_TOLERANCE_M,
    simplify_tolerance_m: float | None = SIMPLIFY_TOLERANCE_M,
) -> bytes:
    """The OSM document (UTF-8 bytes) of ``lanelets``, in our frame convention.

    Points of different borders closer than ``merge_tolerance_m`` (m) become one node;
    successor ends both within ``join_tolerance_m`` (m, may be inf) of each other are
    snapped together (``converters.joins``); each way is thinned by Douglas-Peucker within
    ``simplify_tolerance_m`` (m; None: every vertex kept, for borders sampled to a
    tolerance already, except where a join moved a way's end). Raises ConversionError naming ``source``
    when a lanelet has a border with fewer than two distinct points, or when nothing is
    left to write.
    """
    lanelets = lefts_on_left(lanelets)
    borders = [border for lanelet in lanelets for border in (lanelet.left, lanelet.right)]
    if not borders:
        raise ConversionError(source, "no lanelets to write")
    stacked = np.vstack(borders)
    heights = np.concatenate([_heights(lanelet, side) for lanelet in lanelets for side in ("left", "right")])
    starts = np.cumsum([0] + [len(border) for border in borders])
    representative, positions = join_ends(stacked, merge_points(stacked, merge_tolerance_m),
                                          _joined_ends(lanelets, starts, merge_tolerance_m, join_tolerance_m))
    representative = _keep_short_borders(representative, starts)
    unique, point_index = _dense(representative)
    coordinates = np.column_stack((positions[unique], heights[unique]))
    kept_ids, kept_starts = _without_repeats(point_index, starts)
    last_ids = np.append(kept_ids, -1)[np.array(kept_starts[1:]) - 1].tolist()  # each border's last id
    ways: dict[bytes, int] = {}  # a way's point ids (int64 bytes) in its stored order
    way_points: list[NDArrayInt] = []
    way_tags: list[dict[str, str]] = []
    members: list[tuple[int, int]] = []
    exit_points: list[tuple[int, int]] = []
    for index, lanelet in enumerate(lanelets):
        pair = []
        ends = []
        for side, position, tags in (
            ("left", 2 * index, dict(lanelet.left_tags) or _MARKINGS.get(lanelet.left_marking, {})),
            ("right", 2 * index + 1, dict(lanelet.right_tags) or _MARKINGS.get(lanelet.right_marking, {})),
        ):
            first, end = kept_starts[position], kept_starts[position + 1]
            if end - first < 2:
                raise ConversionError(source, f"lanelet {lanelet.id}: {side} border shorter than {merge_tolerance_m} m")
            ends.append(last_ids[position])
            chain = kept_ids[first:end]
            points = chain.tobytes()
            way = ways.get(points)
            if way is None:
                way = ways.get(chain[::-1].tobytes())
            if way is None:
                way = ways[points] = len(way_points)
                kept = chain if simplify_tolerance_m is None else chain[_kept_vertices(coordinates[chain], simplify_tolerance_m)]
                way_points.append(kept)
                way_tags.append({})
            if not way_tags[way]:
                way_tags[way] = tags
            pair.append(way)
        members.append((pair[0], pair[1]))
        exit_points.append((ends[0], ends[1]))
    used = _dense(np.concatenate(way_points))[0]
    first_id = max(lanelet.id for lanelet in lanelets) + 1
    node_id = np.full(len(coordinates), -1, dtype=np.int64)
    node_id[used] = first_id + np.arange(len(used))
    way_id_base = first_id + len(used)

    root = etree.Element("osm", version="0.6", generator=frame.GENERATOR)
    root.append(etree.Comment(_recipe_comment(geo_reference)))
    bulk = [*_nodes_text(node_id[used], coordinates[used]), *_ways_text(way_id_base, node_id, way_points, way_tags)]
    urban = urban_places(lanelets)
    exits = {}
    for lanelet, (left, right), (left_end, right_end) in zip(lanelets, members, exit_points):
        element = etree.SubElement(root, "relation", id=str(lanelet.id))
        etree.SubElement(element, "member", type="way", role="left", ref=str(way_id_base + left))
        etree.SubElement(element, "member", type="way", role="right", ref=str(way_id_base + right))
        for key, value in lanelet_attributes(lanelet, urban).items():
            etree.SubElement(element, "tag", k=key, v=value)
        exits[lanelet.id] = LaneletExit(
            element, int(node_id[left_end]), int(node_id[right_end]), coordinates[left_end], coordinates[right_end]
        )
    fresh = itertools.count(way_id_base + len(way_points))

    def new_node(xyz: NDArrayFloat) -> int:
        identifier = next(fresh)
        (text,) = _nodes_text(np.array([identifier]), np.asarray(xyz, dtype=np.float64)[None, :])
        root.append(etree.fromstring(text, etree.XMLParser(remove_blank_text=True)))
        return identifier

    regulations = {lanelet.id: lanelet.regulations for lanelet in lanelets}
    append_regulatory_elements(root, regulations, exits, new_node, fresh)
    document = etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)
    # The bulk of nodes and ways, written as text in lxml's pretty-printed form (an element
    # per node is slow), goes right after the recipe comment, where the tree would put it.
    after_comment = document.index(b"-->\n") + len(b"-->\n")
    return b"".join([document[:after_comment], *bulk, document[after_comment:]])


def _escape(value: str) -> str:
    """``value`` as the text of a double-quoted XML attribute."""
    return value.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def _ways_text(
    first_id: int, node_id: NDArrayInt, way_points: Sequence[NDArrayInt], way_tags: Sequence[dict[str, str]]
) -> list[bytes]:
    """Ways ``first_id`` on of these points (indices into ``node_id``) and tags,
    pretty-printed at depth 1 (UTF-8)."""
    import orjson

    tags_text: dict[tuple[tuple[str, str], ...], bytes] = {}
    texts = []
    for way, (chain, tags) in enumerate(zip(way_points, way_tags)):
        key = tuple(tags.items())
        if key not in tags_text:
            tags_text[key] = "".join(f'    <tag k="{_escape(k)}" v="{_escape(v)}"/>\n' for k, v in key).encode("utf-8")
        refs = orjson.dumps(node_id[chain], option=orjson.OPT_SERIALIZE_NUMPY)[1:-1]
        texts.append(b'  <way id="%d">\n    <nd ref="%s"/>\n%s  </way>\n'
                     % (first_id + way, refs.replace(b",", b'"/>\n    <nd ref="'), tags_text[key]))
    return texts


def _nodes_text(identifiers: NDArrayInt, xyz: NDArrayFloat) -> list[bytes]:
    """Nodes at ``xyz`` ((N, 3) x, y, z in m; z NaN: no ``ele``), pretty-printed at depth 1
    (ASCII), in pieces of up to ``_NODES_AT_ONCE`` nodes."""
    lat, lon = frame.lat_lon_deg(xyz[:, 0], xyz[:, 1])
    known = np.isfinite(xyz[:, 2])
    parts = []
    for first in range(0, len(xyz), _NODES_AT_ONCE):
        at = slice(first, first + _NODES_AT_ONCE)
        nodes = len(known[at])
        values: list[object] = [None] * (4 * nodes)  # id, lat, lon, height of each node
        values[0::4], values[1::4], values[2::4], values[3::4] = (
            identifiers[at].tolist(), float_texts(lat[at]), float_texts(lon[at]), _heights_text(xyz[at, 2]))
        if known[at].all():
            formats = _NODE_FORMATS[1] * nodes
        else:
            formats = b"".join(map(_NODE_FORMATS.__getitem__, known[at].tolist()))
        parts.append(formats % tuple(values))
    return parts


def _heights_text(z: NDArrayFloat) -> list[bytes]:
    """``b"%.4f" % h`` of each height (m), each distinct value (bit pattern) formatted once."""
    bits = np.ascontiguousarray(z, dtype=np.float64).view(np.int64)
    if len(bits) and (bits == bits[0]).all():
        return [b"%.4f" % z[0]] * len(bits)
    distinct, inverse = np.unique(bits, return_inverse=True)
    return np.array([b"%.4f" % h for h in distinct.view(np.float64).tolist()], dtype=object)[inverse].tolist()


def float_texts(values: NDArrayFloat) -> list[bytes]:
    """The shortest decimal text (ASCII) of each float of ``values`` that reads back as the
    same float (orjson's, the digits ``repr`` has; its notation: "0.0000123", "1.5e-6"),
    ``repr`` for values not finite."""
    import orjson

    values = np.ascontiguousarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    if not values.size:
        return []
    if finite.all():
        return orjson.dumps(values, option=orjson.OPT_SERIALIZE_NUMPY)[1:-1].split(b",")
    texts = np.array([repr(value).encode("ascii") for value in values.tolist()], dtype=object)
    texts[finite] = float_texts(values[finite])
    return texts.tolist()


_NODES_AT_ONCE: Final[int] = 65536
"""Nodes ``_nodes_text`` formats in one ``%`` (bounds the argument tuple)."""


_NODE_FORMATS: Final[tuple[bytes, bytes]] = (
    b'  <node id="%d" lat="%s" lon="%s"/>\n%.0s',  # no height: the height is formatted as nothing
    b'  <node id="%d" lat="%s" lon="%s">\n    <tag k="ele" v="%s"/>\n  </node>\n',
)
"""An OSM node without and with its ``ele`` tag, pretty-printed at depth 1 (``%`` fields)."""


def _kept_vertices(points: NDArrayFloat, tolerance_m: float) -> npt.NDArray[np.bool_]:
    """Douglas-Peucker (``tolerance_m``) of an (N, 3) way, in plan and in its height
    profile over plan length (a crest on a straight road keeps its vertices)."""
    keep = simplify(points[:, :2], tolerance_m)
    heights = points[:, 2]
    if np.all(np.isfinite(heights)):
        along = arc_lengths(points[:, :2])
        keep |= simplify(np.column_stack((along, heights)), tolerance_m)
    return keep


def _heights(lanelet: SourceLanelet, side: str) -> NDArrayFloat:
    """Heights (m) of one border's vertices; NaN (no ``ele``) when unknown."""
    border = lanelet.left if side == "left" else lanelet.right
    z = lanelet.left_z if side == "left" else lanelet.right_z
    return np.full(len(border), np.nan) if z is None else np.asarray(z, dtype=np.float64)


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
