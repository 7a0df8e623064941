"""The bundled maps (maps/*.xodr) and their generator tools/make_maps.py.

The maps are read here with a small independent lxml reader and evaluated with closed
forms written in this file (line, arc, clothoid via Fresnel integrals about the
zero-curvature point), not with the generator's or the map engine's code.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import PROJECT_ROOT, bundled_map
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree
from scipy.special import fresnel

MAP_NAMES = ("straight", "curve90", "rural", "junction", "highway")
POSITION_TOL_M = 1e-3
BORDER_TOL_M = 1e-2
HEADING_TOL_RAD = 1e-6
LANE_WIDTH_M = 4.0


def _load_generator():
    spec = importlib.util.spec_from_file_location("make_maps", PROJECT_ROOT / "tools" / "make_maps.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_maps"] = module
    spec.loader.exec_module(module)
    return module


make_maps = _load_generator()


# ---- independent reader ---------------------------------------------------------------


@dataclass(frozen=True)
class Geom:
    kind: str
    s: float
    x: float
    y: float
    hdg: float
    length: float
    k0: float
    k1: float


@dataclass(frozen=True)
class LaneRec:
    id: int
    type: str
    widths: tuple[tuple[float, ...], ...]
    pred: tuple[int, ...]
    succ: tuple[int, ...]


@dataclass(frozen=True)
class Section:
    s: float
    lanes: dict[int, LaneRec]


@dataclass(frozen=True)
class RoadRec:
    id: str
    length: float
    junction: str
    pred: tuple[str, str, str | None] | None
    succ: tuple[str, str, str | None] | None
    geoms: tuple[Geom, ...]
    offsets: tuple[tuple[float, ...], ...]
    sections: tuple[Section, ...]

    def link(self, side: str):
        return self.pred if side == "start" else self.succ

    def section_at(self, side: str) -> Section:
        return self.sections[0] if side == "start" else self.sections[-1]

    def s_at(self, side: str) -> float:
        return 0.0 if side == "start" else self.length


@dataclass(frozen=True)
class MapRec:
    path: Path
    root: etree._Element
    roads: dict[str, RoadRec]
    junctions: dict[str, list[tuple[str, str, str, str, tuple[tuple[int, int], ...]]]]


def _poly(element, s_name: str) -> tuple[float, ...]:
    return tuple(float(element.get(k)) for k in (s_name, "a", "b", "c", "d"))


def _road_link(link, tag):
    element = link.find(tag) if link is not None else None
    if element is None:
        return None
    return (element.get("elementType"), element.get("elementId"), element.get("contactPoint"))


def _lane(element) -> LaneRec:
    def ids(tag: str) -> tuple[int, ...]:
        return tuple(int(e.get("id")) for e in element.iterfind(f"link/{tag}"))

    return LaneRec(
        int(element.get("id")), element.get("type"),
        tuple(_poly(w, "sOffset") for w in element.findall("width")), ids("predecessor"), ids("successor"),
    )


def read_map(path: Path) -> MapRec:
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False)
    root = etree.parse(str(path), parser).getroot()
    roads = {}
    for road in root.findall("road"):
        geoms = []
        for g in road.find("planView").findall("geometry"):
            kind_el = g[0]
            k0 = float(kind_el.get("curvature", kind_el.get("curvStart", 0.0)))
            k1 = float(kind_el.get("curvature", kind_el.get("curvEnd", 0.0)))
            geoms.append(Geom(kind_el.tag, *(float(g.get(k)) for k in ("s", "x", "y", "hdg", "length")), k0, k1))
        lanes = road.find("lanes")
        sections = tuple(
            Section(float(sec.get("s")), {int(l.get("id")): _lane(l) for l in sec.iter("lane") if l.get("id") != "0"})
            for sec in lanes.findall("laneSection")
        )
        link = road.find("link")
        roads[road.get("id")] = RoadRec(
            road.get("id"), float(road.get("length")), road.get("junction"),
            _road_link(link, "predecessor"), _road_link(link, "successor"), tuple(geoms),
            tuple(_poly(o, "s") for o in lanes.findall("laneOffset")), sections,
        )
    junctions = {
        j.get("id"): [
            (c.get("id"), c.get("incomingRoad"), c.get("connectingRoad"), c.get("contactPoint"),
             tuple((int(l.get("from")), int(l.get("to"))) for l in c.findall("laneLink")))
            for c in j.findall("connection")
        ]
        for j in root.findall("junction")
    }
    return MapRec(path, root, roads, junctions)


# ---- independent closed forms ---------------------------------------------------------


def geom_pose(g: Geom, ds: float) -> tuple[float, float, float]:
    """Pose at arc length ds along one record."""
    if g.kind == "line":
        return g.x + ds * math.cos(g.hdg), g.y + ds * math.sin(g.hdg), g.hdg
    if g.kind == "arc":
        r = 1.0 / g.k0
        cx, cy = g.x - r * math.sin(g.hdg), g.y + r * math.cos(g.hdg)
        h = g.hdg + g.k0 * ds
        return cx + r * math.sin(h), cy - r * math.cos(h), h
    assert g.kind == "spiral", g.kind
    c = (g.k1 - g.k0) / g.length
    # Standard clothoid κ(σ) = c·σ through the origin with heading 0 at σ = 0.
    a = math.sqrt(math.pi / abs(c))

    def point(sigma: float) -> tuple[float, float]:
        fs, fc = fresnel(sigma / a)
        return a * float(fc), math.copysign(a, c) * float(fs)

    sigma0 = g.k0 / c
    (x0, y0), (x1, y1) = point(sigma0), point(sigma0 + ds)
    theta0 = 0.5 * c * sigma0**2
    rot = g.hdg - theta0
    dx, dy = x1 - x0, y1 - y0
    return (
        g.x + dx * math.cos(rot) - dy * math.sin(rot),
        g.y + dx * math.sin(rot) + dy * math.cos(rot),
        g.hdg + g.k0 * ds + 0.5 * c * ds * ds,
    )


def ref_pose(road: RoadRec, s: float) -> tuple[float, float, float]:
    g = [g for g in road.geoms if g.s <= s + 1e-9][-1]
    return geom_pose(g, min(s - g.s, g.length))


def cubic(records, s: float, start: float = 0.0) -> float:
    active = [r for r in records if r[0] <= s - start + 1e-9]
    if not active:
        return 0.0
    s0, a, b, c, d = active[-1]
    ds = s - start - s0
    return a + b * ds + c * ds**2 + d * ds**3


def lane_width(section: Section, lane_id: int, s: float) -> float:
    return cubic(section.lanes[lane_id].widths, s, section.s)


def lane_borders_t(road: RoadRec, section: Section, lane_id: int, s: float) -> tuple[float, float]:
    """(inner, outer) t of a lane's borders, laneOffset included."""
    sign = 1 if lane_id > 0 else -1
    inner = cubic(road.offsets, s) + sign * sum(lane_width(section, sign * i, s) for i in range(1, abs(lane_id)))
    return inner, inner + sign * lane_width(section, lane_id, s)


def world(road: RoadRec, s: float, t: float) -> np.ndarray:
    x, y, h = ref_pose(road, s)
    return np.array([x - t * math.sin(h), y + t * math.cos(h)])


def angle_diff(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2.0 * math.pi))


def road_links(odr: MapRec):
    """(road, side, link) for every road link."""
    for road in odr.roads.values():
        for side in ("start", "end"):
            if road.link(side) is not None:
                yield road, side, road.link(side)


def lane_link_ids(lane: LaneRec, side: str) -> tuple[int, ...]:
    return lane.pred if side == "start" else lane.succ


def drives_along_s(lane_id: int) -> bool:
    return lane_id < 0


# ---- generator ------------------------------------------------------------------------


@pytest.fixture(scope="session")
def generated_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("generated_maps")
    assert make_maps.main(["--out", str(out)]) == 0
    return out


def test_generator_reproduces_committed_maps_byte_for_byte(generated_dir):
    generated = sorted(p.name for p in generated_dir.iterdir())
    assert generated == sorted(f"{name}.xodr" for name in MAP_NAMES)
    for name in generated:
        committed = bundled_map(Path(name).stem)
        assert (generated_dir / name).read_bytes() == committed.read_bytes(), f"{name} differs: run make maps"


def test_script_check_passes_on_committed_maps():
    result = subprocess.run(
        [sys.executable, str(PROJECT_ROOT / "tools" / "make_maps.py"), "--check"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 0, result.stderr


def test_check_flag_detects_changed_and_missing_files(generated_dir, tmp_path):
    assert make_maps.main(["--check", "--out", str(generated_dir)]) == 0
    changed = tmp_path / "changed"
    shutil.copytree(generated_dir, changed)
    path = changed / "rural.xodr"
    path.write_bytes(path.read_bytes().replace(b'length="150"', b'length="150.0"', 1))
    assert make_maps.main(["--check", "--out", str(changed)]) == 1
    missing = tmp_path / "missing"
    shutil.copytree(generated_dir, missing)
    (missing / "junction.xodr").unlink()
    assert make_maps.main(["--check", "--out", str(missing)]) == 1


def test_unwritable_output_dir_is_one_line_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert make_maps.main(["--out", str(blocker / "maps")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(blocker) in err


@given(st.floats(-1e5, 1e5, allow_nan=False))
def test_fmt_is_positional_and_round_trips(value):
    text = make_maps.fmt(value)
    assert "e" not in text and "E" not in text and text != "-0"
    assert math.isclose(float(text), value, rel_tol=1e-11, abs_tol=1e-300)


def test_bad_segments_raise_naming_the_kind():
    with pytest.raises(ValueError, match="spiral segment"):
        make_maps.spiral(10.0, 0.01, 0.01)
    with pytest.raises(ValueError, match="line segment: length"):
        make_maps.line(float("nan"))
    with pytest.raises(ValueError, match="arc segment"):
        make_maps.arc(5.0, 0.0)
    with pytest.raises(ValueError, match="non-finite"):
        make_maps.fmt(float("inf"))


curvatures = st.floats(-0.1, 0.1, allow_nan=False).filter(lambda k: abs(k) > 1e-4)


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-1e3, 1e3), y=st.floats(-1e3, 1e3), hdg=st.floats(-4.0, 4.0),
    length=st.floats(0.5, 200.0), kind=st.sampled_from(["line", "arc", "spiral"]),
    k0=curvatures, k1=curvatures,
)
def test_generator_end_pose_matches_closed_forms(x, y, hdg, length, kind, k0, k1):
    if kind == "spiral" and abs(k1 - k0) < 1e-4:
        k1 = -k0
    seg = {"line": lambda: make_maps.line(length), "arc": lambda: make_maps.arc(length, k0),
           "spiral": lambda: make_maps.spiral(length, k0, k1)}[kind]()
    end = make_maps.end_pose(make_maps.Pose(x, y, hdg), seg)
    expected = geom_pose(Geom(kind, 0.0, x, y, hdg, length, seg.curv_start, seg.curv_end), length)
    assert math.hypot(end.x - expected[0], end.y - expected[1]) < 1e-6
    assert abs(end.hdg - expected[2]) < 1e-9


# ---- every map ------------------------------------------------------------------------


@pytest.fixture(scope="module", params=MAP_NAMES)
def odr(request) -> MapRec:
    return read_map(bundled_map(request.param))


@pytest.fixture(scope="module")
def maps() -> dict[str, MapRec]:
    return {name: read_map(bundled_map(name)) for name in MAP_NAMES}


def test_header_is_opendrive_1_6_with_fixed_date(odr):
    header = odr.root.find("header")
    assert odr.root.tag == "OpenDRIVE"
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "6")
    assert header.get("date") == "2026-01-01T00:00:00"


def test_ids_unique_and_lane_ids_consecutive(odr):
    road_ids = [r.get("id") for r in odr.root.findall("road")]
    junction_ids = [j.get("id") for j in odr.root.findall("junction")]
    assert len(set(road_ids + junction_ids)) == len(road_ids) + len(junction_ids)
    for connections in odr.junctions.values():
        assert len({c[0] for c in connections}) == len(connections)
    for section in odr.root.iter("laneSection"):
        ids = [int(lane.get("id")) for lane in section.iter("lane")]
        assert len(set(ids)) == len(ids)
        left, right = sorted(i for i in ids if i > 0), sorted((-i for i in ids if i < 0))
        assert 0 in ids and left == list(range(1, len(left) + 1)) and right == list(range(1, len(right) + 1))


def test_plan_view_is_contiguous_within_1_mm(odr):
    for road in odr.roads.values():
        assert road.geoms[0].s == 0.0
        assert math.isclose(sum(g.length for g in road.geoms), road.length, abs_tol=1e-6)
        for prev, nxt in zip(road.geoms, road.geoms[1:]):
            assert math.isclose(prev.s + prev.length, nxt.s, abs_tol=1e-6)
            x, y, h = geom_pose(prev, prev.length)
            assert math.hypot(x - nxt.x, y - nxt.y) <= POSITION_TOL_M, (road.id, nxt.s)
            assert angle_diff(h, nxt.hdg) <= HEADING_TOL_RAD, (road.id, nxt.s)


def test_lanes_are_4_m_wide_except_an_opening_lane(odr):
    for road in odr.roads.values():
        ends = [sec.s for sec in road.sections[1:]] + [road.length]
        for section, s_end in zip(road.sections, ends):
            for lane in section.lanes.values():
                widths = [lane_width(section, lane.id, s) for s in np.linspace(section.s, s_end, 41)]
                assert widths[-1] == pytest.approx(LANE_WIDTH_M, abs=1e-9)
                assert all(-1e-9 <= w <= LANE_WIDTH_M + 1e-9 for w in widths)
                assert np.all(np.diff(widths) >= -1e-9)
                if widths[0] < LANE_WIDTH_M - 1e-9:
                    assert widths[0] == pytest.approx(0.0, abs=1e-9) and not lane.pred


def test_road_links_are_symmetric(odr):
    for road, side, (kind, target, contact) in road_links(odr):
        if kind == "junction":
            assert road.junction == "-1" and contact is None and target in odr.junctions
            continue
        other = odr.roads[target]
        back = other.link(contact)
        if road.junction != "-1" and other.junction == "-1":
            assert back == ("junction", road.junction, None), (road.id, side)
        else:
            assert back == ("road", road.id, side), (road.id, side)


def test_linked_reference_lines_meet_within_1_mm(odr):
    for road, side, (kind, target, contact) in road_links(odr):
        if kind != "road":
            continue
        other = odr.roads[target]
        x0, y0, h0 = ref_pose(road, road.s_at(side))
        x1, y1, h1 = ref_pose(other, other.s_at(contact))
        assert math.hypot(x1 - x0, y1 - y0) <= POSITION_TOL_M, (road.id, side, target)
        expected = h0 if side != contact else h0 + math.pi
        assert angle_diff(h1, expected) <= HEADING_TOL_RAD, (road.id, side, target)


def test_lane_links_between_sections_are_symmetric_and_borders_meet(odr):
    for road in odr.roads.values():
        for before, after in zip(road.sections, road.sections[1:]):
            for lane in after.lanes.values():
                for p in lane.pred:
                    assert lane.id in before.lanes[p].succ
                    for t_before, t_after in zip(lane_borders_t(road, before, p, after.s),
                                                 lane_borders_t(road, after, lane.id, after.s)):
                        assert abs(t_before - t_after) <= BORDER_TOL_M
            for lane in before.lanes.values():
                for q in lane.succ:
                    assert lane.id in after.lanes[q].pred


def test_lane_links_between_roads_are_symmetric_and_borders_meet(odr):
    for road, side, (kind, target, contact) in road_links(odr):
        if kind != "road":
            continue
        other = odr.roads[target]
        for lane in road.section_at(side).lanes.values():
            for linked in lane_link_ids(lane, side):
                other_lane = other.section_at(contact).lanes[linked]
                if other.junction == road.junction:
                    assert lane.id in lane_link_ids(other_lane, contact)
                mine = [world(road, road.s_at(side), t) for t in lane_borders_t(road, road.section_at(side), lane.id, road.s_at(side))]
                theirs = [world(other, other.s_at(contact), t)
                          for t in lane_borders_t(other, other.section_at(contact), linked, other.s_at(contact))]
                for a, b in zip(mine, theirs):
                    assert np.linalg.norm(a - b) <= BORDER_TOL_M, (road.id, lane.id, target, linked)


def test_junction_connections_match_connecting_road_links(odr):
    for junction_id, connections in odr.junctions.items():
        listed = set()
        for _, incoming, connecting, contact, lane_links in connections:
            road = odr.roads[connecting]
            assert road.junction == junction_id
            assert road.link(contact)[:2] == ("road", incoming)
            incoming_side = road.link(contact)[2]
            assert odr.roads[incoming].link(incoming_side) == ("junction", junction_id, None)
            for from_lane, to_lane in lane_links:
                assert from_lane in odr.roads[incoming].section_at(incoming_side).lanes
                assert lane_link_ids(road.section_at(contact).lanes[to_lane], contact) == (from_lane,)
                listed.add((incoming, connecting, contact, from_lane, to_lane))
        # Every lane that enters a connecting road from a linked road is in a laneLink.
        for road in odr.roads.values():
            if road.junction != junction_id:
                continue
            for side in ("start", "end"):
                _, other, _ = road.link(side)
                for lane in road.section_at(side).lanes.values():
                    if drives_along_s(lane.id) == (side == "start"):
                        for linked in lane_link_ids(lane, side):
                            assert (other, road.id, side, linked, lane.id) in listed, (road.id, lane.id)


def test_maps_load_with_the_project_parser(odr):
    if importlib.util.find_spec("cold_maps.opendrive.parser") is None:
        pytest.skip("cold_maps.opendrive.parser not written yet")
    from cold_maps.opendrive.parser import load_opendrive

    model = load_opendrive(odr.path)
    assert (model.header.rev_major, model.header.rev_minor) == (1, 6)
    assert model.header.geo_reference.proj == (odr.root.findtext("header/geoReference") or "").strip()
    assert list(model.roads) == list(odr.roads)
    assert list(model.junctions) == list(odr.junctions)
    for road_id, road in odr.roads.items():
        parsed = model.roads[road_id]
        assert parsed.length == pytest.approx(road.length, abs=1e-9)
        assert [sec.s for sec in parsed.lane_sections] == [sec.s for sec in road.sections]
        for sec, mine in zip(parsed.lane_sections, road.sections):
            assert sorted(lane.id for lane in sec.lanes) == sorted(mine.lanes)
        assert [(g.kind, g.s, g.length) for g in parsed.plan_view] == [(g.kind, g.s, g.length) for g in road.geoms]
        assert parsed.junction == road.junction


def test_map_engine_reference_line_agrees_with_closed_forms(odr):
    if importlib.util.find_spec("cold_maps.opendrive.reference_line") is None:
        pytest.skip("cold_maps.opendrive.reference_line not written yet")
    from cold_maps.opendrive.parser import load_opendrive
    from cold_maps.opendrive.reference_line import reference_pose

    model = load_opendrive(odr.path)
    for road_id, road in odr.roads.items():
        s = np.linspace(0.0, road.length, 23)
        x, y, h = reference_pose(model.roads[road_id], s)
        for i, s_i in enumerate(s):
            ex, ey, eh = ref_pose(road, float(s_i))
            assert math.hypot(x[i] - ex, y[i] - ey) <= POSITION_TOL_M, (road_id, s_i)
            assert angle_diff(h[i], eh) <= 1e-6, (road_id, s_i)


# ---- per-map requirements -------------------------------------------------------------


def lane_ids(road: RoadRec, section: int = 0) -> list[int]:
    return sorted(road.sections[section].lanes)


def driving_only(road: RoadRec) -> bool:
    return all(lane.type == "driving" for sec in road.sections for lane in sec.lanes.values())


def test_straight(maps):
    (road,) = maps["straight"].roads.values()
    assert [g.kind for g in road.geoms] == ["line"] and road.length >= 600.0
    assert lane_ids(road) == [-2, -1, 1, 2] and driving_only(road)
    start, end = world(road, 0.0, 0.0), world(road, road.length, 0.0)
    assert np.linalg.norm(end - start) == pytest.approx(road.length, abs=1e-6)


def test_curve90_is_a_20_m_right_turn_between_100_m_straights(maps):
    (road,) = maps["curve90"].roads.values()
    assert [g.kind for g in road.geoms] == ["line", "arc", "line"]
    before, curve, after = road.geoms
    assert before.length >= 100.0 and after.length >= 100.0
    assert curve.k0 == pytest.approx(-1.0 / 20.0, rel=1e-12)
    assert ref_pose(road, road.length)[2] - ref_pose(road, 0.0)[2] == pytest.approx(-math.pi / 2, abs=1e-9)
    assert lane_ids(road) == [-1, 1] and driving_only(road)
    # Lane centres (maps/README.md): right lane 18 m, left lane 22 m from the curve centre.
    centre = np.array([curve.x + 20.0 * math.sin(curve.hdg), curve.y - 20.0 * math.cos(curve.hdg)])
    for s in np.linspace(curve.s, curve.s + curve.length, 7):
        assert np.linalg.norm(world(road, s, -2.0) - centre) == pytest.approx(18.0, abs=1e-6)
        assert np.linalg.norm(world(road, s, 2.0) - centre) == pytest.approx(22.0, abs=1e-6)


def test_rural_is_long_winding_and_curvature_continuous(maps):
    rural = maps["rural"]
    (road,) = rural.roads.values()
    assert road.length >= 1500.0 and lane_ids(road) == [-1, 1] and driving_only(road)
    kinds = [g.kind for g in road.geoms]
    radii = [1.0 / g.k0 for g in road.geoms if g.kind == "arc"]
    assert all(30.0 - 1e-9 <= abs(r) <= 300.0 + 1e-9 for r in radii)
    assert min(radii) < 0.0 < max(radii)
    assert road.geoms[0].k0 == 0.0 and road.geoms[-1].k1 == 0.0
    for prev, nxt in zip(road.geoms, road.geoms[1:]):
        assert prev.k1 == pytest.approx(nxt.k0, abs=1e-12), nxt.s
    for i, kind in enumerate(kinds):
        if kind == "arc":
            assert kinds[i - 1] == "spiral" and kinds[i + 1] == "spiral"
    s_bends = [
        i for i in range(len(kinds) - 2)
        if kinds[i:i + 3] == ["arc", "spiral", "arc"] and road.geoms[i].k0 * road.geoms[i + 2].k0 < 0
    ]
    assert s_bends and road.geoms[s_bends[0]].k0 > 0.0
    assert "line" in kinds


def test_rural_geo_reference_is_tmerc():
    pyproj = pytest.importorskip("pyproj")
    proj = read_map(bundled_map("rural")).root.find("header/geoReference").text.strip()
    crs = pyproj.CRS.from_proj4(proj)
    assert crs.coordinate_operation.method_name == "Transverse Mercator"
    lon, lat = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True).transform(0.0, 0.0)
    assert (lon, lat) == pytest.approx((11.575, 48.137), abs=1e-9)


def test_junction_has_left_straight_right_from_every_arm(maps):
    odr = maps["junction"]
    arms = [r for r in odr.roads.values() if r.junction == "-1"]
    connecting = [r for r in odr.roads.values() if r.junction != "-1"]
    assert len(arms) == 4 and len(connecting) == 12 and len(odr.junctions) == 1
    for arm in arms:
        assert arm.length >= 100.0 and lane_ids(arm) == [-1, 1] and driving_only(arm)
        assert [link[0] for link in (arm.pred, arm.succ) if link] == ["junction"]
    turns = {}
    for road in connecting:
        assert len(road.geoms) == 1 and road.geoms[0].kind in ("line", "arc")
        assert lane_ids(road) == [-1]
        turn = ref_pose(road, road.length)[2] - ref_pose(road, 0.0)[2]
        turns.setdefault(road.pred[1], []).append((round(turn / (math.pi / 2)), road.succ[1]))
        assert turn == pytest.approx(round(turn / (math.pi / 2)) * math.pi / 2, abs=1e-9)
        if road.geoms[0].kind == "arc":
            assert abs(1.0 / road.geoms[0].k0) == pytest.approx(15.0)
    for arm in arms:
        movements = sorted(turns[arm.id])
        assert [m[0] for m in movements] == [-1, 0, 1]
        assert len({m[1] for m in movements} | {arm.id}) == 4


def test_highway_lanes_offset_and_exit(maps):
    odr = maps["highway"]
    main, ramp = odr.roads["1"], odr.roads["3"]
    assert lane_ids(main, 0) == [-3, -2, -1, 1, 2, 3] and all(driving_only(r) for r in odr.roads.values())
    assert lane_ids(main, 1) == [-4, -3, -2, -1, 1, 2, 3]
    exit_section = main.sections[1]
    assert lane_width(exit_section, -4, exit_section.s) == 0.0 and not exit_section.lanes[-4].pred
    assert any(rec[3] != 0.0 or rec[4] != 0.0 for rec in main.offsets)
    offsets = [cubic(main.offsets, s) for s in np.linspace(0.0, main.length, 61)]
    assert offsets[0] != offsets[-1] and np.all(np.diff(offsets) >= 0.0)
    (connections,) = odr.junctions.values()
    from_main = {c[2]: c[4] for c in connections if c[1] == "1"}
    assert sorted(from_main.values()) == [((-4, -1),), ((-1, -1), (-2, -2), (-3, -3))]
    main_end_hdg = ref_pose(odr.roads["2"], odr.roads["2"].length)[2]
    assert ref_pose(ramp, ramp.length)[2] - main_end_hdg < -0.5
    # The ramp lane ends far to the right of the main carriageway's outer border.
    main_out = odr.roads["2"]
    ramp_end = world(ramp, ramp.length, lane_borders_t(ramp, ramp.sections[-1], -1, ramp.length)[0])
    x, y, h = ref_pose(main_out, 0.0)
    lateral = -(ramp_end[0] - x) * math.sin(h) + (ramp_end[1] - y) * math.cos(h)
    assert lateral < lane_borders_t(main_out, main_out.sections[0], -3, 0.0)[1] - 50.0
