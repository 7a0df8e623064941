"""Adversarial OpenDRIVE maps (tests/adversarial_maps.py) against our export, crdesigner's
independent OpenDRIVE code, the Lanelet2 conversion and ``cold-maps check``.

Where crdesigner is wrong the tests prove it with a closed form or by correcting only the
faulty step of crdesigner, and ``check`` must name exactly the affected lanes.
"""

from __future__ import annotations

import csv
import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from adversarial_maps import ARM_LENGTH_M, ARM_SPLIT_M, JUNCTION_HALF_M, LANE_WIDTH_M, MAPS, write_maps
from conftest import PROJECT_ROOT

from cold_maps.cli.maps import main as cold_maps_main
from cold_maps.cli.maps import map_info
from cold_maps.network.lane_graph import LENGTH_STEP_M, LaneKey, build_lane_graph
from cold_maps.network.route import route_from_lanes
from cold_maps.network.routing import random_route
from cold_maps.opendrive.parser import load_opendrive
from cold_maps.opendrive.sampling import sample_lane_borders

MM = 1e-3
AGREEING = ("spirals", "odd_geometry", "lht_junction", "named_ids", "tmerc", "utm", "utm_south", "no_geo", "lane_offset")
"""Maps on which crdesigner's own OpenDRIVE code follows the spec as we do."""
CONVERTED_AGREEING = (*AGREEING, "param_poly3")
"""Maps whose Lanelet2 conversion agrees with our borders (our converter evaluates
paramPoly3 and poly3 by arc length, unlike crdesigner's own code)."""
CONTINUITY_M = 0.01


@pytest.fixture(scope="session")
def maps(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return write_maps(tmp_path_factory.mktemp("adversarial"))


@pytest.fixture(scope="module")
def tool():
    """tools/crosscheck_opendrive.py as a module (tools/ is not a package)."""
    spec = importlib.util.spec_from_file_location("crosscheck_opendrive", PROJECT_ROOT / "tools" / "crosscheck_opendrive.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    del sys.modules[spec.name]


@pytest.fixture(scope="session")
def reports(maps: dict[str, Path], tmp_path_factory: pytest.TempPathFactory):
    """``check_map`` of every map (one crdesigner conversion each, private cache)."""
    from cold_maps.groundtruth.check import check_map

    cache = tmp_path_factory.mktemp("cache")
    return {name: check_map(path, cache_dir=cache, converter="crdesigner") for name, path in maps.items()}


@pytest.mark.parametrize("name", AGREEING)
def test_export_agrees_with_crdesigner(name: str, maps, tool) -> None:
    result = tool.crosscheck(maps[name], step=0.5)
    assert result.missing_in_theirs == () and result.missing_in_ours == ()
    assert result.lanes_compared >= 2
    assert np.percentile(result.distances, 99) <= 1 * MM
    assert result.distances.max() <= 5 * MM


@pytest.mark.parametrize("name", CONVERTED_AGREEING)
def test_lanelet2_ground_truth_agrees(name: str, reports) -> None:
    report = reports[name]
    assert report.trustworthy, report.failing
    assert all(lane.matched_by == "id" for lane in report.lanes)
    medians = np.array([lane.median_m for lane in report.lanes])
    assert np.median(medians) <= 1 * MM
    assert np.percentile([lane.max_m for lane in report.lanes], 95) <= 5 * MM


@pytest.mark.parametrize("name", list(MAPS))
def test_info_export_graph_and_routes(name: str, maps, tmp_path: Path) -> None:
    path = maps[name]
    odr_map = load_opendrive(path)
    info = dict(line.split(": ", 1) for line in map_info(odr_map))
    graph = build_lane_graph(odr_map)
    assert info["lane graph"].endswith(" 0 issues")
    out = tmp_path / "borders.csv"
    assert cold_maps_main(["export", str(path), "-o", str(out)]) == 0
    with out.open() as stream:
        exported = {(row["road_id"], int(row["section"]), int(row["lane_id"])) for row in csv.DictReader(stream)}
    assert exported == {tuple(lane) for lane in graph.lanes}  # no driving lane missing
    for before, after in graph.edges():
        exit_point = route_from_lanes(graph, [before], step=1.0).centre[-1]
        entry_point = route_from_lanes(graph, [after], step=1.0).centre[0]
        assert np.hypot(*(exit_point - entry_point)) <= CONTINUITY_M, (before, after)
    rng = np.random.default_rng(7)
    for _ in range(5):
        lanes = random_route(graph, 30.0, rng)
        assert lanes is not None
        route = route_from_lanes(graph, lanes, step=0.5)
        assert route.length >= 30.0 - 1e-6
        jumps = np.hypot(*np.diff(route.centre, axis=0).T)
        # a lane centre at t from the reference line steps ds·(1 - κ·t) (|κ·t| < 0.4 here),
        # times 2 on odd_geometry's paramPoly3, whose curve is twice its record length
        assert jumps.max() <= 0.5 * 1.4 * (2.0 if name == "odd_geometry" else 1.0)


def test_lht_junction_drives_on_the_left(maps) -> None:
    """Every arm: lane 1 leaves the junction, lane -1 enters it; every entry reaches the
    three other arms, the left turn (radius 10 m - 1.75 m) being the shortest."""
    odr_map = load_opendrive(maps["lht_junction"])
    graph = build_lane_graph(odr_map)
    half = LANE_WIDTH_M / 2
    # samples every step of s on the reference arc (radius R0 = 10 m) are chords of the
    # same angle on every lane: lengths fall short by step²/(24·R0²) (relative)
    chord = 1 - LENGTH_STEP_M**2 / (24 * JUNCTION_HALF_M**2)
    for k in range(4):
        entering = LaneKey(str(k + 1), 0, -1)
        assert graph.predecessors[entering] == (LaneKey(str(k + 1), 1, -1),)
        targets = {}
        for connector in graph.successors[entering]:
            (leaving,) = graph.successors[connector]
            assert (leaving.section, leaving.lane_id) == (0, 1)
            targets[leaving.road_id] = graph.lengths[connector]
        left, straight, right = (str((k + d) % 4 + 1) for d in (3, 2, 1))
        assert set(targets) == {left, straight, right}
        assert targets[straight] == pytest.approx(2 * JUNCTION_HALF_M, abs=1e-6)
        assert targets[left] == pytest.approx(math.pi / 2 * (JUNCTION_HALF_M - half) * chord, rel=1e-5)
        assert targets[right] == pytest.approx(math.pi / 2 * (JUNCTION_HALF_M + half) * chord, rel=1e-5)
    # arm 1 runs east from (10, 0): lane 1 (outwards) is north of the reference line in
    # LHT, and the driver's left border is its outer one (t = 3.5 m)
    out = route_from_lanes(graph, [LaneKey("1", 0, 1), LaneKey("1", 1, 1)])
    assert out.centre[0] == pytest.approx((JUNCTION_HALF_M, half), abs=1e-9)
    assert out.centre[-1] == pytest.approx((JUNCTION_HALF_M + ARM_LENGTH_M, half), abs=1e-9)
    assert out.left[0] == pytest.approx((JUNCTION_HALF_M, LANE_WIDTH_M), abs=1e-9)
    # straight through, entering on arm 1 (lane -1, south of it) and leaving on arm 3 (x < 0)
    (straight_in,) = [c for c in graph.successors[LaneKey("1", 0, -1)] if graph.successors[c][0].road_id == "3"]
    through = route_from_lanes(graph, [LaneKey("1", 0, -1), straight_in, LaneKey("3", 0, 1)])
    assert through.centre[0] == pytest.approx((JUNCTION_HALF_M + ARM_SPLIT_M, -half), abs=1e-9)
    assert through.centre[-1] == pytest.approx((-JUNCTION_HALF_M - ARM_SPLIT_M, -half), abs=1e-9)


def test_border_records_closed_form(maps) -> None:
    """Road 7 is an arc (x0 = y0 = 0, hdg 0.2, κ = 0.005): a lane's outer border lies at
    t = border(s) exactly, so its radius from the arc centre is 1/κ - t."""
    road = load_opendrive(maps["borders"]).roads["7"]
    kappa, hdg = 0.005, 0.2
    centre = np.array([-math.sin(hdg) / kappa, math.cos(hdg) / kappa])
    expected = {
        1: lambda s: np.where(s < 40.0, 3.5 + 0.01 * s, 3.9 - 0.0005 * (s - 40.0) ** 2),
        -1: lambda s: -3.5 - 0.001 * s**2 + 1e-5 * s**3,
        -2: lambda s: -6.5 - 0.02 * s,
    }
    for lane_id, border in expected.items():
        samples = sample_lane_borders(road, 0, lane_id, step=1.0)
        radius = np.hypot(*(samples.outer[:, :2] - centre).T)
        np.testing.assert_allclose(radius, 1 / kappa - border(samples.s), atol=1e-9)


def test_check_names_crdesigners_border_lanes(reports) -> None:
    """crdesigner 0.8.5 negates right-lane border records (see lanes.py): exactly the right
    lanes fail, by about their border value, and the left lane passes."""
    report = reports["borders"]
    assert {(lane.road_id, lane.lane_id) for lane in report.failing} == {("7", -1), ("7", -2)}
    by_lane = {lane.lane_id: lane for lane in report.lanes}
    assert by_lane[1].max_m <= 5 * MM
    assert by_lane[-1].median_m > 3.0


def _arc_length_param_poly3(original):
    """crdesigner's ParamPoly3.calc_position with s read as arc length (the spec's s):
    p(s) from a fine trapezoid table of |r'(p)|, then crdesigner's own evaluation."""

    def calc_position(self, s_pos, compute_curvature=True):
        p = np.linspace(0.0, self._pRange, 20001)
        speed = np.hypot(
            np.polynomial.polynomial.polyval(p, self.d_coeffs_u), np.polynomial.polynomial.polyval(p, self.d_coeffs_v)
        )
        arc = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(p))))
        p_at_s = np.interp(s_pos * arc[-1] / self.length, arc, p)
        return original(self, p_at_s / self._pRange * self.length, compute_curvature)

    return calc_position


def test_param_poly3_differs_only_by_crdesigners_linear_parameter(maps, tool, reports, monkeypatch) -> None:
    """crdesigner maps s linearly to p (p = s/length·pRange); with non-uniform parameter
    speed s is then no longer arc length. Reading s as arc length in crdesigner, and
    changing nothing else, brings both implementations within 1 mm / 5 mm."""
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_parser.elements.geometry import ParamPoly3

    as_written = tool.crosscheck(maps["param_poly3"], step=0.5)
    assert as_written.distances.max() > 0.1  # 0.46 m along track at a section start
    monkeypatch.setattr(ParamPoly3, "calc_position", _arc_length_param_poly3(ParamPoly3.calc_position))
    corrected = tool.crosscheck(maps["param_poly3"], step=0.5)
    assert corrected.missing_in_theirs == () and corrected.missing_in_ours == ()
    assert corrected.lanes_compared == 12
    assert np.percentile(corrected.distances, 99) <= 1 * MM
    assert corrected.distances.max() <= 5 * MM
    # our converter reads s as arc length too: its lanelets agree (see
    # test_lanelet2_ground_truth_agrees); the zero-width lane is listed apart, not checked
    report = reports["param_poly3"]
    assert report.zero_width == (("1", 3, -2),)
    from cold_maps.groundtruth.check import format_report

    assert "zero-width lanes not checked: 1 (road 1 section 3 lane -2)" in format_report(report)
    assert len(report.lanes) == 11


def test_check_names_the_lanes_of_crdesigners_linear_parameter(maps, tmp_path: Path, monkeypatch) -> None:
    """Without our arc-length evaluation the lanelets of the paramPoly3 road end 0.77 m
    along track from s = 85 m (crdesigner drops the zero-width lane -2 of section 3 and
    starts new lanelets there): check names exactly the three lanes of section 2."""
    from cold_maps.groundtruth.check import check_map
    from converters import crdesigner_bridge

    monkeypatch.setattr(crdesigner_bridge, "_param_poly3_by_arc_length", lambda original: original)
    report = check_map(maps["param_poly3"], cache=False, converter="crdesigner")
    assert {(lane.section, lane.lane_id) for lane in report.failing} == {(2, 1), (2, -1), (2, -2)}
    assert 0.5 < max(lane.max_m for lane in report.failing) < 1.0


def test_param_poly3_is_sampled_by_arc_length(maps) -> None:
    """Our reference line: equal s steps are equal chord lengths (to the chord error),
    and the road ends exactly at the end of the second curve."""
    road = load_opendrive(maps["param_poly3"]).roads["1"]
    from cold_maps.opendrive.reference_line import reference_pose

    s = np.linspace(0.0, road.length, 4001)
    x, y, _ = reference_pose(road, s)
    steps = np.hypot(np.diff(x), np.diff(y))
    np.testing.assert_allclose(steps, s[1] - s[0], rtol=1e-5)


def test_crdesigner_copy_renumbers_only_non_integer_ids(maps) -> None:
    """crdesigner reads ids as integers: "arm-…" roads and junction get fresh integers
    above the largest integer id, every reference follows, integer maps are untouched."""
    from lxml import etree

    from converters.crdesigner_bridge import crdesigner_copy

    def commented(name: str) -> bytes:  # comments at the top level and inside roads
        text = maps[name].read_bytes()
        return text.replace(b"<header", b"<!-- top --><header", 1).replace(b"<planView>", b"<planView><!-- g -->")

    assert crdesigner_copy(commented("lht_junction")) is None
    data, original = crdesigner_copy(commented("named_ids"))
    renamed = etree.fromstring(data)
    road_ids = [road.get("id") for road in renamed.iter("road")]
    assert sorted(map(int, road_ids)) == list(range(1, 17))
    assert sorted(original.values()) == sorted(road.id for road in load_opendrive(maps["named_ids"]).roads.values())
    (junction,) = renamed.iter("junction")
    assert junction.get("id") == "1"
    assert {road.get("junction") for road in renamed.iter("road")} == {"-1", "1"}
    references = [e.get("elementId") for e in renamed.iter("predecessor", "successor") if e.get("elementId")]
    references += [c.get(a) for c in renamed.iter("connection") for a in ("incomingRoad", "connectingRoad")]
    assert references and all(r in road_ids or r == "1" for r in references)


def test_crosscheck_names_a_map_crdesigner_cannot_read(maps, tool, capsys, monkeypatch) -> None:
    """A crdesigner parser failure is one line on stderr naming the map, exit status 1."""
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_parser import parser

    def failing(*args, **kwargs):
        raise KeyError("lane")

    monkeypatch.setattr(parser, "parse_opendrive", failing)
    assert tool.main([str(maps["no_geo"])]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(maps["no_geo"]) in err and "KeyError" in err


def test_crdesigner_copy_turns_constant_spirals_into_arcs_and_lines(maps) -> None:
    from lxml import etree

    from converters.crdesigner_bridge import crdesigner_copy

    data, original = crdesigner_copy(maps["odd_geometry"].read_bytes())
    assert original == {}
    shapes = [g[0] for g in etree.fromstring(data).iter("geometry")]
    assert [s.tag for s in shapes] == ["arc", "line", "line", "paramPoly3"]
    assert float(shapes[0].get("curvature")) == 0.02
