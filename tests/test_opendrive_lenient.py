"""Lenient reading of omitted coefficients (strict mode refuses them), superelevation,
the lane ``direction`` attribute, geometry-record ends in exports and gap reports."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from cold_maps.cli.maps import main
from cold_maps.network.continuity import link_gaps, record_joints, reference_line_defects
from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.model import RoadLink
from cold_maps.opendrive.parser import parse_opendrive
from cold_maps.opendrive.sampling import sample_road
from cold_maps.simulation.neighbours import neighbour_key

LANES = """
    <lanes><laneSection s="0">
      <center><lane id="0" type="none"/></center>
      <right><lane id="-1" type="driving" level="{level}"><link><predecessor id="-1"/><successor id="-1"/></link>
               <width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
             <lane id="-2" type="driving"><link><predecessor id="-2"/><successor id="-2"/></link>
               <width sOffset="0" a="3" b="0" c="0" d="0"/></lane></right>
    </laneSection></lanes>"""


def xodr(roads: str, header: str = "") -> bytes:
    return f'<OpenDRIVE><header revMajor="1" revMinor="6">{header}</header>{roads}</OpenDRIVE>'.encode()


def road(road_id: str, geometry: str, extra: str = "", level: str = "false", length: float = 20.0) -> str:
    return (
        f'<road id="{road_id}" length="{length}" junction="-1"><planView>{geometry}</planView>'
        f"{extra}{LANES.format(level=level)}</road>"
    )


# RoadRunner-style empty records: a spiral without curvStart, a paramPoly3 with only its
# non-zero coefficients, an elevation and a superelevation without values.
ROADRUNNER = xodr(
    road(
        "1",
        '<geometry s="0" x="0" y="0" hdg="0" length="10"><spiral curvEnd="0.02"/></geometry>'
        '<geometry s="10" x="9.99667" y="0.33331" hdg="0.1" length="10"><paramPoly3 bU="1" pRange="arcLength"/></geometry>',
        '<elevationProfile><elevation s="0"/></elevationProfile>'
        "<lateralProfile><superelevation/></lateralProfile>",
    )
    + road("2", '<geometry s="0" x="0" y="50" hdg="0" length="20"><arc/></geometry>')
)


def test_omitted_coefficients_are_zero_with_one_warning_per_kind_and_road(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="cold_maps.opendrive.parser"):
        odr_map = parse_opendrive(ROADRUNNER, path="rr.xodr")
    spiral, poly = odr_map.roads["1"].plan_view
    assert (spiral.curv_start, spiral.curv_end) == (0.0, 0.02)
    assert (poly.au, poly.bu, poly.cu, poly.du, poly.av, poly.bv, poly.cv, poly.dv) == (0, 1, 0, 0, 0, 0, 0, 0)
    assert odr_map.roads["1"].elevation[0] == odr_map.roads["1"].superelevation[0]  # all zeros
    assert odr_map.roads["2"].plan_view[0].curvature == 0.0
    messages = sorted(record.getMessage() for record in caplog.records)
    assert messages == [
        "rr.xodr: road 1: <elevation> without a, b, c, d: taken as 0 (strict mode refuses it)",
        "rr.xodr: road 1: <paramPoly3> without aU, aV, bV, cU, cV, dU, dV: taken as 0 (strict mode refuses it)",
        "rr.xodr: road 1: <spiral> without curvStart: taken as 0 (strict mode refuses it)",
        "rr.xodr: road 1: <superelevation> without a, b, c, d, s: taken as 0 (strict mode refuses it)",
        "rr.xodr: road 2: <arc> without curvature: taken as 0 (strict mode refuses it)",
    ]
    # the defaulted paramPoly3 is the straight line u = p: it ends 10 m along heading 0.1
    x, y, _ = sample_road(odr_map.roads["1"], step=5.0)[0].inner[-1]
    assert (x, y) == pytest.approx((9.99667 + 10 * math.cos(0.1), 0.33331 + 10 * math.sin(0.1)), abs=1e-9)


def test_strict_mode_refuses_the_first_omission() -> None:
    with pytest.raises(OpenDriveError, match="<spiral>: missing required attribute 'curvStart'"):
        parse_opendrive(ROADRUNNER, path="rr.xodr", strict=True)


def test_cli_strict_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    source = tmp_path / "rr.xodr"
    source.write_bytes(ROADRUNNER)
    assert main(["info", str(source)]) == 0
    warned = capsys.readouterr().err.splitlines()
    assert len(warned) == 5 and all(line.startswith("WARNING cold_maps.opendrive.parser: ") for line in warned)
    assert main(["info", "-q", str(source)]) == 0
    assert capsys.readouterr().err == ""
    assert main(["info", "--strict", str(source)]) == 1
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("cold-maps: error: ")


def test_superelevation_raises_the_left_side_and_level_lanes_stay_flat() -> None:
    slope = 0.05  # rad
    extra = f'<lateralProfile><superelevation s="0" a="{slope}" b="0" c="0" d="0"/></lateralProfile>'
    for level, flat in (("false", False), ("true", True)):
        odr_map = parse_opendrive(xodr(road("1", '<geometry s="0" x="0" y="0" hdg="0" length="20"><line/></geometry>', extra, level)))
        first, second = sample_road(odr_map.roads["1"], step=5.0)
        np.testing.assert_allclose(first.inner[:, 2], 0.0, atol=1e-12)
        lane1_outer = 0.0 if flat else -3.5 * math.tan(slope)
        np.testing.assert_allclose(first.outer[:, 2], lane1_outer, atol=1e-12)
        np.testing.assert_allclose(second.outer[:, 2], lane1_outer - 3.0 * math.tan(slope), atol=1e-12)
        np.testing.assert_allclose(first.outer[:, 1], -3.5, atol=1e-12)  # horizontal position unchanged


def test_reversed_lane_direction_turns_the_lane_graph_edge() -> None:
    lanes = LANES.format(level="false").replace('<lane id="-2" type="driving">', '<lane id="-2" type="driving" direction="reversed">')
    roads = "".join(
        f'<road id="{i}" length="10" junction="-1"><link>{link}</link><planView>'
        f'<geometry s="0" x="{10 * (i - 1)}" y="0" hdg="0" length="10"><line/></geometry></planView>{lanes}</road>'
        for i, link in ((1, '<successor elementType="road" elementId="2" contactPoint="start"/>'),
                        (2, '<predecessor elementType="road" elementId="1" contactPoint="end"/>'))
    )
    graph = build_lane_graph(parse_opendrive(xodr(roads)))
    assert graph.successors[LaneKey("1", 0, -1)] == (LaneKey("2", 0, -1),)
    assert graph.successors[LaneKey("2", 0, -2)] == (LaneKey("1", 0, -2),)
    assert graph.successors[LaneKey("1", 0, -2)] == ()
    # the neighbour sensor follows the same direction: a reversed lane beside is no neighbour
    assert neighbour_key(graph, LaneKey("1", 0, -1), -1) is None
    assert neighbour_key(graph, LaneKey("1", 0, -2), +1) is None


GAP_M = 0.04  # the second record starts 4 cm left of where the first ends, and 0.5 deg turned
GAPPED = xodr(
    road(
        "7",
        '<geometry s="0" x="0" y="0" hdg="0" length="10"><line/></geometry>'
        f'<geometry s="10" x="10" y="{GAP_M}" hdg="{math.radians(0.5)}" length="10"><line/></geometry>',
    )
)


def test_record_joints_size_gaps_and_kinks() -> None:
    odr_map = parse_opendrive(GAPPED)
    (joint,) = record_joints(odr_map)
    assert (joint.road_id, joint.s) == ("7", 10.0)
    assert joint.gap_m == pytest.approx(GAP_M, abs=1e-12)
    assert math.degrees(joint.kink_rad) == pytest.approx(0.5, abs=1e-9)
    assert reference_line_defects(odr_map, gap_m=0.05, kink_rad=math.radians(1.0)) == []


OFFSET_U_M, OFFSET_V_M = 0.03, 0.04  # a paramPoly3 that starts off its own x, y


def test_record_joints_measure_from_where_a_param_poly3_starts() -> None:
    """The record's x, y lie exactly where the line ends, but u(0), v(0) = (aU, aV) move its
    first point: the joint's gap is hypot(aU, aV) and the exported border draws that jump."""
    odr_map = parse_opendrive(xodr(road(
        "8",
        '<geometry s="0" x="0" y="0" hdg="0" length="10"><line/></geometry>'
        f'<geometry s="10" x="10" y="0" hdg="0" length="10"><paramPoly3 aU="{OFFSET_U_M}" bU="1" '
        f'aV="{OFFSET_V_M}" pRange="arcLength"/></geometry>',
    )))
    (joint,) = record_joints(odr_map)
    assert joint.gap_m == pytest.approx(math.hypot(OFFSET_U_M, OFFSET_V_M), abs=1e-12)
    assert joint.kink_rad == pytest.approx(0.0, abs=1e-12)
    centre = next(b for b in sample_road(odr_map.roads["8"], step=3.0, record_ends=True) if b.lane_id == -1)
    at = np.flatnonzero(centre.s == 10.0)
    assert len(at) == 2
    np.testing.assert_allclose(centre.inner[at[1], :2] - centre.inner[at[0], :2], (OFFSET_U_M, OFFSET_V_M), atol=1e-12)


def test_export_draws_the_jump_between_records_exactly(tmp_path: Path) -> None:
    source, out = tmp_path / "gap.xodr", tmp_path / "gap.geojson"
    source.write_bytes(GAPPED)
    assert main(["export", str(source), "--step", "3", "--format", "geojson", "--crs", "local", "-o", str(out)]) == 0
    collection = json.loads(out.read_text())
    assert collection["cold_maps:crs"]["frame"] == "local"
    inner = next(f for f in collection["features"] if f["properties"]["lane_id"] == -1 and f["properties"]["side"] == "left")
    s = np.array(inner["properties"]["s"])
    xy = np.array(inner["geometry"]["coordinates"])[:, :2]
    at = np.flatnonzero(s == 10.0)
    assert len(at) == 2  # driving along +s: the first record's end, then the second's start
    np.testing.assert_allclose(xy[at[0]], (10.0, 0.0), atol=1e-4)
    np.testing.assert_allclose(xy[at[1]], (10.0, GAP_M), atol=1e-4)


def test_link_gaps_report_borders_that_miss(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lanes = LANES.format(level="false")
    roads = "".join(
        f'<road id="{i}" length="10" junction="-1"><link>{link}</link><planView>'
        f'<geometry s="0" x="{10 * (i - 1)}" y="{y}" hdg="0" length="10"><line/></geometry></planView>{lanes}</road>'
        for i, y, link in ((1, 0.0, '<successor elementType="road" elementId="2" contactPoint="start"/>'),
                           (2, 0.025, '<predecessor elementType="road" elementId="1" contactPoint="end"/>'))
    )
    gaps = link_gaps(build_lane_graph(parse_opendrive(xodr(roads))))
    assert sorted((g.exit_lane.lane_id, round(g.distance_m, 9)) for g in gaps) == [(-2, 0.025), (-1, 0.025)]
    source = tmp_path / "links.xodr"
    source.write_bytes(xodr(roads))
    assert main(["info", str(source)]) == 0
    out = capsys.readouterr().out
    assert "lane links whose borders miss by over 1 cm: 2 of 2" in out
    assert "road 1 section 0 lane -1 -> road 2 section 0 lane -1: 2.5 cm" in out


def test_a_centre_lane_without_type_is_none_with_one_warning(caplog: pytest.LogCaptureFixture) -> None:
    two_sections = road("1", '<geometry s="0" x="0" y="0" hdg="0" length="20"><line/></geometry>')
    section = two_sections[two_sections.index("<laneSection"):two_sections.index("</laneSection>")]
    two_sections = two_sections.replace("</laneSection>", "</laneSection>" + section.replace('s="0"', 's="10"', 1)
                                        + "</laneSection>", 1)
    untyped = two_sections + road("2", '<geometry s="0" x="0" y="9" hdg="0" length="20"><line/></geometry>')
    data = xodr(untyped.replace('<lane id="0" type="none"/>', '<lane id="0"/>'))
    with caplog.at_level(logging.WARNING, logger="cold_maps.opendrive.parser"):
        odr_map = parse_opendrive(data, path="asam.xodr")
    assert [odr_map.roads[r].lane_sections[0].lane(0).type for r in ("1", "2")] == ["none", "none"]
    warnings = [r.getMessage() for r in caplog.records]
    assert warnings == ['asam.xodr: the centre <lane> of 2 road(s) has no type (first: road 1): taken as "none" '
                        "(strict mode refuses it)"]
    with pytest.raises(OpenDriveError, match="missing required attribute 'type'"):
        parse_opendrive(data, path="asam.xodr", strict=True)
    with pytest.raises(OpenDriveError, match="missing required attribute 'type'"):
        parse_opendrive(xodr(untyped.replace('<lane id="-2" type="driving">', '<lane id="-2">')))


def test_records_whose_length_disagrees_with_the_next_s_are_listed() -> None:
    """ASAM's check_road_geometry_length: a record 2 m short of the next one's s, one 3 m
    long, the last 1 m short of the road's end; the reference line follows the s (each
    record drawn on to the next), so the joints show no gap, and ``info`` lists the lengths."""
    from cold_maps.network.continuity import record_length_mismatches

    records = ('<geometry s="0" x="0" y="0" hdg="0" length="8"><line/></geometry>'
               '<geometry s="10" x="10" y="0" hdg="0" length="8"><line/></geometry>'
               '<geometry s="15" x="15" y="0" hdg="0" length="4"><line/></geometry>')
    odr_map = parse_opendrive(xodr(road("1", records, length=20.0)))
    found = [(joint.s, joint.gap_m) for joint in record_length_mismatches(odr_map)]
    assert found == [(10.0, -2.0), (15.0, 3.0), (20.0, -1.0)]
    assert reference_line_defects(odr_map) == []


def dangling_links_map() -> bytes:
    """Road 1 names a predecessor road 99 (not in the file, no contactPoint) and leads into junction 7, whose
    connecting road 2 names a successor junction 70 (not in the file); junction 7's
    connection 0 comes from road 55 (not in the file), connection 1 from road 1."""
    geometry = '<geometry s="0" x="0" y="0" hdg="0" length="20"><line/></geometry>'
    links = ('<link><predecessor elementType="road" elementId="99"/>'
             '<successor elementType="junction" elementId="7"/></link>')
    connecting_links = ('<link><predecessor elementType="road" elementId="1" contactPoint="end"/>'
                        '<successor elementType="junction" elementId="70"/></link>')
    junction = ('<junction id="7"><connection id="0" incomingRoad="55" connectingRoad="2" contactPoint="start">'
                '<laneLink from="-1" to="-1"/></connection>'
                '<connection id="1" incomingRoad="1" connectingRoad="2" contactPoint="start">'
                '<laneLink from="-1" to="-1"/><laneLink from="-2" to="-2"/></connection></junction>')
    connecting = road("2", geometry.replace('x="0"', 'x="20"'), connecting_links).replace('junction="-1"', 'junction="7"')
    return xodr(road("1", geometry, links) + "\n" + connecting + junction)


def test_links_to_missing_roads_and_junctions_are_dropped_with_one_warning(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="cold_maps.opendrive.parser"):
        odr_map = parse_opendrive(dangling_links_map(), path="dangling.xodr")
    assert [r.getMessage() for r in caplog.records] == [
        "dangling.xodr: 3 link(s) name a road or junction that is not in the file (first: road 1 predecessor, "
        "line 1, links to road '99', which does not exist): road links and junction connections dropped, a road's "
        "junction attribute kept (strict mode refuses them)"
    ]
    first, connecting = odr_map.roads["1"], odr_map.roads["2"]
    assert (first.predecessor, first.successor) == (None, RoadLink("junction", "7"))
    assert (connecting.predecessor, connecting.successor) == (RoadLink("road", "1", "end"), None)
    assert [c.id for c in odr_map.junctions["7"].connections] == ["1"]
    graph = build_lane_graph(odr_map)
    assert graph.issues == ()
    assert set(graph.edges()) == {(LaneKey("1", 0, lane), LaneKey("2", 0, lane)) for lane in (-1, -2)}


def test_strict_mode_refuses_a_link_to_a_missing_road(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(OpenDriveError, match="links to road '99', which does not exist") as info:
        parse_opendrive(dangling_links_map(), path="dangling.xodr", strict=True)
    assert (info.value.element, info.value.line) == ("predecessor", 1)
    source = tmp_path / "dangling.xodr"
    source.write_bytes(dangling_links_map())
    assert main(["info", "-q", str(source)]) == 0
    assert main(["info", "-q", "--strict", str(source)]) == 1
    assert capsys.readouterr().err.count("\n") == 1


def single_point_map(*, last: bool = True, sections: tuple[float, ...] = (0.0,)) -> bytes:
    """Road 1: a 100 m line along +x and RoadRunner's empty ``<paramPoly3/>`` of 23.6 m
    (a single point at x = 100), as its last record or followed by another 50 m line."""
    records = ('<geometry s="0" x="0" y="0" hdg="0" length="100"><line/></geometry>'
               '<geometry s="100" x="100" y="0" hdg="0" length="23.6"><paramPoly3/></geometry>')
    length = 123.6
    if not last:
        records += '<geometry s="123.6" x="100" y="0" hdg="0" length="50"><line/></geometry>'
        length += 50.0
    text = road("1", records, length=length)
    section = text[text.index('<laneSection s="0">'):text.index("</laneSection>") + len("</laneSection>")]
    text = text.replace(section, "".join(section.replace('s="0"', f's="{s!r}"', 1) for s in sections))
    return xodr(text)


def test_a_last_record_that_draws_a_single_point_ends_the_road(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="cold_maps.opendrive.parser"):
        odr_map = parse_opendrive(single_point_map(sections=(0.0, 60.0, 110.0)), path="rr.xodr")
    assert caplog.records[-1].getMessage() == (
        "rr.xodr: 1 road(s) end in <paramPoly3> records that draw a single point (first: road 1, 1 record(s) from "
        "s=100 m): read as absent, the road and its lanes end there (strict mode refuses them)")
    road_1 = odr_map.roads["1"]
    assert road_1.length == 100.0 and [g.kind for g in road_1.plan_view] == ["line"]
    assert [(section.s, section.s_end) for section in road_1.lane_sections] == [(0.0, 60.0), (60.0, 100.0)]
    last = sample_road(road_1, step=1.0)[-1]
    np.testing.assert_allclose(last.outer[-1, :2], [100.0, -6.5])
    graph = build_lane_graph(odr_map)
    assert graph.lengths[LaneKey("1", 1, -1)] == pytest.approx(40.0)
    written = single_point_map().replace(b"<paramPoly3/>", b'<paramPoly3 aU="0" bU="0" cU="0" dU="0" aV="0" bV="0" '
                                                           b'cV="0" dV="0"/>')
    with pytest.raises(OpenDriveError, match="the <geometry> at s=100 is a <paramPoly3> that draws a single point"):
        parse_opendrive(written, path="rr.xodr", strict=True)


def test_a_single_point_record_inside_a_road_is_refused_naming_it() -> None:
    with pytest.raises(OpenDriveError) as info:
        parse_opendrive(single_point_map(last=False), path="rr.xodr")
    assert info.value.element == "paramPoly3"
    assert "the <geometry> at s=100: paramPoly3 at s=100.0: u(p), v(p) describe a single point" in str(info.value)
