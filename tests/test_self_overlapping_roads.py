"""Roads that pass over themselves (issue 28): on a two-turn helical ramp the turns lie on
one another in x, y, and every detection along it is matched to its ground truth and
scored, never rejected for the other turn."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from small_maps import HELIX_APPROACH_M, HELIX_RADIUS_M, helical_ramp

from cold_maps.groundtruth.meter import GroundTruthMeter
from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.network.lane_strip import LaneStrip
from cold_maps.network.route import route_from_lanes
from cold_maps.opendrive.parser import parse_opendrive
from cold_maps.simulation.sensor import LaneSensor

STATION_STEP_M = 5.0
"""Spacing (m) of the ego stations measured along the ramp."""


def test_the_ramp_turns_lie_on_one_another() -> None:
    odr_map = parse_opendrive(helical_ramp().encode())
    graph = build_lane_graph(odr_map)
    lanes = [LaneKey(road, 0, -1) for road in ["1", *(str(10 + k) for k in range(8)), "2"]]
    route = route_from_lanes(graph, lanes)
    quarter = np.pi * HELIX_RADIUS_M / 2
    first = (route.distance >= HELIX_APPROACH_M) & (route.distance <= HELIX_APPROACH_M + 4 * quarter)
    second = route.distance >= HELIX_APPROACH_M + 4 * quarter
    lap = 4 * quarter * (HELIX_RADIUS_M + 1.75) / HELIX_RADIUS_M  # the lane centre runs 1.75 m outside
    np.testing.assert_allclose(route.length, 2 * HELIX_APPROACH_M + 2 * lap, rtol=1e-4)
    gaps, _ = cKDTree(route.centre[second]).query(route.centre[first])
    assert np.max(gaps) < 0.06  # the first turn lies within half a 0.1 m sample of the second in x, y


def ramp_strip_and_ground_truth(tmp_path: Path) -> tuple[LaneStrip, Any]:
    """The helical ramp's lane −1 from the approach over both turns as a strip, and the
    ground truth of the ramp (converted into a cache below ``tmp_path``)."""
    from converters import load_lanelet2
    from gt_matching import GroundTruth

    path = tmp_path / "ramp.xodr"
    path.write_text(helical_ramp())
    graph = build_lane_graph(parse_opendrive(path.read_bytes()))
    lanes = [LaneKey(road, 0, -1) for road in ["1", *(str(10 + k) for k in range(8)), "2"]]
    route = route_from_lanes(graph, lanes)
    ground_truth = GroundTruth(*load_lanelet2(path, cache_dir=tmp_path / "cache"))
    return LaneStrip.from_borders(route.left, route.right), ground_truth


def test_every_detection_on_the_ramp_is_matched_and_scored(tmp_path: Path) -> None:
    strip, ground_truth = ramp_strip_and_ground_truth(tmp_path)
    meter = GroundTruthMeter(ground_truth)
    sensor = LaneSensor()
    worst = []
    for station in np.arange(0.0, strip.length - sensor.range_m, STATION_STEP_M):
        detection = sensor.detect(strip, float(station))
        left, right = detection.to_world()
        measured = meter.measure(left, right, (detection.x, detection.y, detection.yaw))
        assert measured.gt_unmatched == "", f"station {station} m"
        worst.append(max(measured.left_errors_m.max(), measured.right_errors_m.max()))
    assert len(worst) > 50 and max(worst) <= 0.02


def test_a_detection_run_backwards_on_the_ramp_is_still_refused(tmp_path: Path) -> None:
    strip, ground_truth = ramp_strip_and_ground_truth(tmp_path)
    for station in (140.0, 280.0):  # on the first and on the second turn
        detection = LaneSensor().detect(strip, station)
        left, right = detection.to_world()
        match = ground_truth.match(left[::-1], right[::-1], (detection.x, detection.y, detection.yaw))
        assert not match.matched and "against the driving direction" in match.mismatch
