"""converters: OpenDRIVE → Lanelet2 in the exact inertial frame, the cache, errors, CLI.

Synthetic maps: a straight road and an arc (radius 80 m) with lanes 1, -1 (3.5 m) and -2
(3.0 m); their borders are known in closed form, so every Lanelet2 vertex is checked
against the analytic border it must lie on, and every lanelet's driving direction and
left/right sides against RHT/LHT.
"""

from __future__ import annotations

import math
import os
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from conftest import bundled_map
from hypothesis import given, settings
from hypothesis import strategies as st

import converters
from converters import api, frame
from converters.cache import atomic_write, cache_path, cache_root
from converters.crdesigner_bridge import SourceLanelet, crdesigner_version, read_geo_reference
from converters.osm import (
    MERGE_TOLERANCE_M,
    OPENDRIVE_TAG,
    float_texts,
    left_on_left,
    lefts_on_left,
    merge_points,
    opendrive_lanes_tag,
    parse_opendrive_lanes_tag,
)
from gt_matching.polyline import simplify

HEADING = 0.3
LENGTH = 60.0
RADIUS = 80.0
ARC_OFFSET = (200.0, 10.0)
LANE_T = {1: (0.0, 3.5), -1: (0.0, -3.5), -2: (-3.5, -6.5)}
"""lane id → (t of inner border, t of outer border), m."""


def synthetic_xodr(geo_reference: str = "", rule: str = "RHT", x0: float = 0.0, y0: float = 0.0) -> str:
    """Road 1: a line from (x0, y0); road 2: an arc from (x0, y0) + ARC_OFFSET; both with
    heading HEADING and length LENGTH, lanes of LANE_T."""
    geo = f"<geoReference><![CDATA[{geo_reference}]]></geoReference>" if geo_reference else ""
    rule_attr = f' rule="{rule}"' if rule != "RHT" else ""
    lanes = (
        '<lanes><laneSection s="0">'
        '<left><lane id="1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></left>'
        '<center><lane id="0" type="driving" level="false"><link/></lane></center>'
        '<right><lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>'
        '<lane id="-2" type="driving" level="false"><link/><width sOffset="0" a="3.0" b="0" c="0" d="0"/></lane></right>'
        "</laneSection></lanes>"
    )

    def road(road_id: int, geometry: str, x: float, y: float) -> str:
        return (
            f'<road name="r{road_id}" length="{LENGTH!r}" id="{road_id}" junction="-1"{rule_attr}><link/>'
            f'<planView><geometry s="0" x="{x!r}" y="{y!r}" hdg="{HEADING!r}" length="{LENGTH!r}">{geometry}</geometry>'
            f"</planView><elevationProfile/><lateralProfile/>{lanes}</road>"
        )

    arc = f'<arc curvature="{1.0 / RADIUS!r}"/>'
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n<OpenDRIVE><header revMajor="1" revMinor="4" name="synthetic">'
        f"{geo}</header>{road(1, '<line/>', x0, y0)}{road(2, arc, x0 + ARC_OFFSET[0], y0 + ARC_OFFSET[1])}"
        "</OpenDRIVE>\n"
    )


def road_coordinates(road: int, points: np.ndarray, x0: float, y0: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form (s, t) of inertial points on road 1 (line) or road 2 (arc)."""
    if road == 1:
        rel = points - (x0, y0)
        return rel @ (math.cos(HEADING), math.sin(HEADING)), rel @ (-math.sin(HEADING), math.cos(HEADING))
    start = np.array([x0 + ARC_OFFSET[0], y0 + ARC_OFFSET[1]])
    centre = start + RADIUS * np.array([-math.sin(HEADING), math.cos(HEADING)])
    rel = points - centre
    angle = np.arctan2(rel[:, 1], rel[:, 0]) - math.atan2(*(start - centre)[::-1])
    return RADIUS * np.mod(angle + math.pi, 2 * math.pi) - RADIUS * math.pi, RADIUS - np.hypot(rel[:, 0], rel[:, 1])


@dataclass(frozen=True)
class Variant:
    name: str
    geo_reference: str
    rule: str
    x0: float
    y0: float


VARIANTS = (
    Variant("no-georef", "", "RHT", 12.5, -7.25),
    Variant(
        "tmerc-false-easting",
        "+proj=tmerc +lat_0=48 +lon_0=11 +k=0.9996 +x_0=500000 +y_0=200000 +ellps=WGS84 +units=m +no_defs",
        "RHT",
        512345.678,
        234567.891,
    ),
    Variant("utm-1e6", "+proj=utm +zone=32 +datum=WGS84 +units=m +no_defs", "RHT", 987654.321, 5334567.891),
    Variant("lht", "", "LHT", -40.0, 25.0),
)


@pytest.fixture(scope="session")
def synthetic_maps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Variant, object]]:
    """Each variant converted once (no cache)."""
    folder = tmp_path_factory.mktemp("synthetic")
    result = {}
    for variant in VARIANTS:
        path = folder / f"{variant.name}.xodr"
        path.write_text(synthetic_xodr(variant.geo_reference, variant.rule, variant.x0, variant.y0))
        lanelet_map, _ = converters.load_lanelet2(path, cache=False)
        result[variant.name] = (variant, lanelet_map)
    return result


def xy(line: object) -> np.ndarray:
    return np.array([(p.x, p.y) for p in line])


@pytest.mark.parametrize("name", [v.name for v in VARIANTS])
def test_synthetic_borders_on_analytic_borders_in_driving_direction(synthetic_maps, name: str) -> None:
    variant, lanelet_map = synthetic_maps[name]
    errors, seen = [], set()
    for lanelet in lanelet_map.laneletLayer:
        left, right = xy(lanelet.leftBound), xy(lanelet.rightBound)
        road = 1 if np.mean(left[:, 0]) - variant.x0 < 0.5 * ARC_OFFSET[0] else 2
        s_left, t_left = road_coordinates(road, left, variant.x0, variant.y0)
        _, t_right = road_coordinates(road, right, variant.x0, variant.y0)
        centre_t = 0.5 * (np.mean(t_left) + np.mean(t_right))
        lane = next(i for i, (a, b) in LANE_T.items() if min(a, b) < centre_t < max(a, b))
        seen.add((road, lane))
        assert dict(lanelet.attributes)[OPENDRIVE_TAG] == f"{road}:0:{lane}"
        along_s = (lane < 0) == (variant.rule == "RHT")
        assert (s_left[-1] > s_left[0]) == along_s, f"{name}: road {road} lane {lane} runs the wrong way"
        assert s_left.min() > -1e-6 and s_left.max() < LENGTH + 1e-6
        inner, outer = LANE_T[lane]
        left_t, right_t = (inner, outer) if variant.rule == "RHT" else (outer, inner)
        errors.extend(np.abs(t_left - left_t))
        errors.extend(np.abs(t_right - right_t))
    assert seen == {(road, lane) for road in (1, 2) for lane in LANE_T}
    errors = np.asarray(errors)
    assert np.median(errors) <= 1e-3
    assert np.percentile(errors, 95) <= 5e-3
    assert errors.max() <= MERGE_TOLERANCE_M + 1e-6


def test_plain_lanelet2_with_the_recipe_lands_in_the_same_frame(tmp_path: Path, synthetic_maps) -> None:
    import lanelet2.io
    import lanelet2.projection

    variant, converted = synthetic_maps["utm-1e6"]
    xodr = tmp_path / "utm.xodr"
    xodr.write_text(synthetic_xodr(variant.geo_reference, variant.rule, variant.x0, variant.y0))
    recipe = converters.convert(xodr, tmp_path / "utm.osm", cache=False)
    assert recipe.geo_reference == variant.geo_reference and recipe.lanelets == 6
    projector = getattr(lanelet2.projection, recipe.projector)(
        lanelet2.io.Origin(recipe.origin_lat_deg, recipe.origin_lon_deg)
    )
    plain = lanelet2.io.load(recipe.osm_path, projector)
    for lanelet in plain.laneletLayer:
        expected = converted.laneletLayer[lanelet.id]
        assert np.abs(xy(lanelet.leftBound) - xy(expected.leftBound)).max() < 1e-9
    # lanelet2.io.load(path, Origin(0, 0)) defaults to the same spherical Mercator; the
    # UTM projector at that origin would put the map ~100 km away.
    default = lanelet2.io.load(recipe.osm_path, lanelet2.io.Origin(0.0, 0.0))
    utm = lanelet2.io.load(recipe.osm_path, lanelet2.projection.UtmProjector(lanelet2.io.Origin(0.0, 0.0)))
    for other, low, high in ((default, 0.0, 1e-9), (utm, 1e4, np.inf)):
        lanelet = next(iter(other.laneletLayer))
        offset = np.abs(xy(lanelet.leftBound) - xy(converted.laneletLayer[lanelet.id].leftBound)).max()
        assert low <= offset <= high
    program, flag, code = shlex.split(recipe.python_snippet())
    assert (program, flag) == ("python", "-c")
    shell = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert shell.returncode == 0, shell.stderr
    assert shell.stdout.strip() == "6 lanelets"


def test_routing_follows_the_arc_after_the_line(tmp_path: Path) -> None:
    """Two roads joined end to start (line, then arc): the routing graph connects them."""
    text = synthetic_xodr()
    end = (LENGTH * math.cos(HEADING), LENGTH * math.sin(HEADING))
    text = text.replace(f'x="{ARC_OFFSET[0]!r}" y="{ARC_OFFSET[1]!r}"', f'x="{end[0]!r}" y="{end[1]!r}"')
    text = text.replace('id="1" junction="-1"><link/>', 'id="1" junction="-1"><link><successor elementType="road" elementId="2" contactPoint="start"/></link>')
    text = text.replace('id="2" junction="-1"><link/>', 'id="2" junction="-1"><link><predecessor elementType="road" elementId="1" contactPoint="end"/></link>')
    path = tmp_path / "joined.xodr"
    path.write_text(text)
    lanelet_map, graph = converters.load_lanelet2(path, cache=False)
    starts = {lanelet.id: xy(lanelet.leftBound)[0] for lanelet in lanelet_map.laneletLayer}
    first = next(lanelet for lanelet in lanelet_map.laneletLayer if np.linalg.norm(starts[lanelet.id]) < 1e-6)
    following = graph.following(first)
    assert len(following) == 1
    assert np.linalg.norm(xy(following[0].leftBound)[0] - end) < 1e-6


# --- point merging and orientation -----------------------------------------------------

@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), min_size=1, max_size=60), st.floats(1e-4, 0.5))
def test_merge_points_moves_no_point_farther_than_the_tolerance(points, tolerance) -> None:
    array = np.array(points, dtype=np.float64)
    representative = merge_points(array, tolerance)
    assert np.all(representative[representative] == representative)
    assert np.all(np.linalg.norm(array - array[representative], axis=1) <= tolerance)
    alone = np.array([np.sum(np.linalg.norm(array - p, axis=1) <= tolerance) == 1 for p in array])
    assert np.all(representative[alone] == np.flatnonzero(alone))


@given(st.lists(st.tuples(st.sampled_from([0.0, -0.0, 1.5, -2.25, 1e-300, math.nan]),
                          st.sampled_from([0.0, -0.0, 3.0, 7.5])), min_size=1, max_size=60), st.booleans())
def test_merge_points_without_tolerance_gives_each_point_the_first_equal_one(points, collide) -> None:
    """Also when every point's hash is the same (the exact sort then decides); NaN equals nothing."""
    array = np.array(points, dtype=np.float64)
    first_equal = [next((j for j, q in enumerate(points) if q[0] == p[0] and q[1] == p[1]), i)
                   for i, p in enumerate(points)]
    hashing = (lambda values: values & np.uint64(0)) if collide else converters.osm._mixed
    with mock.patch.object(converters.osm, "_mixed", hashing):
        assert merge_points(array, 0.0).tolist() == first_equal


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=40), st.floats(1e-4, 1.0))
def test_simplify_keeps_the_ends_and_every_dropped_vertex_within_tolerance(points, tolerance) -> None:
    from gt_matching.polyline import closest_distances

    array = np.array(points, dtype=np.float64)
    keep = simplify(array, tolerance)
    assert keep[0] and keep[-1]
    kept = array[keep]
    if len(kept) >= 2 and (~keep).any():
        assert closest_distances(array[~keep], kept)[0].max() <= tolerance + 1e-9


def test_simplify_drops_collinear_vertices_and_keeps_corners() -> None:
    line = np.column_stack((np.linspace(0.0, 10.0, 21), np.zeros(21)))
    corner = np.vstack((line, [[10.0, 5.0]]))
    assert simplify(line, 1e-6).tolist() == [True] + [False] * 19 + [True]
    assert np.flatnonzero(simplify(corner, 1e-6)).tolist() == [0, 20, 21]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), max_size=50))
def test_float_texts_read_back_as_the_same_floats_with_repr_s_digits(values) -> None:
    _assert_shortest_round_trip(np.array(values, dtype=np.float64))


def _assert_shortest_round_trip(values: np.ndarray) -> None:
    """Each text reads back bit for bit and has ``repr``'s significant digits (the shortest)."""
    def digits(text: str) -> str:
        return text.lower().lstrip("-").partition("e")[0].replace(".", "").strip("0")

    texts = [text.decode("ascii") for text in float_texts(values)]
    assert len(texts) == len(values)
    for value, text in zip(values.tolist(), texts):
        assert np.float64(text).view(np.int64) == np.float64(value).view(np.int64) or (value != value and text == "nan")
        assert digits(text) == digits(repr(value))


def test_node_heights_are_written_as_four_decimals_each_bit_pattern_its_own() -> None:
    from converters.osm import _heights_text

    heights = np.array([0.0, -0.0, 1.23455, 1.23465, -2.5, 0.0, np.nan])
    assert _heights_text(heights) == [b"%.4f" % h for h in heights.tolist()]
    assert _heights_text(heights)[:2] == [b"0.0000", b"-0.0000"]
    assert _heights_text(np.full(3, -0.0)) == [b"-0.0000"] * 3


def test_float_texts_in_every_decade_and_at_the_notation_changes() -> None:
    rng = np.random.default_rng(0)
    decades = rng.uniform(1.0, 10.0, 20_000) * 10.0 ** rng.integers(-40, 25, 20_000)
    edges = np.array([1e-4, 1e-5, 1e15, 1e16, 5e-324, 1.7976931348623157e308, 0.0, -0.0, 1.0, 100.0])
    with np.errstate(over="ignore"):  # the largest float's next is inf
        edges = np.concatenate([edges, np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf)])
    bits = rng.integers(0, 2**63, 20_000, dtype=np.int64).view(np.float64)
    for values in (decades, -decades, edges, bits, rng.uniform(-0.02, 0.02, 20_000)):
        _assert_shortest_round_trip(values)


@given(st.lists(st.tuples(st.text(min_size=1).filter(lambda t: ";" not in t), st.integers(0, 99), st.integers(-9, 9))))
def test_opendrive_lanes_tag_round_trips(lanes) -> None:
    assert parse_opendrive_lanes_tag(opendrive_lanes_tag(lanes)) == tuple(lanes)


def test_left_on_left_swaps_only_lanelets_whose_left_border_is_on_the_right() -> None:
    s = np.linspace(0.0, 10.0, 11)
    centre = np.column_stack((s, 0.1 * s**2))
    normal = np.column_stack((-0.2 * s, np.ones_like(s))) / np.hypot(0.2 * s, 1.0)[:, None]
    good = SourceLanelet(7, centre + 1.5 * normal, centre - 1.5 * normal, frozenset({"urban"}))
    assert left_on_left(good) is good
    swapped = left_on_left(SourceLanelet(7, good.right, good.left, good.types))
    assert np.array_equal(swapped.left, good.left) and np.array_equal(swapped.right, good.right)


def test_lefts_on_left_judges_each_lanelet_by_its_own_gradient_sum() -> None:
    rng = np.random.default_rng(5)
    lanelets = [SourceLanelet(i, rng.normal(size=(n, 2)), rng.normal(size=(m, 2)), frozenset())
                for i, (n, m) in enumerate([(2, 2), (3, 3), (7, 7), (130, 130), (5, 4), (1, 1)] * 20)]

    def leftness(lanelet: SourceLanelet) -> float:
        tangent = np.gradient(0.5 * (lanelet.left + lanelet.right), axis=0)
        across = lanelet.left - lanelet.right
        return np.sum(tangent[:, 0] * across[:, 1] - tangent[:, 1] * across[:, 0])

    judged = [len(lanelet.left) == len(lanelet.right) >= 2 for lanelet in lanelets]
    swapped = [judge and leftness(lanelet) < 0.0 for judge, lanelet in zip(judged, lanelets)]
    assert 0 < sum(swapped) < sum(judged)
    for lanelet, result, swap in zip(lanelets, lefts_on_left(lanelets), swapped):
        assert (result is not lanelet) == swap
        assert result.left is (lanelet.right if swap else lanelet.left)


def test_a_border_merged_into_one_node_keeps_its_last_point_as_its_own() -> None:
    from converters.osm import _keep_short_borders

    rng = np.random.default_rng(6)
    for _ in range(500):
        starts = np.cumsum(np.concatenate(([0], rng.integers(0, 5, rng.integers(0, 8)))))
        representative = rng.integers(0, 3, starts[-1])
        kept = _keep_short_borders(representative, starts)
        for first, end in zip(starts[:-1].tolist(), starts[1:].tolist()):
            if end > first:
                single = end - first >= 2 and len(set(representative[first:end].tolist())) == 1
                assert kept[first:end - 1].tolist() == representative[first:end - 1].tolist()
                assert kept[end - 1] == (end - 1 if single else representative[end - 1])


# --- cache -----------------------------------------------------------------------------

@pytest.fixture()
def straight_map(tmp_path: Path) -> Path:
    path = tmp_path / "straight.xodr"
    path.write_text(synthetic_xodr())
    return path


def _forbid_conversion(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the converter was called")

    monkeypatch.setattr(api, "odr_to_lanelets", refuse)


def test_cache_hit_returns_the_same_map_without_converting(straight_map, tmp_path, monkeypatch) -> None:
    cache = tmp_path / "cache"
    first, _ = converters.load_lanelet2(straight_map, cache_dir=cache)
    key = cache_path(straight_map.read_bytes(), crdesigner_version(), cache)
    assert key.is_file() and key.parent == cache
    _forbid_conversion(monkeypatch)
    second, _ = converters.load_lanelet2(straight_map, cache_dir=cache)
    assert sorted(ll.id for ll in first.laneletLayer) == sorted(ll.id for ll in second.laneletLayer)
    for lanelet in first.laneletLayer:
        assert np.array_equal(xy(lanelet.rightBound), xy(second.laneletLayer[lanelet.id].rightBound))
    with pytest.raises(AssertionError, match="converter was called"):
        converters.load_lanelet2(straight_map, cache=False)
    straight_map.write_text(synthetic_xodr(x0=1.0))
    with pytest.raises(AssertionError, match="converter was called"):
        converters.load_lanelet2(straight_map, cache_dir=cache)


def test_stray_temporary_file_is_ignored_and_cleared(straight_map, tmp_path) -> None:
    cache = tmp_path / "cache"
    key = cache_path(straight_map.read_bytes(), crdesigner_version(), cache)
    cache.mkdir()
    stray = cache / f".{key.name}.abandoned.tmp"
    stray.write_bytes(b"<osm half-written")
    lanelet_map, _ = converters.load_lanelet2(straight_map, cache_dir=cache)
    assert len(lanelet_map.laneletLayer) == 6 and key.is_file() and stray.is_file()
    (cache / "unrelated.txt").write_text("keep")
    assert converters.clear_cache(cache) == 2
    assert sorted(p.name for p in cache.iterdir()) == ["unrelated.txt"]


def test_damaged_cache_entry_is_converted_again(straight_map, tmp_path) -> None:
    cache = tmp_path / "cache"
    key = cache_path(straight_map.read_bytes(), crdesigner_version(), cache)
    cache.mkdir()
    key.write_bytes(b'<osm version="0.6" generator="cold-maps-converters/4"><node id="1" lat=')
    lanelet_map, _ = converters.load_lanelet2(straight_map, cache_dir=cache)
    assert len(lanelet_map.laneletLayer) == 6
    assert key.read_bytes().count(b"<relation ") == 6


def test_failed_write_leaves_neither_target_nor_temporary(tmp_path, monkeypatch) -> None:
    target = tmp_path / "out" / "map.osm"

    def broken_replace(source: str, destination: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(converters.ConversionError, match="map.osm: cannot write: No space left"):
        atomic_write(target, b"data", create_folder=True)
    assert list(target.parent.iterdir()) == []


def test_cache_folder_precedence(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("COLD_MAPS_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "cold-maps"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cache_root() == Path.home() / ".cache" / "cold-maps"
    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "env"))
    assert cache_root() == tmp_path / "env"
    assert cache_root(tmp_path / "arg") == tmp_path / "arg"
    name = cache_path(b"abc", "9.9", tmp_path).name
    assert name.startswith("ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad")
    assert "crdesigner9.9" in name and f"format{frame.FORMAT_VERSION}" in name


def test_geo_reference_read_from_the_header_alone_is_the_whole_file_s(tmp_path) -> None:
    header = "<header><geoReference><![CDATA[ +proj=utm  +zone=32 ]]></geoReference></header>"
    whole = tmp_path / "whole.xodr"
    whole.write_text(f"<OpenDRIVE>{header}<road/></OpenDRIVE>")
    cut = tmp_path / "cut.xodr"
    cut.write_text(f"<OpenDRIVE>{header}<road")
    assert read_geo_reference(whole) == read_geo_reference(whole, header_only=True) == "+proj=utm +zone=32"
    assert read_geo_reference(cut, header_only=True) == "+proj=utm +zone=32"  # what follows the header is not read
    with pytest.raises(converters.ConversionError, match="not well-formed XML"):
        read_geo_reference(cut)
    for content, message in (("<OpenDRIVE><header", "not well-formed XML"), ("<osm/>", "root element is <osm>"),
                             ('<!DOCTYPE x [<!ENTITY a "b">]><OpenDRIVE/>', "DOCTYPE is not allowed")):
        whole.write_text(content)
        with pytest.raises(converters.ConversionError, match=message):
            read_geo_reference(whole, header_only=True)
    whole.write_text("<OpenDRIVE><road/></OpenDRIVE>")
    assert read_geo_reference(whole, header_only=True) == ""


# --- errors and CLI --------------------------------------------------------------------

@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "cannot read the map"),
        ("<OpenDRIVE><header", "not well-formed XML"),
        ('<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "b">]><OpenDRIVE/>', "DOCTYPE is not allowed"),
        (f"<!--{'x' * 5000}--><!DOCTYPE x [<!ENTITY a \"b\">]><OpenDRIVE a='&a;'/>", "DOCTYPE is not allowed"),
        ("<osm/>", "root element is <osm>, not <OpenDRIVE>"),
        ('<OpenDRIVE><header revMajor="1" revMinor="4"/></OpenDRIVE>', "no lanelets"),
        (synthetic_xodr().replace(' length="60.0">', ">", 1), "converter crashed"),
    ],
)
def test_bad_maps_raise_conversion_error_naming_the_file(tmp_path, content, message) -> None:
    path = tmp_path / "bad.xodr"
    if content is not None:
        path.write_text(content)
    with pytest.raises(converters.ConversionError, match=message) as info:
        converters.load_lanelet2(path, cache=False)
    assert str(path) in str(info.value)


def test_foreign_osm_and_unknown_suffix_are_refused(tmp_path) -> None:
    foreign = tmp_path / "foreign.osm"
    foreign.write_text('<osm version="0.6" generator="JOSM"/>')
    with pytest.raises(converters.ConversionError, match="'JOSM'.*frame unknown"):
        converters.load_lanelet2(foreign)
    with pytest.raises(converters.ConversionError, match="unknown map type '.txt'"):
        converters.load_lanelet2(tmp_path / "map.txt")


@pytest.mark.parametrize("converter", ["engine", "crdesigner"])
def test_cli_convert_reports_one_line_and_loads_back(straight_map, tmp_path, capsys, converter) -> None:
    from cold_maps.cli.maps import main

    out = tmp_path / "straight.osm"
    assert main(["convert", str(straight_map), "-o", str(out), "--no-cache", "--converter", converter]) == 0
    assert capsys.readouterr().out == (f"cold-maps convert: 6 lanelets in the OpenDRIVE inertial frame -> {out} "
                                       f"(converter {converter})\n")
    lanelet_map, _ = converters.load_lanelet2(out)
    assert len(lanelet_map.laneletLayer) == 6
    assert main(["convert", str(straight_map), "-o", str(out), "-v", "--converter", converter]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].endswith(f"6 lanelets in the OpenDRIVE inertial frame -> {out} (converter {converter})")
    assert f"wrote {out}: 6 lanelets" in printed[1] and any("MercatorProjector" in line for line in printed)
    assert main(["convert", str(straight_map), "-o", str(out), "-q"]) == 0
    assert capsys.readouterr().out == ""
    assert main(["convert", str(tmp_path / "missing.xodr"), "-o", str(out), "--no-cache"]) == 1
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("cold-maps: error: ") and "missing.xodr: cannot read file" in error


def test_importing_converters_does_not_import_crdesigner_or_lanelet2() -> None:
    code = "import sys, converters; print(any(m.split('.')[0] in ('crdesigner', 'lanelet2') for m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.stdout.strip() == "False", result.stderr


# --- cross-check against our own sampling (cold_maps.groundtruth.check) ---------------------------

@pytest.fixture(scope="session")
def town01_checked(town01_path: Path, tmp_path_factory: pytest.TempPathFactory):
    """Town01 converted once (its CommonRoad lanelets kept, the OSM stored in a session
    cache), the cross-check report and the loaded map from that cache."""
    from cold_maps.groundtruth.check import check_map
    from converters.crdesigner_bridge import odr_to_lanelets
    from converters.osm import build_osm

    cache = tmp_path_factory.mktemp("cache")
    lanelets, geo_reference = odr_to_lanelets(town01_path)
    target = cache_path(town01_path.read_bytes(), crdesigner_version(), cache)
    atomic_write(target, build_osm(lanelets, geo_reference=geo_reference, source=str(town01_path)))
    report = check_map(town01_path, cache_dir=cache, converter="crdesigner")
    lanelet_map, graph = converters.load_lanelet2(town01_path, cache_dir=cache)
    return report, lanelet_map, graph, lanelets


def test_town01_lanelet2_borders_are_the_commonroad_vertices(town01_checked) -> None:
    """Every CommonRoad vertex lies on its lanelet's border within the merge + thinning
    tolerances, and every non-sidewalk lanelet keeps its driving direction."""
    from converters.osm import SIMPLIFY_TOLERANCE_M
    from gt_matching.polyline import closest_distances

    _, lanelet_map, _, lanelets = town01_checked
    worst = 0.0
    for source in lanelets:
        lanelet = lanelet_map.laneletLayer[source.id]
        for vertices, border in ((source.left, lanelet.leftBound), (source.right, lanelet.rightBound)):
            converted = xy(border)
            worst = max(worst, float(closest_distances(vertices, converted)[0].max()))
            if "sidewalk" not in source.types:
                assert np.linalg.norm(converted[0] - vertices[0]) <= MERGE_TOLERANCE_M
    assert worst <= MERGE_TOLERANCE_M + SIMPLIFY_TOLERANCE_M


def test_town01_ground_truth_agrees_with_our_sampling(town01_checked) -> None:
    from cold_maps.groundtruth.check import format_report

    report, lanelet_map, _, _ = town01_checked
    assert report.lanes and report.trustworthy and report.exit_code == 0
    assert {lane.matched_by for lane in report.lanes} == {"id"}
    medians = np.array([lane.median_m for lane in report.lanes])
    assert np.all(medians <= 5e-3) and np.median(medians) <= 1e-3
    assert "TRUSTWORTHY" in format_report(report) and "NOT" not in format_report(report)
    assert report.lanelets == len(lanelet_map.laneletLayer)


def test_town01_routes_between_any_two_road_lanelets(town01_checked) -> None:
    _, lanelet_map, graph, _ = town01_checked
    roads = sorted((ll for ll in lanelet_map.laneletLayer if ll.attributes["subtype"] == "road"), key=lambda ll: ll.id)
    assert all(graph.following(ll) and graph.previous(ll) for ll in roads)
    rng = np.random.default_rng(7)
    for a, b in rng.choice(len(roads), size=(15, 2), replace=True):
        assert graph.getRoute(roads[a], roads[b]) is not None, (roads[a].id, roads[b].id)


def _parsed(text: str):
    from cold_maps.opendrive.parser import parse_opendrive

    return parse_opendrive(text.encode(), path="synthetic.xodr")


@pytest.mark.parametrize("name", ["no-georef", "lht"])
def test_check_passes_on_a_faithful_conversion(synthetic_maps, name: str) -> None:
    from cold_maps.groundtruth.check import check_lanelet_map

    variant, lanelet_map = synthetic_maps[name]
    odr = _parsed(synthetic_xodr(variant.geo_reference, variant.rule, variant.x0, variant.y0))
    report = check_lanelet_map(odr, lanelet_map)
    assert len(report.lanes) == 6 and report.trustworthy
    chord_sagitta = 0.5**2 / (8 * (RADIUS - 3.5))  # crdesigner samples every <= 0.5 m
    assert max(lane.max_m for lane in report.lanes) <= chord_sagitta + MERGE_TOLERANCE_M
    assert len({lane.lanelet_id for lane in report.lanes}) == 6


def test_check_measures_a_known_lateral_shift_and_lists_every_lane(synthetic_maps) -> None:
    from cold_maps.groundtruth.check import check_lanelet_map, format_report

    variant, lanelet_map = synthetic_maps["no-georef"]
    shift = 0.08
    x0 = variant.x0 - shift * math.sin(HEADING)
    y0 = variant.y0 + shift * math.cos(HEADING)
    report = check_lanelet_map(_parsed(synthetic_xodr("", "RHT", x0, y0)), lanelet_map, path="shifted.xodr")
    assert not report.trustworthy and report.exit_code == 3 and len(report.failing) == 6
    for lane in report.lanes:
        if lane.road_id == "1":
            assert lane.median_m == pytest.approx(shift, abs=1e-6) and lane.max_m == pytest.approx(shift, abs=1e-6)
        else:
            assert shift * math.cos(LENGTH / RADIUS) - 1e-3 <= lane.median_m <= shift + 1e-3
    text = format_report(report)
    assert "NOT TRUSTWORTHY (6 of 6 lanes" in text
    assert any(line.split()[:3] == ["1", "0", "-2"] and line.split()[4:6] == ["id", "80.00"] for line in text.splitlines())


def _renumbered(text: str) -> str:
    """The synthetic map with roads 1, 2 renamed 31, 32 (ids no lanelet tag names)."""
    return text.replace('id="1" junction', 'id="31" junction').replace('id="2" junction', 'id="32" junction')


def test_check_matches_by_opendrive_id_else_by_geometry(synthetic_maps) -> None:
    from cold_maps.groundtruth.check import check_lanelet_map, format_report

    _, lanelet_map = synthetic_maps["no-georef"]
    variant = synthetic_maps["no-georef"][0]
    text = synthetic_xodr("", "RHT", variant.x0, variant.y0)
    by_id = check_lanelet_map(_parsed(text), lanelet_map)
    by_geometry = check_lanelet_map(_parsed(_renumbered(text)), lanelet_map)
    assert {lane.matched_by for lane in by_id.lanes} == {"id"}
    assert {lane.matched_by for lane in by_geometry.lanes} == {"geometry"}
    assert by_geometry.trustworthy
    assert [lane.lanelet_id for lane in by_id.lanes] == [lane.lanelet_id for lane in by_geometry.lanes]
    assert "by OpenDRIVE id: 0, by geometry: 6, unmatched: 0" in format_report(by_geometry)


def test_check_reports_lanes_without_any_lanelet(synthetic_maps) -> None:
    from cold_maps.groundtruth.check import check_lanelet_map, format_report

    _, lanelet_map = synthetic_maps["no-georef"]
    far = _renumbered(synthetic_xodr("", "RHT", 5000.0, 5000.0))
    report = check_lanelet_map(_parsed(far), lanelet_map)
    assert all(lane.lanelet_id is None and lane.matched_by == "" and lane.max_m == math.inf for lane in report.lanes)
    assert report.exit_code == 3 and "none" in format_report(report).splitlines()[-1]
    with pytest.raises(ValueError, match="threshold"):
        check_lanelet_map(_parsed(synthetic_xodr()), lanelet_map, threshold_m=float("nan"))


def test_check_subcommand_exit_codes(straight_map, tmp_path, monkeypatch, capsys) -> None:
    from cold_maps.cli.maps import main

    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "cache"))
    assert main(["check", "--no-progress", str(straight_map), "--converter", "crdesigner"]) == 0
    assert "ground truth: TRUSTWORTHY (0 of 6 lanes" in capsys.readouterr().out
    assert main(["check", "--no-progress", str(straight_map), "--threshold", "1e-6", "--converter", "crdesigner"]) == 3
    assert "NOT TRUSTWORTHY" in capsys.readouterr().out


@pytest.mark.parametrize(("road_mark", "subtype", "lane_change"), [("broken", "dashed", True), ("solid", "solid", False)])
def test_road_marks_become_way_tags_that_govern_lane_changes(tmp_path, road_mark, subtype, lane_change) -> None:
    """Lane -1's roadMark is on its outer border, the one it shares with lane -2."""
    width = '<lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/>'
    mark = f'<roadMark sOffset="0" type="{road_mark}" weight="standard" color="standard" width="0.12"/>'
    path = tmp_path / "marked.xodr"
    path.write_text(synthetic_xodr().replace(width, width + mark))
    lanelet_map, graph = converters.load_lanelet2(path, cache=False)
    shared = [ll for ll in lanelet_map.laneletLayer if dict(ll.rightBound.attributes).get("subtype") == subtype]
    assert len(shared) == 2  # lane -1 of both roads
    for lanelet in shared:
        assert lanelet.rightBound.attributes["type"] == "line_thin"
        neighbour = graph.right(lanelet)
        assert (neighbour is not None) == lane_change
        if lane_change:
            assert neighbour.leftBound.id == lanelet.rightBound.id


def test_crdesigner_warnings_are_silenced_unless_verbose(tmp_path) -> None:
    import logging
    import warnings

    path = tmp_path / "geoid.xodr"
    path.write_text(synthetic_xodr("+proj=tmerc +lat_0=0 +lon_0=0 +geoidgrids=egm96_15.gtx +units=m"))
    before = logging.root.manager.disable
    for verbose, expected in ((False, 0), (True, 1)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            converters.load_lanelet2(path, cache=False, verbose=verbose)
        assert min(sum("geoidgrids" in str(w.message) for w in caught), 1) == expected
        assert logging.root.manager.disable == before


def test_opening_lane_keeps_its_opendrive_borders(tmp_path) -> None:
    """Lane -2 opens from 0 to 3 m (smooth cubic); crdesigner would move its borders
    ("mirroring" a split), the converter keeps them where OpenDRIVE puts them."""
    c, d = 9.0 / LENGTH**2, -6.0 / LENGTH**3  # w(s) = 3·(3(s/L)² − 2(s/L)³)
    text = synthetic_xodr().replace(
        '<lane id="-2" type="driving" level="false"><link/><width sOffset="0" a="3.0" b="0" c="0" d="0"/>',
        f'<lane id="-2" type="driving" level="false"><link/><width sOffset="0" a="0" b="0" c="{c!r}" d="{d!r}"/>',
    )
    path = tmp_path / "opening.xodr"
    path.write_text(text)
    lanelet_map, _ = converters.load_lanelet2(path, cache=False)
    checked = 0
    for lanelet in lanelet_map.laneletLayer:
        left, right = xy(lanelet.leftBound), xy(lanelet.rightBound)
        if np.mean(left[:, 0]) > 0.5 * ARC_OFFSET[0]:
            continue
        _, t_left = road_coordinates(1, left, 0.0, 0.0)
        s_right, t_right = road_coordinates(1, right, 0.0, 0.0)
        if np.mean(t_right) > -3.5 - 1e-6 or np.mean(t_left) > -1.0:
            continue  # not lane -2
        width = c * s_right**2 + d * s_right**3
        assert np.abs(t_left + 3.5).max() <= MERGE_TOLERANCE_M
        assert np.abs(t_right + 3.5 + width).max() <= MERGE_TOLERANCE_M
        checked += 1
    assert checked == 1


def test_bundled_highway_ground_truth_is_trustworthy() -> None:
    from cold_maps.groundtruth.check import check_map

    report = check_map(bundled_map("highway"), cache=False, converter="crdesigner")
    assert report.trustworthy and len(report.lanes) >= 20
    assert max(lane.max_m for lane in report.lanes) <= 2 * MERGE_TOLERANCE_M


def test_convert_output_gets_the_ordinary_file_mode_and_needs_its_folder(straight_map, tmp_path) -> None:
    """``convert -o`` writes 0666 less the umask (not a temporary file's 0600) and refuses a
    missing folder instead of creating it."""
    import os

    out = tmp_path / "map.osm"
    converters.convert(straight_map, out, cache_dir=tmp_path / "cache")
    mask = os.umask(0)
    os.umask(mask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~mask
    with pytest.raises(converters.ConversionError, match="missing"):
        converters.convert(straight_map, tmp_path / "missing" / "map.osm", cache_dir=tmp_path / "cache")
    assert not (tmp_path / "missing").exists()
