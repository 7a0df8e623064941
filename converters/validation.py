"""The checks of ``lanelet2_validation`` that apply to a converted map, in Python.

The lanelet2 wheel (1.2.3) has no ``lanelet2.validation`` module, so the checks are
re-implemented here from lanelet2_validation's ``mapping.*`` validators
(``validators/mapping/*.cpp``: the same known tags, known values, mandatory tags and
boolean tags), and the ``routing_graph.*`` checks are ``RoutingGraph.checkValidity`` of
the German vehicle rules. Parser errors (``lanelet2.io.loadRobust``) and routing-graph
errors are errors; tag findings are warnings, as in lanelet2_validation. A tag is known
when it starts with a known tag (``lane_change:left`` is known), as there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

from converters import frame

Severity = Literal["error", "warning"]

_LINE_TYPES: Final[frozenset[str]] = frozenset({
    "arrow", "bike_marking", "bump", "curbstone", "door", "fence", "gate", "guard_rail", "jersey_barrier",
    "keepout", "lift_gate", "line_thick", "line_thin", "pedestrian_marking", "rail", "road_border", "stop_line",
    "symbol", "traffic_light", "traffic_sign", "trajectory", "virtual", "visualization", "wall", "zebra", "zig-zag",
})  # fmt: skip
_LINE_MARKS: Final[frozenset[str]] = frozenset({"dashed", "dashed_solid", "solid", "solid_dashed", "solid_solid"})
_LINE_SUBTYPES: Final[dict[str, frozenset[str]]] = {
    "line_thick": _LINE_MARKS,
    "line_thin": _LINE_MARKS,
    "curbstone": frozenset({"high", "low"}),
    "arrow": frozenset({"left", "left_right", "right", "straight", "straight_left", "straight_right"}),
    "bike_marking": frozenset({"dashed", "solid"}),
    "pedestrian_marking": frozenset({"dashed", "solid"}),
    "stop_line": frozenset({"dashed", "solid"}),
    "bump": frozenset(),
    "traffic_light": frozenset({"red", "red_green", "red_yellow", "red_yellow_green"}),
    "virtual": frozenset(),
}
"""Known subtypes per line type (a type absent here accepts any subtype)."""

KNOWN_TAGS: Final[dict[str, tuple[str, ...]]] = {
    "point": ("ele", "type", "subtype"),
    "linestring": ("type", "subtype", "lane_change", "width", "height", "temporary", "color"),
    "lanelet": ("type", "subtype", "one_way", "name", "region", "speed_limit", "location", "participant"),
    "area": ("type", "subtype", "speed_limit", "location", "region", "name"),
    "regulatory_element": ("dynamic", "fallback", "sign_type", "speed_limit", "subtype", "type"),
}
MANDATORY_TAGS: Final[dict[str, tuple[str, ...]]] = {
    "linestring": ("type",),
    "lanelet": ("type", "subtype", "location"),
    "area": ("type", "subtype", "location"),
    "regulatory_element": ("type", "subtype"),
}
KNOWN_LANELET_VALUES: Final[dict[str, frozenset[str]]] = {
    "type": frozenset({"lanelet"}),
    "subtype": frozenset({
        "bicycle_lane", "bus_lane", "crosswalk", "emergency_lane", "highway", "play_street", "rail", "road",
        "shared_walkway", "stairs", "walkway",
    }),  # fmt: skip
    "location": frozenset({"nonurban", "private", "urban"}),
}
BOOL_TAGS: Final[tuple[str, ...]] = ("one_way", "dynamic", "lane_change", "participant", "fallback", "temporary")
_TRUE_FALSE: Final[frozenset[str]] = frozenset({"yes", "no", "true", "false", "1", "0"})


@dataclass(frozen=True)
class Issue:
    """One finding.

    Fields:
        severity: "error" or "warning".
        primitive: "map", "point", "linestring", "lanelet", "area", "regulatory_element"
            or "routing_graph".
        id: the primitive's id (0 for the map or graph).
        check: the lanelet2_validation check name ("mapping.unknown_tags", ...).
        message: what is wrong.
        tag: the tag concerned ("" when none).
    """

    severity: Severity
    primitive: str
    id: int
    check: str
    message: str
    tag: str = ""

    def __str__(self) -> str:
        return f"{self.severity}: {self.check}: {self.primitive} {self.id}: {self.message}"


def _tag_issues(primitive: str, element_id: int, attributes: dict[str, str]) -> list[Issue]:
    issues = []
    known = KNOWN_TAGS[primitive]
    for key, value in attributes.items():
        if not any(key.startswith(tag) for tag in known):
            message = f"attribute {key} is not a known lanelet2 tag"
            issues.append(Issue("warning", primitive, element_id, "mapping.unknown_tags", message, key))
        if any(key.startswith(tag) for tag in BOOL_TAGS) and value.lower() not in _TRUE_FALSE:
            issues.append(Issue("warning", primitive, element_id, "mapping.bool_tags", f"attribute {key}: {value} is not a bool"))
    for tag in MANDATORY_TAGS.get(primitive, ()):
        if tag not in attributes:
            issues.append(Issue("warning", primitive, element_id, "mapping.mandatory_tags", f"should have a {tag} attribute"))
    issues.extend(_value_issues(primitive, element_id, attributes))
    return issues


def _value_issues(primitive: str, element_id: int, attributes: dict[str, str]) -> list[Issue]:
    unknown = []
    if primitive == "lanelet":
        unknown = [key for key, values in KNOWN_LANELET_VALUES.items() if key in attributes and attributes[key] not in values]
    elif primitive == "linestring":
        kind = attributes.get("type")
        if kind is not None and kind not in _LINE_TYPES:
            unknown.append("type")
        if kind in _LINE_SUBTYPES and "subtype" in attributes and attributes["subtype"] not in _LINE_SUBTYPES[kind]:
            unknown.append("subtype")
    elif primitive == "regulatory_element" and attributes.get("type", "regulatory_element") != "regulatory_element":
        unknown.append("type")
    message = "value {} is not a known value for {}"
    return [
        Issue("warning", primitive, element_id, "mapping.unknown_tag_value", message.format(attributes[key], key))
        for key in unknown
    ]


def outside_namespaces(issues: list[Issue]) -> list[Issue]:
    """The issues other than unknown-tag warnings on namespaced ("prefix:key") tags, the
    documented extensions (``commonroad:types``, ``opendrive:lanes``)."""
    return [issue for issue in issues if not (issue.check == "mapping.unknown_tags" and ":" in issue.tag)]


def _attributes(primitive: Any) -> dict[str, str]:
    return {str(key): str(value) for key, value in primitive.attributes.items()}


def validate_osm(path: str | Path) -> list[Issue]:
    """All findings on an OSM file this converter wrote (loaded in our frame)."""
    import lanelet2.io

    lanelet_map, errors = lanelet2.io.loadRobust(str(path), frame.projector())
    issues = [Issue("error", "map", 0, "io", str(error)) for error in errors]
    layers = (
        ("point", lanelet_map.pointLayer),
        ("linestring", lanelet_map.lineStringLayer),
        ("lanelet", lanelet_map.laneletLayer),
        ("area", lanelet_map.areaLayer),
        ("regulatory_element", lanelet_map.regulatoryElementLayer),
    )
    for primitive, layer in layers:
        for element in layer:
            issues.extend(_tag_issues(primitive, int(element.id), _attributes(element)))
    from converters.lanes import routing_graph

    graph = routing_graph(lanelet_map)
    issues.extend(Issue("error", "routing_graph", 0, "routing_graph.is_valid", str(e)) for e in graph.checkValidity(False))
    return issues
