"""The OpenDRIVE reader puts every element it reads into the expected model fields."""

from __future__ import annotations

import math
import random
from collections import Counter
from pathlib import Path

import pytest
from conftest import bundled_map
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.opendrive.model import CubicPoly, LaneLink, OpenDriveMap, RoadLink
from cold_maps.opendrive.parser import load_opendrive, parse_opendrive

SMALL_MAP = Path(__file__).parent / "data" / "small_1_8.xodr"


CENTER_ONLY = '<laneSection s="0"><center><lane id="0" type="none"/></center></laneSection>'


def minimal(
    road: str = "", header: str = '<header revMajor="1" revMinor="4"/>', extra: str = "", sections: str = CENTER_ONLY
) -> bytes:
    """A one-road map (id "r", 10 m line): ``road`` is inserted into the road element,
    ``sections`` into its ``<lanes>``, ``extra`` after it."""
    return f"""<?xml version="1.0"?>
<OpenDRIVE>
  {header}
  <road id="r" length="10" junction="-1">
    <planView><geometry s="0" x="0" y="0" hdg="0" length="10"><line/></geometry></planView>
    {road}
    <lanes>{sections}</lanes>
  </road>
  {extra}
</OpenDRIVE>""".encode()


@pytest.fixture(scope="module")
def small() -> OpenDriveMap:
    return load_opendrive(SMALL_MAP)


def test_header_fields(small: OpenDriveMap) -> None:
    header = small.header
    assert (header.rev_major, header.rev_minor) == (1, 8)
    assert (header.name, header.vendor) == ("small", "cold-maps")
    assert (header.north, header.south, header.east, header.west) == (10.5, -2.0, 30.0, -1.25)
    geo = header.geo_reference
    assert geo.proj == "+proj=utm +zone=32 +ellps=WGS84 +units=m"
    assert (geo.offset_x, geo.offset_y, geo.offset_z, geo.offset_hdg) == (100.5, -20.0, 3.0, 0.25)


def test_header_defaults_when_absent() -> None:
    header = parse_opendrive(minimal()).header
    assert (header.rev_major, header.rev_minor, header.name, header.vendor) == (1, 4, "", "")
    assert all(math.isnan(v) for v in (header.north, header.south, header.east, header.west))
    assert header.geo_reference.proj == ""
    assert header.geo_reference.offset_hdg == 0.0


def test_geo_reference_plain_text_without_cdata() -> None:
    header = '<header revMajor="1" revMinor="6"><geoReference>\n  +proj=tmerc +lat_0=0 \n</geoReference></header>'
    assert parse_opendrive(minimal(header=header)).header.geo_reference.proj == "+proj=tmerc +lat_0=0"


def test_road_fields_and_links(small: OpenDriveMap) -> None:
    assert list(small.roads) == ["1", "2", "3"]
    road = small.roads["1"]
    assert (road.id, road.name, road.length, road.junction, road.rule) == ("1", "main", 30.0, "-1", "LHT")
    assert road.predecessor == RoadLink("road", "2", "end")
    # a contactPoint on a junction link (CARLA writes them) is tolerated and dropped
    assert road.successor == RoadLink("junction", "7", None)
    road_tag = '  <road id="1" name="main" length="30" junction="-1" rule="LHT">'
    assert road.line == SMALL_MAP.read_text().splitlines().index(road_tag) + 1
    other = small.roads["2"]
    assert (other.rule, other.predecessor, other.successor) == ("RHT", None, RoadLink("road", "1", "start"))
    assert small.roads["3"].junction == "7"
    assert small.roads["3"].name == ""


def test_traffic_rule_direction(small: OpenDriveMap) -> None:
    lht, rht = small.roads["1"], small.roads["2"]
    assert lht.drives_along_s(1) and not lht.drives_along_s(-1)
    assert rht.drives_along_s(-1) and not rht.drives_along_s(1)


def test_plan_view_sorted_with_every_kind(small: OpenDriveMap) -> None:
    plan = small.roads["1"].plan_view
    assert [g.kind for g in plan] == ["line", "arc", "spiral", "poly3", "paramPoly3", "paramPoly3"]
    assert [g.s for g in plan] == [0.0, 5.0, 10.0, 15.0, 20.000001, 25.0]
    line, arc, spiral, poly3, explicit, default = plan
    assert (line.x, line.y, line.hdg, line.length) == (1.0, 2.0, 0.5, 5.0)
    assert line.curvature == 0.0 and line.au == 0.0
    assert arc.curvature == -0.02
    assert (spiral.curv_start, spiral.curv_end) == (0.0, 0.04)
    assert (poly3.a, poly3.b, poly3.c, poly3.d, poly3.length) == (0.0, 0.1, 0.001, -0.0001, 5.000001)
    assert (explicit.au, explicit.bu, explicit.cu, explicit.du) == (1.0, 2.0, 3.0, 4.0)
    assert (explicit.av, explicit.bv, explicit.cv, explicit.dv) == (5.0, 6.0, 7.0, 8.0)
    assert explicit.p_range == "arcLength"
    assert default.p_range == "normalized"  # the spec default when pRange is absent
    assert (default.cu, default.dv) == (0.1, 0.003)


def test_elevation_and_lane_offset_sorted_absolute(small: OpenDriveMap) -> None:
    road = small.roads["1"]
    assert road.elevation == (CubicPoly(0.0, 1.0, 0.02, -0.001, 1e-5), CubicPoly(12.0, 1.5, 0.01, 0.0, 0.0))
    assert road.lane_offsets == (CubicPoly(0.0, 0.25, 0.01, 0.0, 0.0), CubicPoly(12.0, 0.5, 0.0, 0.0, 0.0))
    assert small.roads["2"].elevation == () and small.roads["2"].lane_offsets == ()


def test_lane_sections_sorted_with_ends(small: OpenDriveMap) -> None:
    sections = small.roads["1"].lane_sections
    assert [(sec.s, sec.s_end, sec.single_side) for sec in sections] == [(0.0, 18.0, False), (18.0, 30.0, True)]
    first, second = sections
    assert [lane.id for lane in first.left] == [1, 2]
    assert [lane.id for lane in first.right] == [-1, -2]
    assert first.center.id == 0 and first.center.type == "none"
    assert [lane.id for lane in first.lanes] == [1, 2, -1, -2]
    assert second.left == () and [lane.id for lane in second.right] == [-1]
    assert second.lane(-1).widths == (CubicPoly(0.0, 3.0, 0.0, 0.0, 0.0),)


def test_lane_fields(small: OpenDriveMap) -> None:
    section = small.roads["1"].lane_sections[0]
    left1 = section.lane(1)
    assert (left1.type, left1.level, left1.direction) == ("driving", False, "reversed")
    assert left1.widths == (CubicPoly(0.0, 3.25, 0.05, 0.001, -0.0002), CubicPoly(9.0, 3.5, -0.1, 0.0, 0.0))
    assert left1.borders == ()
    assert (left1.predecessors, left1.successors) == ((3,), (1, 2))
    left2 = section.lane(2)
    assert (left2.type, left2.level, left2.direction, left2.predecessors) == ("sidewalk", True, "", ())
    right1 = section.lane(-1)
    assert right1.widths == ()
    assert right1.borders == (CubicPoly(0.0, -3.0, -0.1, 0.0, 0.0), CubicPoly(5.0, -3.5, 0.0, 0.0, 0.0))
    assert (right1.predecessors, right1.successors) == ((-1,), (-1,))
    with pytest.raises(KeyError):
        section.lane(3)


def test_junction_connections(small: OpenDriveMap) -> None:
    assert list(small.junctions) == ["7"]
    junction = small.junctions["7"]
    assert (junction.id, junction.name, junction.type) == ("7", "crossing", "default")
    first, second = junction.connections
    assert (first.id, first.incoming_road, first.connecting_road, first.contact_point) == ("0", "1", "3", "start")
    assert first.lane_links == (LaneLink(-1, -1), LaneLink(1, 2))
    assert (second.id, second.incoming_road, second.contact_point, second.lane_links) == ("1", "2", "end", ())


def test_direct_junction_linked_road() -> None:
    extra = """<road id="s" length="5" junction="-1">
      <planView><geometry s="0" x="10" y="0" hdg="0" length="5"><line/></geometry></planView>
      <lanes><laneSection s="0"><center><lane id="0" type="none"/></center></laneSection></lanes></road>
    <junction id="d" type="direct">
      <connection id="0" incomingRoad="r" linkedRoad="s" contactPoint="start"/>
    </junction>"""
    junction = parse_opendrive(minimal(extra=extra)).junctions["d"]
    assert junction.type == "direct"
    assert (junction.connections[0].incoming_road, junction.connections[0].connecting_road) == ("r", "s")


def test_last_section_ends_at_road_length_and_sections_can_be_empty_length() -> None:
    later = CENTER_ONLY.replace('s="0"', 's="4"')
    road = parse_opendrive(minimal(sections=later + CENTER_ONLY)).roads["r"]
    assert [(sec.s, sec.s_end) for sec in road.lane_sections] == [(0.0, 4.0), (4.0, 10.0)]
    at_end = CENTER_ONLY.replace('s="0"', 's="10"')
    road = parse_opendrive(minimal(sections=CENTER_ONLY + at_end)).roads["r"]
    assert [(sec.s, sec.s_end) for sec in road.lane_sections] == [(0.0, 10.0), (10.0, 10.0)]
    rounded_past_end = CENTER_ONLY.replace('s="0"', 's="10.0009"')
    road = parse_opendrive(minimal(sections=CENTER_ONLY + rounded_past_end)).roads["r"]
    assert [(sec.s, sec.s_end) for sec in road.lane_sections] == [(0.0, 10.0), (10.0, 10.0)]


def test_zero_length_geometry_records_are_dropped() -> None:
    data = minimal().replace(
        b'<planView><geometry s="0" x="0" y="0" hdg="0" length="10"><line/></geometry>',
        b'<planView><geometry s="0" x="0" y="0" hdg="0" length="0"><arc curvature="0.5"/></geometry>'
        b'<geometry s="0" x="0" y="0" hdg="0" length="10"><line/></geometry>'
        b'<geometry s="10" x="10" y="0" hdg="0" length="0.0"><line/></geometry>',
    )
    plan_view = parse_opendrive(data).roads["r"].plan_view
    assert [(g.kind, g.s, g.length) for g in plan_view] == [("line", 0.0, 10.0)]


def test_namespaced_file_is_read() -> None:
    data = minimal().replace(b"<OpenDRIVE>", b'<OpenDRIVE xmlns="http://www.asam.net/xsd/OpenDRIVE/1.8">')
    assert list(parse_opendrive(data).roads) == ["r"]


@pytest.mark.parametrize("minor", [4, 5, 6, 7, 8])
def test_revisions_1_4_to_1_8_load(minor: int) -> None:
    header = f'<header revMajor="1" revMinor="{minor}" name="v{minor}"/>'
    odr = parse_opendrive(minimal(header=header))
    assert (odr.header.rev_minor, odr.header.name, list(odr.roads)) == (minor, f"v{minor}", ["r"])


def test_bundled_maps_load() -> None:
    """Maps written by our own generator (OpenDRIVE 1.6) round-trip through the reader."""
    odr = load_opendrive(bundled_map("junction"))
    assert odr.header.rev_minor == 6 and len(odr.junctions) == 1
    assert all(c.connecting_road in odr.roads for j in odr.junctions.values() for c in j.connections)


def test_in_memory_map_has_empty_path() -> None:
    assert parse_opendrive(minimal()).path == ""
    assert parse_opendrive(minimal(), path="mem.xodr").path == "mem.xodr"


def test_parse_rejects_text_input() -> None:
    with pytest.raises(TypeError, match="bytes"):
        parse_opendrive(minimal().decode())  # type: ignore[arg-type]


@pytest.mark.parametrize("town, roads, junctions", [("Town01", 122, 12), ("Town04", 276, 27)])
def test_carla_towns_load(town: str, roads: int, junctions: int, request: pytest.FixtureRequest) -> None:
    path = request.getfixturevalue(f"{town.lower()}_path")
    odr = load_opendrive(path)
    assert (len(odr.roads), len(odr.junctions)) == (roads, junctions)
    assert odr.path == str(path)
    assert (odr.header.rev_major, odr.header.rev_minor, odr.header.vendor) == (1, 4, "VectorZero")
    assert odr.header.geo_reference.proj.startswith("+proj=tmerc +lat_0=0 +lon_0=0")
    kinds = Counter(g.kind for road in odr.roads.values() for g in road.plan_view)
    assert set(kinds) == {"line", "arc"}  # RoadRunner wrote no spiral/poly3/paramPoly3 here
    for road in odr.roads.values():
        assert [g.s for g in road.plan_view] == sorted(g.s for g in road.plan_view)
        assert road.lane_sections[0].s == 0.0 and road.lane_sections[-1].s_end == road.length
        for before, after in zip(road.lane_sections, road.lane_sections[1:]):
            assert before.s_end == after.s and before.s <= after.s
        # the geometry records tile the reference line up to rounding
        assert math.isclose(sum(g.length for g in road.plan_view), road.length, rel_tol=1e-6, abs_tol=1e-6)
        for section in road.lane_sections:
            assert all(lane.widths or lane.borders for lane in section.lanes)
    in_junction = [road for road in odr.roads.values() if road.junction != "-1"]
    assert in_junction and all(road.junction in odr.junctions for road in in_junction)
    connecting = {c.connecting_road for j in odr.junctions.values() for c in j.connections}
    assert connecting == {road.id for road in in_junction}


def test_town04_has_multi_section_roads_and_lane_offsets(town04_path: Path) -> None:
    odr = load_opendrive(town04_path)
    assert max(len(road.lane_sections) for road in odr.roads.values()) > 1
    assert sum(len(road.lane_offsets) for road in odr.roads.values()) == 1393
    assert sum(len(road.elevation) for road in odr.roads.values()) == 2055
    assert sum(len(road.plan_view) for road in odr.roads.values()) == 1280


@settings(max_examples=60, deadline=None)
@given(
    starts=st.lists(st.floats(0.0, 10.0, allow_nan=False), min_size=1, max_size=6),
    widths=st.lists(st.tuples(st.floats(0.0, 50.0), st.floats(-5.0, 5.0)), max_size=5),
    order=st.randoms(use_true_random=False),
)
def test_sections_and_records_in_any_file_order(
    starts: list[float], widths: list[tuple[float, float]], order: random.Random
) -> None:
    """Sections and width records come out sorted by s whatever their file order; the
    section ends chain to the next start and the last ends at the road length."""
    records = "".join(f'<width sOffset="{s0!r}" a="{a!r}" b="0" c="0" d="0"/>' for s0, a in widths)
    lane = f'<right><lane id="-1" type="driving">{records}</lane></right>'
    center = '<center><lane id="0" type="none"/></center>'
    sections = [f'<laneSection s="{s!r}">{center}{lane}</laneSection>' for s in [0.0, *starts]]
    order.shuffle(sections)
    road = parse_opendrive(minimal(sections="".join(sections))).roads["r"]
    assert [sec.s for sec in road.lane_sections] == sorted([0.0, *starts])
    assert [sec.s_end for sec in road.lane_sections] == sorted(starts) + [10.0]
    expected = sorted((CubicPoly(s0, a, 0.0, 0.0, 0.0) for s0, a in widths), key=lambda r: r.s0)
    assert all(list(sec.lane(-1).widths) == expected for sec in road.lane_sections)
