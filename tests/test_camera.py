"""The camera lane sensor (issue 26): each visibility rule against a closed form on a map
built for it, the road-mark classification of borders, and the sensor profiles."""

from __future__ import annotations

import csv
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from camera_maps import LANE_WIDTH_M, Lane, one_road, write
from conftest import bundled_map

import fusion
from cold_maps.cli import evaluate
from cold_maps.evaluation.report import FRAMES_CSV_COLUMNS
from cold_maps.network.lane_graph import LaneKey, load_graph
from cold_maps.network.lane_strip import LaneStrip
from cold_maps.opendrive.parser import load_opendrive
from cold_maps.opendrive.road_marks import BoundaryType, classify_border
from cold_maps.simulation.camera import (END_REASONS, CameraSensor, behind_footprints, detection_window,
                                         detection_windows, lane_sensor)
from cold_maps.simulation.detection import obstacles_of
from cold_maps.simulation.drive import Track, VehicleState
from cold_maps.simulation.sensor import END_MAP, END_RANGE, LaneSensor
from cold_maps.simulation.sensor_profile import (
    BUILTIN_PROFILES,
    CAMERA,
    IDEAL,
    SensorProfile,
    load_profile,
)

EGO_LANE = LaneKey("1", 0, -1)
WIDE_OPEN = replace(CAMERA, name="wide", min_range_m=0.0, max_range_m=200.0, fov_half_angle_rad=0.5 * math.pi)
"""A camera that only the rule under test limits."""


def _track(tmp_path: Path, text: str, lane: LaneKey = EGO_LANE) -> tuple[object, Track]:
    graph = load_graph(write(tmp_path, "road", text))
    return graph, Track.build(graph, [lane])


def _two_lanes(**kwargs: object) -> str:
    return one_road(300.0, (Lane(1), Lane(-1)), **kwargs)


@pytest.mark.parametrize("alpha_deg, radius_m", [(25.0, 40.0), (15.0, 80.0), (35.0, 25.0)])
def test_a_border_leaves_the_field_of_view_where_its_bearing_reaches_alpha(tmp_path, alpha_deg, radius_m) -> None:
    """Camera on a circle of radius Rc (lane centre), heading along it; a border point on
    the circle of radius Rb at centre angle φ is seen at bearing α when
    Rc = Rb·cos(φ − α)/cos α, i.e. φ = α + arccos(Rc·cos α / Rb) (2α on the camera's own
    circle, arc length 2·Rc·α). The lane ends at the first border to get there."""
    alpha = math.radians(alpha_deg)
    graph, track = _track(tmp_path, one_road(2.5 * math.pi * radius_m, (Lane(-1),), curvature=1.0 / radius_m))
    centre = radius_m + LANE_WIDTH_M / 2
    angles = [alpha + math.acos(min(centre * math.cos(alpha) / rb, 1.0)) for rb in (radius_m, radius_m + LANE_WIDTH_M)]
    expected_m = centre * min(angles)
    sensor = CameraSensor(replace(WIDE_OPEN, fov_half_angle_rad=alpha), graph)
    detection, reason = sensor.read(track, 10.0, np.empty((0, 3)))
    assert reason == "field_of_view"
    assert expected_m - sensor.step_m - 1e-6 <= detection.end_station - 10.0 <= expected_m + 1e-6
    assert 2.0 * centre * alpha == pytest.approx(centre * (alpha + math.acos(math.cos(alpha))))


@pytest.mark.parametrize("vertical_radius_m, height_m", [(1000.0, 1.3), (2500.0, 1.3), (600.0, 2.0)])
def test_a_crest_hides_the_road_beyond_the_tangent_from_the_camera(tmp_path, vertical_radius_m, height_m) -> None:
    """Camera at height h on the top of a vertical curve z = −s²/(2·R_v): the sight line
    grazes the road √(2·R_v·h) ahead; the border beyond is hidden."""
    graph, track = _track(tmp_path, _two_lanes(elevation_c=-0.5 / vertical_radius_m))
    sensor = CameraSensor(replace(WIDE_OPEN, camera_height_m=height_m), graph)
    detection, reason = sensor.read(track, 0.0, np.empty((0, 3)))
    tangent_m = math.sqrt(2.0 * vertical_radius_m * height_m)
    assert reason == "crest"
    assert detection.end_station == pytest.approx(tangent_m, rel=0.02)
    flat_graph, flat = _track(tmp_path, _two_lanes())
    _, flat_reason = CameraSensor(replace(WIDE_OPEN, camera_height_m=height_m), flat_graph).read(flat, 0.0,
                                                                                                  np.empty((0, 3)))
    assert flat_reason == "range"


@pytest.mark.parametrize("distance_m, width_m", [(20.0, 1.8), (12.0, 2.5), (30.0, 1.8)])
def test_a_vehicle_ahead_hides_the_lane_borders_beyond_d_times_w_lane_over_w(tmp_path, distance_m, width_m) -> None:
    """A vehicle of width w centred in the lane of width W, its rear d ahead of the camera:
    the sight line to a border point x ahead passes the rear at W/2·d/x from the lane
    centre, inside the vehicle for x >= d·W/w."""
    graph, track = _track(tmp_path, _two_lanes())
    profile = replace(WIDE_OPEN, vehicle_width_m=width_m)
    sensor = CameraSensor(profile, graph)
    station = 50.0
    x, y, yaw = track.strip.pose(station)
    vehicle = np.array([[x + distance_m + profile.vehicle_length_m / 2, y, yaw]])
    detection, reason = sensor.read(track, station, vehicle)
    hidden_from_m = distance_m * LANE_WIDTH_M / width_m
    assert reason == "occlusion"
    assert hidden_from_m - sensor.step_m - 1e-6 <= detection.left[-1, 0] < hidden_from_m
    assert detection.right[-1, 0] < hidden_from_m
    _, clear = sensor.read(track, station, vehicle + [0.0, 3.0 * LANE_WIDTH_M, 0.0])
    assert clear == "range"


def _border_types(tmp_path: Path, lanes: tuple[Lane, ...], lane_id: int = -1, junction: str = "-1") -> list[int]:
    road = load_opendrive(write(tmp_path, "marks", one_road(100.0, lanes, junction=junction))).roads["1"]
    s = np.array([10.0, 50.0])
    return [int(classify_border(road, 0, lane_id, side, s).type[0]) for side in ("inner", "outer")]


def test_road_marks_classify_borders_as_osi_boundary_types(tmp_path) -> None:
    """Lane -1's outer border between two driving lanes: type none → NO_LINE, broken →
    DASHED_LINE; unpainted beside a sidewalk → CURB, beside a shoulder → ROAD_EDGE, with
    nothing beyond → ROAD_EDGE outside a junction, NO_LINE inside one; the centre line's
    own mark (solid) is lane -1's inner border."""
    none = ((0.0, "none"),)
    assert _border_types(tmp_path, (Lane(1), Lane(-1, marks=none), Lane(-2))) == [
        BoundaryType.SOLID_LINE, BoundaryType.NO_LINE]
    assert _border_types(tmp_path, (Lane(1), Lane(-1, marks=((0.0, "broken"),)), Lane(-2)))[1] == \
        BoundaryType.DASHED_LINE
    assert _border_types(tmp_path, (Lane(1), Lane(-1, marks=none), Lane(-2, "sidewalk")))[1] == BoundaryType.CURB
    assert _border_types(tmp_path, (Lane(1), Lane(-1, marks=none), Lane(-2, "shoulder")))[1] == \
        BoundaryType.ROAD_EDGE
    assert _border_types(tmp_path, (Lane(1), Lane(-1, marks=none)))[1] == BoundaryType.ROAD_EDGE
    assert _border_types(tmp_path, (Lane(1), Lane(-1, marks=none)), junction="7")[1] == BoundaryType.NO_LINE
    # A zero-width lane between: the border beyond it counts (its mark, or what lies beyond).
    assert _border_types(tmp_path, (Lane(-1, marks=none), Lane(-2, width_m=0.0, marks=none),
                                    Lane(-3, "sidewalk")))[1] == BoundaryType.CURB


@pytest.mark.parametrize("mark, beyond, expected", [
    ("none", "driving", "unmarked"), ("broken", "driving", "range"), ("none", "sidewalk", "range")])
def test_the_camera_sees_painted_borders_and_physical_edges_only(tmp_path, mark, beyond, expected) -> None:
    """A none-marked border between two driving lanes is not detected (no lane at all), a
    dashed one is (dashes never end it), a curb beside a sidewalk is, as an edge."""
    graph, track = _track(tmp_path, one_road(300.0, (Lane(1), Lane(-1, marks=((0.0, mark),)), Lane(-2, beyond))))
    detection, reason = CameraSensor(CAMERA, graph).read(track, 50.0, np.empty((0, 3)))
    assert reason == expected
    assert (detection is None) == (expected == "unmarked")


@pytest.mark.parametrize("gap_m, ends", [(8.0, False), (20.0, True)])
def test_an_unmarked_stretch_ends_the_lane_only_when_longer_than_the_gap_tolerance(tmp_path, gap_m, ends) -> None:
    """Lane -1's outer border unpainted (a driving lane beyond) from s 80 to 80 + gap:
    bridged when the gap is at most the 12 m tolerance, else the lane ends at s 80."""
    marks = ((0.0, "solid"), (80.0, "none"), (80.0 + gap_m, "solid"))
    graph, track = _track(tmp_path, one_road(300.0, (Lane(1), Lane(-1, marks=marks), Lane(-2))))
    detection, reason = CameraSensor(CAMERA, graph).read(track, 50.0, np.empty((0, 3)))
    if ends:
        assert reason == "unmarked" and 80.0 - CAMERA.step_m - 1e-6 <= detection.end_station < 80.0
    else:
        assert reason == "range" and detection.end_station > 80.0 + gap_m


def test_the_camera_lane_starts_at_the_minimum_range_and_ends_at_the_maximum(tmp_path) -> None:
    """On a flat straight road with painted borders: from the first cross-section whose
    borders are both min_range away (√(r² − (W/2)²) ahead) to the last within max_range."""
    graph, track = _track(tmp_path, _two_lanes())
    detection, reason = CameraSensor(CAMERA, graph).read(track, 50.0, np.empty((0, 3)))
    half = LANE_WIDTH_M / 2
    first_m = math.sqrt(CAMERA.min_range_m**2 - half**2)
    last_m = math.sqrt(CAMERA.max_range_m**2 - half**2)
    assert reason == "range"
    assert first_m <= detection.left[0, 0] < first_m + CAMERA.step_m
    assert last_m - CAMERA.step_m < detection.left[-1, 0] <= last_m
    assert np.hypot(*detection.right.T).max() <= CAMERA.max_range_m


def test_a_lane_ending_in_view_ends_for_map_end(tmp_path) -> None:
    graph, track = _track(tmp_path, _two_lanes())
    detection, reason = CameraSensor(CAMERA, graph).read(track, track.length - 20.0, np.empty((0, 3)))
    assert reason == "map_end" and detection.end_station == pytest.approx(track.length)


def test_the_ideal_profile_is_the_generic_sensor(tmp_path) -> None:
    graph, track = _track(tmp_path, _two_lanes(curvature=1.0 / 60.0))
    sensor = lane_sensor(IDEAL, graph)
    assert sensor == LaneSensor()
    got, reason = sensor.read(track, 12.3, np.array([[20.0, 0.0, 0.0]]))
    today = LaneSensor().detect(track.strip, 12.3)
    assert reason == "range" and np.array_equal(got.left, today.left) and np.array_equal(got.right, today.right)


def test_builtin_profiles_hold_the_issue_values() -> None:
    camera, highway = BUILTIN_PROFILES["camera"], BUILTIN_PROFILES["camera-highway"]
    assert (camera.min_range_m, camera.max_range_m, camera.camera_height_m) == (3.0, 50.0, 1.3)
    assert math.degrees(camera.fov_half_angle_rad) == pytest.approx(25.0)
    assert camera.lane_error.sigma_m(np.array([0.0]))[0] == pytest.approx(math.hypot(0.05, 0.01))
    assert replace(highway, name="camera", max_range_m=50.0) == camera
    assert IDEAL.lane_error.is_zero and IDEAL.kind == "ideal" and IDEAL.max_range_m == 30.0


def test_a_toml_file_sets_any_field(tmp_path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text('max_range_m = 70\ngap_tolerance_m = 4.5\n[lane_error]\nsigma_c0_m = 0.2\n', encoding="utf-8")
    profile = load_profile(str(path))
    assert profile == replace(CAMERA, name="mine", max_range_m=70.0, gap_tolerance_m=4.5,
                              lane_error=replace(CAMERA.lane_error, sigma_c0_m=0.2))
    path.write_text('base = "ideal"\nmax_range_m = 40\n', encoding="utf-8")
    assert load_profile(str(path)) == replace(IDEAL, name="mine", max_range_m=40.0)


@pytest.mark.parametrize("text, named", [
    ("max_rang_m = 3\n", "'max_rang_m'"), ("max_range_m = -1\n", "max_range_m"), ('step_m = "x"\n', "step_m"),
    ('kind = "lidar"\n', "kind"), ("[lane_error]\ntau_s = 0\n", "lane_error.tau_s"),
    ("[lane_error]\nsigma = 1\n", "lane_error.sigma"), ('base = "radar"\n', "base"), ("max_range_m = \n", "not TOML"),
    ("min_range_m = 60\n", "min_range_m")])
def test_a_bad_toml_file_is_one_line_naming_the_key(tmp_path, text, named) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError) as error:
        load_profile(str(path))
    message = str(error.value)
    assert named in message and str(path) in message and "\n" not in message


def test_unknown_profile_names_the_choices() -> None:
    with pytest.raises(ValueError, match="camera-highway"):
        load_profile("lidar")
    with pytest.raises(ValueError, match="sensor profile x: fov_half_angle_rad"):
        SensorProfile(name="x", fov_half_angle_rad=4.0)


def test_cold_eval_with_a_camera_records_why_each_local_detection_ended(tmp_path) -> None:
    """frames.csv gains ``end_reason`` (set on the local rows only, one of the six), the
    summary lists the profile's parameters; without --sensor no such column exists."""
    out = tmp_path / "camera"
    args = ["--map", str(bundled_map("junction")), "--frames", "30", "--routes", "2", "--gaps", "30",
            "--interpolation", "paper", "--no-mcap", "--no-plots", "--workers", "1"]
    assert evaluate.main([*args, "--sensor", "camera", "--out", str(out)]) == 0
    with open(out / "frames.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    local = [row for row in rows if row["fusion"] == "local"]
    assert local and {row["end_reason"] for row in local} <= set(END_REASONS)
    assert all(row["end_reason"] == "" for row in rows if row["fusion"] != "local")
    assert f"junction: {CAMERA.describe()}" in (out / "summary.md").read_text()
    assert evaluate.main([*args, "--frames", "2", "--out", str(tmp_path / "ideal")]) == 0
    header = (tmp_path / "ideal" / "frames.csv").read_text().splitlines()[0]
    assert header == ",".join(FRAMES_CSV_COLUMNS)


def test_every_end_reason_of_the_sensors_is_one_a_detection_states() -> None:
    """The camera's and the ideal sensor's end reasons are exactly ``fusion``'s, split into
    those that reach the sensor's range (or the lane's end) and those that stop short of it."""
    assert set(END_REASONS) == set(fusion.types.END_REASONS)
    assert {END_RANGE, END_MAP} == set(fusion.types.END_REACHED)


@pytest.mark.parametrize("value, named", [("lidar", "unknown sensor 'lidar'"), ("nope.toml", "nope.toml: cannot read")])
def test_a_bad_sensor_is_a_usage_error(value, named, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        evaluate.main(["--map", "x.xodr", "--sensor", value])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and named in err and "(see cold-eval --help)" in err and "\n" not in err


def test_every_vehicle_sees_every_other_vehicle_but_itself() -> None:
    strip = LaneStrip.from_borders(np.array([[0.0, 1.0], [100.0, 1.0]]), np.array([[0.0, -1.0], [100.0, -1.0]]))
    track = Track((), strip, np.array([0.0, 100.0]))
    states = {name: VehicleState(name, "coop", track, station, LaneKey("1", 0, -1), station)
              for name, station in (("ego", 10.0), ("a", 30.0), ("b", 60.0))}
    obstacles = obstacles_of(states)
    assert obstacles["ego"][:, 0].tolist() == [30.0, 60.0] and obstacles["b"][:, 0].tolist() == [10.0, 30.0]


def test_a_lane_hidden_behind_a_vehicle_shortly_before_the_range_ends_for_the_occlusion(tmp_path) -> None:
    """Hidden from d·W/w = 44.2 m, out of range from 50 m: the gap's first 12 m are mostly
    occluded (every point past 44.2 m is), so the lane ended for the occlusion."""
    graph, track = _track(tmp_path, _two_lanes())
    x, y, yaw = track.strip.pose(50.0)
    rear_m = 22.75
    vehicle = np.array([[x + rear_m + CAMERA.vehicle_length_m / 2, y, yaw]])
    detection, reason = CameraSensor(CAMERA, graph).read(track, 50.0, vehicle)
    assert reason == "occlusion" and detection.left[-1, 0] < rear_m * LANE_WIDTH_M / CAMERA.vehicle_width_m


def test_the_detection_window_bridges_short_gaps_and_names_the_rule_that_hides_most() -> None:
    """Masks along one border every 1 m: a 5 m gap is bridged, an 8 m one ends the lane at
    the last visible point before it, for the rule set on most of its first 6 m."""
    along = np.arange(40.0)[None, :]
    range_bit, occlusion_bit, unmarked_bit = 1 << 0, 1 << 3, 1 << 4
    mask = np.zeros((1, 40), dtype=np.int64)
    mask[0, 5:9] = unmarked_bit  # gap from 4 to 9: 5 m
    mask[0, 20:27] = occlusion_bit  # gap from 19 to 27: 8 m
    mask[0, 23:27] |= range_bit
    assert detection_window(mask, along, 0, 6.0) == (19, 3)
    assert detection_window(mask, along, 0, 10.0) == (39, -1)
    mask[0, 30:] = range_bit  # open to the end
    assert detection_window(mask, along, 0, 10.0) == (29, 0)
    assert detection_window(mask, along, 5, 3.0) == (4, 4)  # hidden from the start: nothing reported


def test_occlusion_of_many_frames_is_every_segment_that_crosses_a_footprint() -> None:
    """Six frames of random cameras (any heading, so footprints straddle the bearing ±π behind
    some), footprints (one around each camera, ignored) and points: hidden exactly where
    shapely finds the camera-to-point segment crossing a footprint that does not hold the camera."""
    import shapely

    rng = np.random.default_rng(7)
    length_m, width_m = CAMERA.vehicle_length_m, CAMERA.vehicle_width_m
    cameras = np.column_stack((rng.uniform(-50, 50, (6, 2)), rng.uniform(-math.pi, math.pi, 6)))
    counts = rng.integers(50, 400, 6)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    points = np.repeat(cameras[:, :2], counts, axis=0) + rng.uniform(-40, 40, (int(offsets[-1]), 2))
    obstacles = [np.vstack((np.column_stack((camera[:2] + rng.uniform(-25, 25, (8, 2)), rng.uniform(-4, 4, 8))),
                            [[camera[0] + 1.0, camera[1], rng.uniform(-4, 4)]])) for camera in cameras]
    owner = np.repeat(np.arange(6), counts)
    yaw = cameras[owner, 2]
    dx, dy = points[:, 0] - cameras[owner, 0], points[:, 1] - cameras[owner, 1]
    bearing = np.arctan2(-np.sin(yaw) * dx + np.cos(yaw) * dy, np.cos(yaw) * dx + np.sin(yaw) * dy)
    hidden = behind_footprints(points, np.hypot(dx, dy), bearing, offsets, cameras, obstacles, length_m, width_m)
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [0.5 * length_m, 0.5 * width_m]
    expected = np.zeros(len(points), dtype=bool)
    for f, camera in enumerate(cameras):
        segments = shapely.linestrings([[camera[:2], point] for point in points[offsets[f]:offsets[f + 1]]])
        for x, y, heading in obstacles[f]:
            turn = np.array([[math.cos(heading), math.sin(heading)], [-math.sin(heading), math.cos(heading)]])
            box = shapely.Polygon(corners @ turn + [x, y])
            if not box.contains(shapely.Point(camera[:2])):
                expected[offsets[f]:offsets[f + 1]] |= shapely.intersects(segments, box)
    assert 0 < expected.sum() < len(points) and np.array_equal(hidden, expected)


def test_the_detection_windows_of_frames_are_each_frame_s_window() -> None:
    """Frames of 10 to 40 candidates padded with garbage to one table: each frame's (last
    candidate, reason) is :func:`detection_window` of its own candidates."""
    rng = np.random.default_rng(3)
    counts = np.array([40, 10, 25, 33, 17])
    starts = np.array([0, 3, 24, 5, 0])
    hidden = rng.integers(0, 32, (5, 2, 40)) * (rng.random((5, 2, 40)) < 0.3)
    along = np.cumsum(rng.uniform(0.5, 1.5, (5, 2, 40)), axis=2)
    ends, whys = detection_windows(hidden, along, counts, starts, 3.0)
    expected = [detection_window(hidden[f, :, :count], along[f, :, :count], int(start), 3.0)
                for f, (count, start) in enumerate(zip(counts, starts))]
    assert list(zip(ends.tolist(), whys.tolist())) == expected and {why for _, why in expected} != {-1}
