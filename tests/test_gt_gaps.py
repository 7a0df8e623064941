"""Lane ends that do not touch (issue 17): joined in the Lanelet2 output, checked for
connectivity, never silently measured against a GT that stops; maps crdesigner rejects."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from converters.crdesigner_bridge import SourceLanelet, crdesigner_copy
from converters.joins import JOIN_TOLERANCE_M, join_ends, successor_gaps
from converters.osm import MERGE_TOLERANCE_M, build_osm
from tests.gap_maps import ROAD1_LENGTH_M, branch_gap_map

LANE_M = 3.5


def _straight(lanelet_id: int, x0: float, x1: float, dy: float = 0.0, successors: tuple[int, ...] = ()) -> SourceLanelet:
    """A lanelet along +x from x0 to x1 (m), vertices every 0.5 m, left border at y = dy."""
    x = np.linspace(x0, x1, int(round((x1 - x0) / 0.5)) + 1)
    left = np.column_stack((x, np.full_like(x, dy)))
    right = np.column_stack((x, np.full_like(x, dy - LANE_M)))
    return SourceLanelet(lanelet_id, left, right, frozenset({"urban"}), successors=successors)


def _load(tmp_path: Path, data: bytes):
    import lanelet2.io

    from converters import frame, routing_graph

    path = tmp_path / "map.osm"
    path.write_bytes(data)
    lanelet_map = lanelet2.io.load(str(path), frame.projector())
    return lanelet_map, routing_graph(lanelet_map)


@pytest.mark.parametrize("gap_m", [0.0, 0.02, 0.3])
def test_linked_ends_within_tolerance_share_nodes_at_their_midpoint(tmp_path, gap_m) -> None:
    lanelets = [_straight(1, 0.0, 10.0, successors=(2,)), _straight(2, 10.0, 20.0, dy=gap_m)]
    lanelet_map, routing = _load(tmp_path, build_osm(lanelets))
    first, second = lanelet_map.laneletLayer[1], lanelet_map.laneletLayer[2]
    assert [f.id for f in routing.following(first)] == [2]
    for bound in ("leftBound", "rightBound"):
        end, start = getattr(first, bound)[-1], getattr(second, bound)[0]
        assert end.id == start.id
    # the joined node sits halfway: the GT moves by half the gap at the join, nowhere else
    assert first.leftBound[-1].y == pytest.approx(gap_m / 2, abs=1e-6)
    assert first.leftBound[0].y == pytest.approx(0.0, abs=1e-6)
    assert second.leftBound[-1].y == pytest.approx(gap_m, abs=1e-6)


def test_linked_ends_beyond_tolerance_stay_apart_and_are_reported(tmp_path) -> None:
    gap_m = JOIN_TOLERANCE_M + 0.3
    lanelets = [_straight(1, 0.0, 10.0, successors=(2,)), _straight(2, 10.0, 20.0, dy=gap_m)]
    (gap,) = successor_gaps(lanelets, MERGE_TOLERANCE_M)
    assert (gap.lanelet, gap.successor, gap.joined) == (1, 2, False)
    assert gap.left_m == pytest.approx(gap_m) and gap.right_m == pytest.approx(gap_m)
    lanelet_map, routing = _load(tmp_path, build_osm(lanelets))
    assert list(routing.following(lanelet_map.laneletLayer[1])) == []
    assert lanelet_map.laneletLayer[1].leftBound[-1].y == pytest.approx(0.0, abs=1e-6)


def test_unlinked_ends_are_not_joined(tmp_path) -> None:
    lanelets = [_straight(1, 0.0, 10.0), _straight(2, 10.0, 20.0, dy=0.02)]
    assert successor_gaps(lanelets, MERGE_TOLERANCE_M) == ()
    lanelet_map, routing = _load(tmp_path, build_osm(lanelets))
    assert list(routing.following(lanelet_map.laneletLayer[1])) == []


@settings(max_examples=50, deadline=None)
@given(
    points=st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=12),
    data=st.data(),
)
def test_join_ends_moves_only_joined_points_to_their_group_centroid(points, data) -> None:
    xy = np.array(points, dtype=np.float64)
    n = len(xy)
    pairs = data.draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=4))
    representative, positions = join_ends(xy, np.arange(n, dtype=np.int64), pairs)
    touched = {i for pair in pairs for i in pair}
    for i in range(n):
        if i not in touched and all(representative[j] != representative[i] for j in touched):
            assert representative[i] == i and np.array_equal(positions[representative[i]], xy[i])
    for group in set(representative.tolist()):
        members = [i for i in range(n) if representative[i] == group]
        np.testing.assert_allclose(positions[group], xy[members].mean(axis=0), atol=1e-9)
    for a, b in pairs:
        assert representative[a] == representative[b]


def test_border_shorter_than_the_merge_keeps_two_nodes(tmp_path) -> None:
    """The inner border of a lane turning about its edge: 0.4 mm long, once refused."""
    right = np.array([[0.0, -3.5], [5.0, -3.5], [10.0, -3.5]])
    left = np.array([[5.0, 0.0], [5.0002, 0.0], [5.0004, 0.0]])
    lanelet_map, _ = _load(tmp_path, build_osm([SourceLanelet(1, left, right, frozenset())]))
    bound = lanelet_map.laneletLayer[1].leftBound
    assert len(bound) == 2
    assert bound[-1].x - bound[0].x == pytest.approx(0.0004, abs=1e-6)


# ---- the converter and `cold-maps check` on issue 17's junction ---------------------------


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / f"{name}.xodr"
    path.write_text(text)
    return path


def test_check_lists_edges_without_routing_successor_with_their_gap(tmp_path) -> None:
    from cold_maps.groundtruth.check import check_map

    near = check_map(_write(tmp_path, "near", branch_gap_map(0.02)), cache=False, converter="crdesigner")
    assert near.trustworthy and near.edges == 3 and near.disconnected == ()
    # the straight branch's start moves by half the 2 cm gap; nothing else moves
    assert max(lane.max_m for lane in near.lanes) == pytest.approx(0.01, abs=5e-4)
    far_m = JOIN_TOLERANCE_M + 0.3
    far = check_map(_write(tmp_path, "far", branch_gap_map(far_m)), cache=False, converter="crdesigner")
    assert not far.trustworthy and not far.failing
    (edge,) = far.disconnected
    assert (edge.source, edge.target) == (("1", 0, -1), ("2", 0, -1))
    assert edge.gap_m == pytest.approx(far_m, abs=1e-6)
    assert {("1", 0, -1), ("2", 0, -1)} <= far.flagged_lanes()


def _local_max(out: Path) -> float:
    scenarios = json.loads((out / "metrics.json").read_text())["scenarios"]
    return max(s["max_error_m"] for s in scenarios if s["fusion"] == "local")


ISSUE_RUN = ["--frames", "30", "--gaps", "20", "--interpolation", "paper", "--no-distractors", "--no-mcap",
             "--no-plots"]


@pytest.mark.parametrize("offsets", [(0.02, 0.0), (-0.02, 0.02)])
def test_local_error_follows_every_branch_across_small_gaps(tmp_path, monkeypatch, offsets) -> None:
    from cold_maps.cli.evaluate import main

    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "cache"))
    path = _write(tmp_path, "branch", branch_gap_map(*offsets, arc_exit=True))
    out = tmp_path / "out"
    assert main(["--map", str(path), "--routes", "all", "--out", str(out), *ISSUE_RUN]) == 0
    assert "gt_unmatched" not in (out / "metrics.json").read_text()
    assert _local_max(out) <= 0.05
    assert "NOT TRUSTWORTHY" not in (out / "summary.md").read_text()


def test_run_over_a_gap_too_wide_to_join_says_so_and_scores_no_frame_past_the_gt(tmp_path, monkeypatch, capsys) -> None:
    from cold_maps.cli.evaluate import main

    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "cache"))
    path = _write(tmp_path, "far", branch_gap_map(JOIN_TOLERANCE_M + 0.3))
    out = tmp_path / "out"
    # crdesigner's GT leaves the gap open (the engine's joins every lane-graph edge)
    assert main(["--map", str(path), "--routes", "1", "--out", str(out), "--converter", "crdesigner", *ISSUE_RUN]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "GROUND TRUTH NOT TRUSTWORTHY" in line and "1:0:-1" in line
    summary = (out / "summary.md").read_text()
    assert summary.index("GROUND TRUTH NOT TRUSTWORTHY") < summary.index("## Results per scenario")
    local = [s for s in json.loads((out / "metrics.json").read_text())["scenarios"] if s["fusion"] == "local"]
    for scenario in local:
        counted = scenario["gt_unmatched"]["past_gt_end"]
        assert counted == scenario["rejected"]["gt_unmatched"] > 0
        assert scenario["fused_frames"] + counted == scenario["frames"] == 30
    # the frames past the GT's end grew by 1 m per frame before; none of them is scored now
    frames = (out / "frames.csv").read_text().splitlines()
    assert sum(",local,," in row and ",gt_unmatched," in row for row in frames) == 2 * counted


# ---- coverage of a lane by its GT -----------------------------------------------------------


def test_points_past_the_gt_ends_are_counted_beyond_the_tolerance() -> None:
    from cold_maps.groundtruth.meter import GT_END_TOLERANCE_M, points_past_ends

    gt = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0]])
    points = np.array([[5.0, 1.0], [10.0 + GT_END_TOLERANCE_M / 2, 0.0], [10.5, 0.2], [-0.5, 0.0], [12.0, -3.0]])
    distances = np.array([1.0, GT_END_TOLERANCE_M / 2, math.hypot(0.5, 0.2), 0.5, math.hypot(2.0, 3.0)])
    assert points_past_ends(points, gt, distances, 0.02) == 3



def _past_ends_reference(points: np.ndarray, gt: np.ndarray, distances: np.ndarray, step_m: float) -> int:
    """``points_past_ends`` point by point: the end direction from the first vertex farther
    than the tolerance, every point tested on its own."""
    from cold_maps.groundtruth.meter import GT_END_TOLERANCE_M

    count = 0
    for end, inner in ((gt[-1], gt[-2::-1]), (gt[0], gt[1:])):
        apart = [v for v in inner if math.hypot(*(end - v)) > GT_END_TOLERANCE_M]
        if not apart:
            continue
        direction = (end - apart[0]) / math.hypot(*(end - apart[0]))
        for point, distance in zip(points, distances):
            offset = point - end
            count += bool(offset @ direction > GT_END_TOLERANCE_M and math.hypot(*offset) <= distance + step_m)
    return count


@settings(max_examples=60, deadline=None)
@given(
    dense_end=st.integers(0, 20),
    spacing_m=st.floats(0.001, 0.2),
    heading=st.floats(-math.pi, math.pi),
    seed=st.integers(0, 2**16),
)
def test_points_past_ends_equals_a_point_by_point_count(dense_end: int, spacing_m: float, heading: float,
                                                        seed: int) -> None:
    """GT borders whose ends carry up to 20 vertices closer together than the tolerance (the
    end direction lies beyond the first vertices searched) and points scattered around
    both ends: the vectorised count equals the point-by-point one."""
    from cold_maps.groundtruth.meter import points_past_ends

    rng = np.random.default_rng(seed)
    along = np.concatenate((np.arange(dense_end) * spacing_m, dense_end * spacing_m + np.cumsum(rng.uniform(0.2, 2.0, 8))))
    along = np.concatenate((along, along[-1] + along[-1] - along[::-1][1:]))
    gt = np.column_stack((along * math.cos(heading), along * math.sin(heading))) + rng.normal(0.0, 0.01, (len(along), 2))
    points = np.vstack([end + rng.normal(0.0, 1.0, (40, 2)) for end in (gt[0], gt[-1])])
    nearest = np.min(np.hypot(*(points[:, None, :] - gt[None]).transpose(2, 0, 1)), axis=1)
    distances = nearest + rng.uniform(-0.03, 0.03, len(points))
    assert points_past_ends(points, gt, distances, 0.02) == _past_ends_reference(points, gt, distances, 0.02)


# ---- maps crdesigner rejects ------------------------------------------------------------------


SECTION_BEYOND_RECORD = (
    '<laneSection s="29.5"><center><lane id="0" type="none"/></center><right><lane id="-1" type="driving">'
    '<width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right></laneSection>'
)
"""A second lane section starting past a 29.2 m record's end, within the 1 m our reader allows
between the last record and the road length (crdesigner: "Tried to calculate
a position outside of the borders of the reference path")."""


def _road(shape: str, length: float, road_length: float, extra: str = "", sections: str = "") -> str:
    return (
        '<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="6"/>'
        f'<road id="1" length="{road_length!r}" junction="-1"><link/>'
        f'<planView><geometry s="0" x="0" y="0" hdg="0" length="{length!r}">{shape}</geometry></planView>'
        '<lanes><laneSection s="0"><center><lane id="0" type="none"/></center><right>'
        '<lane id="-1" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right></laneSection>'
        f"{sections}</lanes>{extra}</road></OpenDRIVE>"
    )


def test_crdesigner_copy_rewrites_what_crdesigner_rejects() -> None:
    from lxml import etree

    data, _ = crdesigner_copy(_road('<spiral curvStart="0.01" curvEnd="0.0100000001"/>', 30.0, 30.0).encode())
    arc = etree.fromstring(data).find(".//arc")
    assert float(arc.get("curvature")) == pytest.approx(0.01000000005, rel=1e-12)
    data, _ = crdesigner_copy(_road('<spiral curvStart="0.0" curvEnd="0.02"/>', 20.0, 30.0).encode())
    geometry = etree.fromstring(data).find(".//geometry")
    spiral = geometry.find("spiral")
    assert float(geometry.get("length")) == 30.0
    assert float(spiral.get("curvEnd")) == pytest.approx(0.03)  # the rate 0.001 1/m² is kept
    junction = '<junction id="9" type="direct"><connection id="0" incomingRoad="1" linkedRoad="1" contactPoint="start"/></junction>'
    text = _road("<line/>", 30.0, 30.0).replace("</OpenDRIVE>", junction + "</OpenDRIVE>")
    data, _ = crdesigner_copy(text.encode())
    assert etree.fromstring(data).find(".//connection").get("connectingRoad") == "1"
    assert crdesigner_copy(_road("<line/>", 30.0, 30.0).encode()) is None
    data, _ = crdesigner_copy(_road('<arc curvature="-0.0"/>', 30.0, 30.0).encode())
    assert etree.fromstring(data).find(".//arc") is None and etree.fromstring(data).find(".//line") is not None
    assert crdesigner_copy(_road('<arc curvature="1e-12"/>', 30.0, 30.0).encode()) is None


def test_a_signal_past_its_road_end_is_moved_to_the_end_for_crdesigner(tmp_path) -> None:
    from lxml import etree

    from cold_maps.groundtruth.check import check_map

    signals = ('<signals><signal s="30.6" t="-4" id="1" dynamic="yes" orientation="+" country="DE" type="1000001" '
               'subtype="-1"/><signal s="-0.2" t="-4" id="2" dynamic="no" orientation="+" country="DE" type="274" '
               'subtype="-1" value="50"/></signals>')
    text = _road("<line/>", 30.0, 30.0, signals)
    data, _ = crdesigner_copy(text.encode())
    assert [float(s.get("s")) for s in etree.fromstring(data).iter("signal")] == [30.0, 0.0]
    report = check_map(_write(tmp_path, "m", text), cache=False, converter="crdesigner")
    assert report.trustworthy and len(report.lanes) == 1


@pytest.mark.parametrize("offset", ['x="55.451" y="109.52" z="0" hdg="0"', 'x="0" y="0.04" z="0" hdg="0"',
                                    'x="3" y="-2" z="1" hdg="0.3"'])
def test_the_header_offset_leaves_the_ground_truth_in_the_inertial_frame(tmp_path, offset) -> None:
    """crdesigner subtracts the header's <offset> from every record: ASAM's ValidSampleCrossing
    (offset 55.45, 109.52 m) was off by 122.8 m, a 4 cm offset passed the check unseen."""
    from converters import load_lanelet2
    from gt_matching import GroundTruth

    header = f'<header revMajor="1" revMinor="6"><offset {offset}/></header>'
    text = _road("<line/>", 30.0, 30.0).replace('<header revMajor="1" revMinor="6"/>', header)
    lanelet_map, routing = load_lanelet2(_write(tmp_path, "m", text), cache_dir=tmp_path / "cache")
    lanelets = list(GroundTruth(lanelet_map, routing).lanelet_map.laneletLayer)
    assert len(lanelets) == 1
    right = np.array([(p.x, p.y) for p in lanelets[0].rightBound])
    left = np.array([(p.x, p.y) for p in lanelets[0].leftBound])
    # lane -1 of the straight road along +x from the origin, 3.5 m wide, in the inertial frame
    np.testing.assert_allclose(left[:, 1], 0.0, atol=1e-6)
    np.testing.assert_allclose(right[:, 1], -3.5, atol=1e-6)
    assert min(left[:, 0].min(), right[:, 0].min()) == pytest.approx(0.0, abs=1e-6)
    assert max(left[:, 0].max(), right[:, 0].max()) == pytest.approx(30.0, abs=1e-6)


def test_lane_types_crdesigner_lacks_convert_and_check(tmp_path) -> None:
    """OpenDRIVE 1.8's slipLane (a vehicle lane: checked) and walking (crdesigner raised an
    Exception without a message on both)."""
    from lxml import etree

    from cold_maps.groundtruth.check import check_map

    walking = '<lane id="-2" type="walking"><width sOffset="0" a="2" b="0" c="0" d="0"/></lane>'
    text = (_road("<line/>", 30.0, 30.0).replace('<lane id="-1" type="driving">', '<lane id="-1" type="slipLane">')
            .replace("</lane></right>", f"</lane>{walking}</right>"))
    data, _ = crdesigner_copy(text.encode())
    assert [lane.get("type") for lane in etree.fromstring(data).iter("lane")] == ["none", "driving", "sidewalk"]
    report = check_map(_write(tmp_path, "m", text), cache=False, converter="crdesigner")
    assert report.trustworthy and [(lane.road_id, lane.lane_id) for lane in report.lanes] == [("1", -1)]


def test_a_centre_lane_without_type_converts_and_checks(tmp_path) -> None:
    """ASAM's Ex_Entry_Exit.xodr omits the centre lanes' type (crdesigner raised)."""
    from cold_maps.groundtruth.check import check_map

    text = _road("<line/>", 30.0, 30.0).replace('<lane id="0" type="none"/>', '<lane id="0"/>')
    assert '<lane id="0"/>' in text
    report = check_map(_write(tmp_path, "m", text), cache=False, converter="crdesigner")
    assert report.trustworthy and len(report.lanes) == 1


@pytest.mark.parametrize("geo_reference", ["<geoReference/>", "<geoReference>\n  </geoReference>"])
def test_straight_arc_and_empty_geo_reference_convert_and_check(tmp_path, geo_reference) -> None:
    """A straight ``<arc curvature="0">`` (crdesigner: ZeroDivisionError) on a map whose
    geoReference has no text (crdesigner: TypeError cleaning None) converts and checks."""
    from lxml import etree

    from cold_maps.groundtruth.check import check_map

    header = f'<header revMajor="1" revMinor="6">{geo_reference}</header>'
    text = _road('<arc curvature="0"/>', 30.0, 30.0).replace('<header revMajor="1" revMinor="6"/>', header)
    data, _ = crdesigner_copy(text.encode())
    assert etree.fromstring(data).find(".//geoReference") is None
    report = check_map(_write(tmp_path, "m", text), cache=False, converter="crdesigner")
    assert report.trustworthy and len(report.lanes) == 1


@pytest.mark.parametrize(
    ("shape", "length", "extra", "sections"),
    [
        ("<line/>", 30.0, '<signals><signal s="10" t="-4" id="1" dynamic="no" orientation="+" '
         'country="se" type="c" subtype="31" value="5"/></signals>', ""),
        ("<line/>", 30.0, '<signals><signal s="10" t="-4" id="1" dynamic="no" orientation="+" '
         'country="BEL" type="274" subtype="-1" value="50" unit="km/h"/></signals>', ""),
        ('<spiral curvStart="0.01" curvEnd="0.0100000001"/>', 30.0, "", ""),
        ('<arc curvature="0.01"/>', 29.2, "", SECTION_BEYOND_RECORD),
    ],
    ids=["swedish-signal", "belgian-signal", "nearly-constant-spiral", "record-short-of-road"],
)
def test_maps_crdesigner_rejected_convert_and_check(tmp_path, shape, length, extra, sections) -> None:
    from cold_maps.groundtruth.check import check_map

    report = check_map(_write(tmp_path, "m", _road(shape, length, 30.0, extra, sections)), cache=False, converter="crdesigner")
    assert report.trustworthy and len(report.lanes) == 1 + bool(sections)


def test_branch_map_geometry_is_what_the_issue_describes() -> None:
    from cold_maps.network.lane_graph import LaneKey, build_lane_graph
    from cold_maps.opendrive.parser import parse_opendrive

    graph = build_lane_graph(parse_opendrive(branch_gap_map(0.02).encode()))
    assert sorted((a.road_id, b.road_id) for a, b in graph.edges()) == [("1", "2"), ("1", "3"), ("2", "4")]
    assert graph.lengths[LaneKey("1", 0, -1)] == pytest.approx(ROAD1_LENGTH_M, abs=0.01)


def test_gt_follows_the_branch_the_detection_takes(tmp_path) -> None:
    from converters import load_lanelet2
    from converters.osm import OPENDRIVE_TAG
    from gt_matching import GroundTruth
    from tests.gap_maps import ARC_RADIUS_M

    lanelet_map, routing = load_lanelet2(_write(tmp_path, "branch", branch_gap_map(0.02, arc_exit=True)), cache=False)
    by_road = {dict(l.attributes)[OPENDRIVE_TAG].split(":")[0]: int(l.id) for l in lanelet_map.laneletLayer}
    truth = GroundTruth(lanelet_map, routing)
    x = np.linspace(25.0, 55.0, 301)
    left = np.column_stack((x, np.where(x < ROAD1_LENGTH_M, 0.0, 0.02)))
    straight = truth.match(left, left - [0.0, LANE_M], (25.0, -LANE_M / 2, 0.0))
    assert straight.matched and straight.lanelet_ids == (by_road["1"], by_road["2"])
    before = np.column_stack((np.linspace(25.0, ROAD1_LENGTH_M, 151)[:-1], np.zeros(150)))
    angle = np.linspace(0.0, 10.0 / ARC_RADIUS_M, 101)

    def arc(radius: float) -> np.ndarray:
        return np.column_stack((ROAD1_LENGTH_M + radius * np.sin(angle), radius * np.cos(angle) - ARC_RADIUS_M))

    turn = truth.match(np.vstack((before, arc(ARC_RADIUS_M))),
                       np.vstack((before - [0.0, LANE_M], arc(ARC_RADIUS_M - LANE_M))), (25.0, -LANE_M / 2, 0.0))
    assert turn.matched and turn.lanelet_ids == (by_road["1"], by_road["3"])


def test_border_fit_is_the_mean_capped_offset_of_the_detected_borders(tmp_path) -> None:
    from gt_matching.geometry import LaneletGeometry
    from gt_matching.ground_truth import _border_fit_m

    lanelet_map, _ = _load(tmp_path, build_osm([_straight(1, 0.0, 10.0, successors=(2,)), _straight(2, 10.0, 30.0)]))
    lanelets = [LaneletGeometry.of(lanelet_map.laneletLayer[i]) for i in (1, 2)]
    x = np.linspace(2.0, 28.0, 261)
    left = np.column_stack((x, np.full_like(x, 0.03)))
    right = np.column_stack((x, np.full_like(x, -LANE_M + 0.07)))
    assert _border_fit_m(lanelets, left, right, 1.5) == pytest.approx(0.05, abs=1e-9)
    assert _border_fit_m(lanelets, left + [0.0, 4.0], right + [0.0, 4.0], 1.5) == pytest.approx(1.5)


CORNER_ROAD_CROSSWALK = (
    '<objects><object id="5" type="crosswalk" s="50" t="0" zOffset="0" hdg="0" orientation="none" length="3" '
    'width="7"><outline id="0">' + "".join(f'<cornerRoad s="{s}" t="{t}" dz="0" height="0"/>'
                                           for s, t in ((48.5, -3.5), (48.5, 3.5), (51.5, 3.5), (51.5, -3.5)))
    + "</outline></object></objects>"
)


@pytest.mark.parametrize("converter", ["crdesigner", "engine"])
def test_a_crosswalk_outlined_by_road_corners_leaves_the_lanes_convertible(tmp_path, converter) -> None:
    from cold_maps.groundtruth.check import check_map

    path = _write(tmp_path, "corner", _road("<line/>", 100.0, 100.0, CORNER_ROAD_CROSSWALK))
    report = check_map(path, cache=False, converter=converter)  # crdesigner raised NotImplementedError (shapely)
    assert report.trustworthy and report.lanelets == 1 and len(report.lanes) == 1
