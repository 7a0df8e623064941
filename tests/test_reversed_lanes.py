"""Lanes with ``direction="reversed"`` (issue 28): left and right in the driver's frame in
routes, the sensor, export's side column and the link gaps of ``info``/``check``."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from small_maps import REVERSED_LEFT_WIDTH_M, REVERSED_RIGHT_WIDTH_M, REVERSED_ROAD_M, reversed_lane_road

from cold_maps.cli.maps import main
from cold_maps.network.continuity import link_gaps
from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.network.lane_strip import LaneStrip
from cold_maps.network.route import route_from_lanes
from cold_maps.opendrive.parser import parse_opendrive
from cold_maps.simulation.sensor import LaneSensor

#: lane id → (y of the driver's left border, y of the right one) in m; both lanes run along -x
DRIVER_BORDERS_Y_M = {1: (0.0, REVERSED_LEFT_WIDTH_M), -1: (-REVERSED_RIGHT_WIDTH_M, 0.0)}


def _graph(**kwargs: bool):
    return build_lane_graph(parse_opendrive(reversed_lane_road(**kwargs).encode(), path="reversed.xodr"))


@pytest.mark.parametrize("lane_id", [1, -1])
def test_route_borders_are_the_drivers_left_and_right(lane_id: int) -> None:
    route = route_from_lanes(_graph(), [LaneKey("1", 0, lane_id)])
    left_y, right_y = DRIVER_BORDERS_Y_M[lane_id]
    assert route.centre[0, 0] == pytest.approx(REVERSED_ROAD_M) and route.centre[-1, 0] == pytest.approx(0.0)
    np.testing.assert_allclose(route.left[:, 1], left_y, atol=1e-9)
    np.testing.assert_allclose(route.right[:, 1], right_y, atol=1e-9)
    assert route.length == pytest.approx(REVERSED_ROAD_M)


@pytest.mark.parametrize("lane_id", [1, -1])
def test_sensor_sees_the_left_border_on_its_left(lane_id: int) -> None:
    route = route_from_lanes(_graph(), [LaneKey("1", 0, lane_id)])
    detection = LaneSensor().detect(LaneStrip.from_borders(route.left, route.right), 100.0)
    assert detection is not None
    width = abs(np.subtract(*DRIVER_BORDERS_Y_M[lane_id]))
    assert abs(detection.yaw) == pytest.approx(np.pi)
    np.testing.assert_allclose(detection.left[:, 1], width / 2, atol=1e-9)
    np.testing.assert_allclose(detection.right[:, 1], -width / 2, atol=1e-9)


def test_export_side_column(tmp_path: Path) -> None:
    path, out = tmp_path / "reversed.xodr", tmp_path / "borders.csv"
    path.write_text(reversed_lane_road())
    assert main(["export", str(path), "-o", str(out), "--step", "50"]) == 0
    with out.open() as file:
        rows = list(csv.DictReader(file))
    ys: dict[tuple[int, str], set[float]] = {}
    for row in rows:
        ys.setdefault((int(row["lane_id"]), row["side"]), set()).add(round(float(row["y"]), 6))
    assert ys == {(lane, side): {y} for lane, (left, right) in DRIVER_BORDERS_Y_M.items()
                  for side, y in (("left", left), ("right", right))}


def test_no_link_gap_where_a_reversed_lane_meets_a_standard_one() -> None:
    graph = _graph(lht_predecessor=True)
    assert list(graph.edges()) == [(LaneKey("1", 0, -1), LaneKey("2", 0, -1))]
    assert link_gaps(graph, tolerance_m=1e-6) == []


def test_lanes_driven_the_same_way_across_the_centre_lane_are_adjacent() -> None:
    from cold_maps.simulation.drive import lanes_beside

    graph = _graph()
    assert lanes_beside(graph, LaneKey("1", 0, -1)) == [("adjacent", LaneKey("1", 0, 1))]
    assert lanes_beside(graph, LaneKey("1", 0, 1)) == [("adjacent", LaneKey("1", 0, -1))]
