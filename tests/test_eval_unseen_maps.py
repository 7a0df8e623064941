"""``cold-eval --map`` on small OpenDRIVE maps unlike the bundled ones: left-hand traffic
through a junction with a dead end, a one-way ring road (routes through a cycle), a lane
merge between lane sections, a paramPoly3 road under every error model, and a map whose
roads are all shorter than a drive. The maps are written into ``tmp_path``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cold_maps.cli import evaluate
from cold_maps.recording.recorder import METADATA_STATUS, read_detections, read_metadata

LANE_WIDTH_M = 3.5
RING_RADIUS_M = 50.0
FRAMES = 6
SENSOR_RANGE_M = 30.0
GT_STEP_M = 0.02
CLEAN_ERROR_M = GT_STEP_M / 2 + 1e-6  # error-free detections: only the GT resampling floor


def _lane(lane_id: int, pred: int | None, succ: int | None, width: str) -> str:
    links = (f'<predecessor id="{pred}"/>' if pred is not None else "") + (
        f'<successor id="{succ}"/>' if succ is not None else "")
    return f'<lane id="{lane_id}" type="driving" level="false"><link>{links}</link>{width}</lane>'


def _width(a: float, b: float = 0.0, c: float = 0.0, d: float = 0.0) -> str:
    return f'<width sOffset="0" a="{a}" b="{b}" c="{c}" d="{d}"/>'


def _section(s: float, left: list[str], right: list[str]) -> str:
    """``left`` from the outermost lane in, ``right`` from the centre out."""
    return (f'<laneSection s="{s}">' + (f"<left>{''.join(left)}</left>" if left else "")
            + '<center><lane id="0" type="none" level="false"/></center>'
            + (f"<right>{''.join(right)}</right>" if right else "") + "</laneSection>")


def _two_way(s: float = 0.0) -> str:
    return _section(s, [_lane(1, 1, 1, _width(LANE_WIDTH_M))], [_lane(-1, -1, -1, _width(LANE_WIDTH_M))])


def _link(kind: str, target: tuple[str, ...] | None) -> str:
    if target is None:
        return ""
    contact = f' contactPoint="{target[2]}"' if len(target) > 2 else ""
    return f'<{kind} elementType="{target[0]}" elementId="{target[1]}"{contact}/>'


def _road(road_id: str, length: float, geometry: str, sections: list[str], *, pred: tuple[str, ...] | None = None,
          succ: tuple[str, ...] | None = None, junction: str = "-1", rule: str = "RHT") -> str:
    return (f'<road name="r{road_id}" length="{length!r}" id="{road_id}" junction="{junction}" rule="{rule}">'
            f'<link>{_link("predecessor", pred)}{_link("successor", succ)}</link><type s="0" type="town"/>'
            f'<planView>{geometry}</planView><lanes>{"".join(sections)}</lanes></road>')


def _geometry(x: float, y: float, hdg: float, length: float, shape: str = "<line/>") -> str:
    return f'<geometry s="0" x="{x!r}" y="{y!r}" hdg="{hdg!r}" length="{length!r}">{shape}</geometry>'


def _document(parts: list[str]) -> str:
    return ('<?xml version="1.0" encoding="UTF-8"?><OpenDRIVE><header revMajor="1" revMinor="6" name="t" '
            'version="1.0" north="0" south="0" east="0" west="0"/>' + "".join(parts) + "</OpenDRIVE>")


def t_junction(rule: str) -> str:
    """Road 1 (300 m along +x) into junction 9, on to road 2 (straight, 300 m) or left into
    road 3 (15 m, a dead end); the junction's connecting roads carry the lane that drives
    along +s (id 1 under LHT, -1 under RHT) only, so they are one-way."""
    lane = 1 if rule == "LHT" else -1
    side = "left" if lane > 0 else "right"

    def connecting(road_id: str, length: float, geometry: str, to: str) -> str:
        section = (f'<laneSection s="0"><{side}>{_lane(lane, lane, lane, _width(LANE_WIDTH_M))}</{side}>'
                   '<center><lane id="0" type="none" level="false"/></center></laneSection>')
        return _road(road_id, length, geometry, [section], pred=("road", "1", "end"), succ=("road", to, "start"),
                     junction="9", rule=rule)

    turn_m = 10.0 * math.pi
    roads = [
        _road("1", 300.0, _geometry(0, 0, 0, 300.0), [_two_way()], succ=("junction", "9"), rule=rule),
        _road("2", 300.0, _geometry(320, 0, 0, 300.0), [_two_way()], pred=("junction", "9"), rule=rule),
        _road("3", 15.0, _geometry(320, 20, math.pi / 2, 15.0), [_two_way()], pred=("junction", "9"), rule=rule),
        connecting("100", 20.0, _geometry(300, 0, 0, 20.0), "2"),
        connecting("101", turn_m, _geometry(300, 0, 0, turn_m, '<arc curvature="0.05"/>'), "3"),
    ]
    links = "".join(f'<connection id="{i}" incomingRoad="1" connectingRoad="{road}" contactPoint="start">'
                    f'<laneLink from="{lane}" to="{lane}"/></connection>' for i, road in enumerate(("100", "101")))
    return _document([*roads, f'<junction id="9" name="j">{links}</junction>'])


def ring() -> str:
    """Four one-way quarter arcs (two lanes, counter-clockwise, radius 50 m) joined into a loop."""
    quarter = math.pi * RING_RADIUS_M / 2
    starts = [(RING_RADIUS_M, 0.0, math.pi / 2), (0.0, RING_RADIUS_M, math.pi), (-RING_RADIUS_M, 0.0, -math.pi / 2),
              (0.0, -RING_RADIUS_M, 0.0)]
    section = _section(0, [], [_lane(-1, -1, -1, _width(LANE_WIDTH_M)), _lane(-2, -2, -2, _width(LANE_WIDTH_M))])
    roads = [_road(str(i + 1), quarter, _geometry(x, y, h, quarter, f'<arc curvature="{1 / RING_RADIUS_M!r}"/>'),
                   [section], pred=("road", str((i - 1) % 4 + 1), "end"), succ=("road", str((i + 1) % 4 + 1), "start"))
             for i, (x, y, h) in enumerate(starts)]
    return _document(roads)


def merge_and_curve() -> str:
    """A two-way paramPoly3 road (gentle S, 500 m) whose right side has two lanes up to
    s = 200 m, the outer one narrowing to zero by s = 250 m, and one lane after."""
    length = 500.0
    shape = (f'<paramPoly3 aU="0" bU="{length}" cU="0" dU="0" aV="0" bV="0" cV="60" dV="-40" '
             'pRange="normalized"/>')
    left = [_lane(1, 1, 1, _width(LANE_WIDTH_M))]
    taper = _width(LANE_WIDTH_M, 0.0, -3 * LANE_WIDTH_M / 50.0 ** 2, 2 * LANE_WIDTH_M / 50.0 ** 3)
    sections = [
        _section(0, left, [_lane(-1, None, -1, _width(LANE_WIDTH_M)), _lane(-2, None, None, _width(LANE_WIDTH_M))]),
        _section(200, left, [_lane(-1, -1, -1, _width(LANE_WIDTH_M)), _lane(-2, -2, None, taper)]),
        _section(250, left, [_lane(-1, -1, None, _width(LANE_WIDTH_M))]),
    ]
    return _document([_road("1", length, _geometry(0, 0, 0, length, shape), sections)])


def two_roads(length_m: float) -> str:
    """Two straight two-way roads of ``length_m`` in a row."""
    return _document([
        _road("1", length_m, _geometry(0, 0, 0, length_m), [_two_way()], succ=("road", "2", "start")),
        _road("2", length_m, _geometry(length_m, 0, 0, length_m), [_two_way()], pred=("road", "1", "end"))])


def _run(tmp_path_factory: pytest.TempPathFactory, name: str, text: str, *extra: str) -> tuple[int, Path]:
    folder = tmp_path_factory.mktemp(name)
    path = folder / f"{name}.xodr"
    path.write_text(text)
    out = folder / "out"
    status = evaluate.main(["--map", str(path), "--routes", "all", "--frames", str(FRAMES), "--gaps", "30",
                            "--interpolation", "hermite", "--no-plots", "--out", str(out), *extra])
    return status, out


def _scenarios(out: Path) -> tuple[dict, dict[tuple[str, str], dict]]:
    document = json.loads((out / "metrics.json").read_text())
    return document, {(r["fusion"], r["boundary"]): r for r in document["scenarios"]}


@pytest.fixture(scope="module")
def lht_run(tmp_path_factory):
    return _run(tmp_path_factory, "lht_junction", t_junction("LHT"))


@pytest.fixture(scope="module")
def ring_run(tmp_path_factory):
    return _run(tmp_path_factory, "ring", ring())


def test_left_hand_traffic_junction_with_dead_end(lht_run):
    status, out = lht_run
    assert status == 0
    document, records = _scenarios(out)
    assert document["partial"] is False
    for boundary in ("left", "right"):
        local = records[("local", boundary)]
        assert local["fused_frames"] == local["frames"] > 0  # every ego detection found its LHT lanelet
        assert local["max_error_m"] <= CLEAN_ERROR_M
        assert local["perception_range_m"] == pytest.approx(SENSOR_RANGE_M, abs=0.1)
        for fusion in ("convoy", "spline"):
            fused = records[(fusion, boundary)]
            assert fused["fused_frames"] > 0 and fused["max_error_m"] < 0.05
            assert fused["fusibility"]["precision"] == fused["fusibility"]["recall"] == 1.0
    summary = (out / "summary.md").read_text()
    # 8 lanes: roads 1-3 both ways and the two connecting roads; routes cannot start on the
    # 15 m dead end, the lanes driving into the junction's far side, or the turn.
    assert "covering 5 of 8 driving lanes" in summary


def test_ring_road_perception_range_across_the_seam(ring_run):
    """The converted ring is one closed lanelet per lane; the range along a border of
    radius r of the ego's 30 m along the lane centre (radius r_c) is 30 r / r_c."""
    status, out = ring_run
    assert status == 0
    _, records = _scenarios(out)
    frames = [line.split(",") for line in (out / "frames.csv").read_text().splitlines()[1:]]
    header = (out / "frames.csv").read_text().splitlines()[0].split(",")
    column = {name: i for i, name in enumerate(header)}
    ranges = [float(row[column["perception_range_m"]]) for row in frames if row[column["fusion"]] == "local"]
    assert len(ranges) == 2 * records[("local", "left")]["frames"]
    assert min(ranges) > 0
    lane_radii = {RING_RADIUS_M + LANE_WIDTH_M / 2, RING_RADIUS_M + 1.5 * LANE_WIDTH_M}
    expected = {round(SENSOR_RANGE_M * (c + side * LANE_WIDTH_M / 2) / c, 1) for c in lane_radii for side in (-1, 1)}
    assert {round(r, 1) for r in ranges} <= {e + d for e in expected for d in (-0.1, 0.0, 0.1)}
    assert records[("convoy", "left")]["perception_range_m"] > 45.0


def test_mcap_of_unseen_map_is_complete(ring_run):
    _, out = ring_run
    from mcap.reader import make_reader

    with open(out / "run.mcap", "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert {"/gt", "/fused", "/metrics", "/cold/detections", "/detections/ego"} <= {
        c.topic for c in summary.channels.values()}
    _, records = _scenarios(out)
    frames = [frame for frame, _ in read_detections(out / "run.mcap")]
    assert frames == list(range(records[("local", "left")]["frames"]))  # one per frame of every route, in order
    assert read_metadata(out / "run.mcap")[METADATA_STATUS]["status"] == "complete"


def test_merge_and_param_poly3_under_every_error_model(tmp_path_factory):
    status, out = _run(tmp_path_factory, "merge_ppoly", merge_and_curve(), "--noise", "0.05", "--lateral-offset",
                       "0.2", "--drop", "0.1", "--pose-xy", "0.1", "--heading-bias", "0.005", "--range-jitter", "1",
                       "--pose-yaw", "0.005", "--seed", "7")
    assert status == 0
    text = (out / "metrics.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    _, records = _scenarios(out)
    local = records[("local", "left")]
    # every ego detection that was not dropped (10 %) found its ground truth
    assert set(local["rejected"]) == {"ego_dropped"}
    assert local["fused_frames"] + local["rejected"]["ego_dropped"] == local["frames"]
    assert local["rejected"]["ego_dropped"] < local["frames"] / 3
    # a 0.2 m lateral offset plus 0.05 m noise: errors near 0.2 m, far below a lane width
    assert 0.1 < local["mean_error_m"] < 0.4
    for fusion in ("convoy", "spline"):
        fused = records[(fusion, "right")]
        assert fused["fused_frames"] > 0 and fused["max_error_m"] < 1.5


def test_map_shorter_than_the_plan_evaluates_what_fits(tmp_path_factory, capsys):
    status, out = _run(tmp_path_factory, "short", two_roads(40.0))
    assert status == 0
    result = capsys.readouterr().out.strip().splitlines()
    assert len(result) == 1 and "short: what did not fit the map is listed in summary.md" in result[0]
    _, records = _scenarios(out)
    # 6 frames (5 m) + 60 m spline coop + 35 m > 80 m; the convoy (25 m) fits, without its 25 m behind
    assert {fusion for fusion, _ in records} == {"local", "convoy"}
    summary = (out / "summary.md").read_text()
    assert "short: no distractors 25, 60 m ahead and behind" in summary
    assert "short: dropped spline-hermite-d30 (coops 60 m ahead): 6 frames need 100 m of route" in summary


def test_map_shorter_than_one_frame_fails_cleanly(tmp_path_factory, capsys):
    status, out = _run(tmp_path_factory, "tiny", two_roads(15.0))
    assert status == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "no drivable route" in err[0] and "(longest 30 m)" in err[0] and "even one frame needs 35 m" in err[0]
    assert not out.exists()


def test_too_many_frames_names_the_most_that_fit(tmp_path_factory, capsys):
    status, out = _run(tmp_path_factory, "long", two_roads(150.0), "--no-distractors", "--frames", "1000")
    assert status == 1
    # local: 30 m range + 5 m margin; the spline coop 60 m more; 10 frames per second at 10 m/s
    assert "at most 266 --frames fit (206 with every scenario)" in capsys.readouterr().err
    assert not out.exists()


@pytest.fixture(scope="module")
def ring_ground_truth(tmp_path_factory):
    from converters import load_lanelet2
    from gt_matching import GroundTruth

    path = tmp_path_factory.mktemp("ring_gt") / "ring.xodr"
    path.write_text(ring())
    return GroundTruth(*load_lanelet2(path))


@pytest.mark.parametrize("start_rad", [-0.3, -0.01, 0.5, 2.0])
def test_ring_lanelet_matched_across_its_seam(ring_ground_truth, start_rad):
    """Inner lane of the ring (borders at radius 50 and 53.5 m, counter-clockwise): a 30 m
    detection matches its lanelet wherever it starts, also across the closed lanelet's
    seam at angle 0, with range 30 r / r_c along the border of radius r; the same points
    in reverse order run against the lane."""
    centre_m = RING_RADIUS_M + LANE_WIDTH_M / 2
    angles = start_rad + SENSOR_RANGE_M / centre_m * np.linspace(0.0, 1.0, 301)
    left = RING_RADIUS_M * np.c_[np.cos(angles), np.sin(angles)]
    right = (RING_RADIUS_M + LANE_WIDTH_M) * np.c_[np.cos(angles), np.sin(angles)]
    pose = (centre_m * math.cos(start_rad), centre_m * math.sin(start_rad), start_rad + math.pi / 2)
    match = ring_ground_truth.match(left, right, pose)
    assert match.matched, match.mismatch
    errors = ring_ground_truth.errors(left, right, match, exact=True)
    assert errors.left.distances_m.max() < 1e-3 and errors.right.distances_m.max() < 1e-3
    for border, radius in ((errors.left, RING_RADIUS_M), (errors.right, RING_RADIUS_M + LANE_WIDTH_M)):
        assert border.arc_m[-1] - border.arc_m[0] == pytest.approx(SENSOR_RANGE_M * radius / centre_m, abs=0.05)
    backwards = ring_ground_truth.match(left[::-1], right[::-1], pose)
    assert not backwards.matched and "against the driving direction" in backwards.mismatch


def test_two_maps_with_one_name_are_refused(tmp_path, capsys):
    """Results are keyed by map name: two files named ring.xodr would pool into one row."""
    paths = [tmp_path / folder / "ring.xodr" for folder in ("a", "b")]
    for path in paths:
        path.parent.mkdir()
        path.write_text(ring())
    out = tmp_path / "out"
    assert evaluate.main(["--map", str(paths[0]), "--map", str(paths[1]), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "share the name 'ring'" in err[0] and err[0].endswith("(see cold-eval --help)")
    assert not out.exists()


def test_repeated_routes_are_noted_as_such(tmp_path_factory):
    """Two 40 m two-way roads in a row: a route of the plan's length starts only on the
    first lane of each direction, so a third route repeats one of them."""
    status, out = _run(tmp_path_factory, "repeats", two_roads(40.0), "--routes", "3")
    assert status == 0
    summary = (out / "summary.md").read_text()
    assert "repeats: 3 route(s) of 6 frames" in summary
    assert "covering 4 of 4 driving lanes (2 distinct: a repeated route drives the same lanes again" in summary
