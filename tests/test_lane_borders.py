"""``route.lane_borders``: one lane's left and right border in driving order, the same
points ``cold-maps export`` writes for it (bundled junction, a reversed lane)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from conftest import bundled_map
from small_maps import REVERSED_LEFT_WIDTH_M, REVERSED_RIGHT_WIDTH_M, REVERSED_ROAD_M, reversed_lane_road

from cold_maps.cli.maps import COORDINATE_DECIMALS, main
from cold_maps.network.lane_graph import LaneKey
from cold_maps.network.route import lane_borders
from cold_maps.opendrive import load_opendrive

STEP_M = 0.5


def _export_rows(path: Path, out: Path, lane: tuple[str, int, int]) -> dict[str, np.ndarray]:
    """side → (N, 4) s, x, y, z of the lane's rows in ``cold-maps export``'s csv."""
    assert main(["export", str(path), "-o", str(out), "--step", str(STEP_M), "-q"]) == 0
    rows: dict[str, list[list[float]]] = {"left": [], "right": []}
    with out.open() as file:
        for row in csv.DictReader(file):
            if (row["road_id"], int(row["section"]), int(row["lane_id"])) == lane:
                rows[row["side"]].append([float(row[k]) for k in ("s", "x", "y", "z")])
    return {side: np.array(points) for side, points in rows.items()}


def _assert_same_as_export(path: Path, out: Path, lane: tuple[str, int, int]) -> None:
    borders = lane_borders(load_opendrive(path), lane, step=STEP_M, record_ends=True)
    rows = _export_rows(path, out, lane)
    tolerance = 0.6 * 10.0**-COORDINATE_DECIMALS
    for side, xyz in (("left", borders.left), ("right", borders.right)):
        assert rows[side].shape == (len(borders.s), 4)
        np.testing.assert_allclose(rows[side][:, 0], borders.s, atol=tolerance)
        np.testing.assert_allclose(rows[side][:, 1:], xyz, atol=tolerance)


@pytest.mark.parametrize("lane", [("1", 0, 1), ("1", 0, -1), ("101", 0, -1)])
def test_junction_lane_matches_export_and_the_driver_sees_left_on_the_left(tmp_path: Path, lane) -> None:
    path = bundled_map("junction")
    _assert_same_as_export(path, tmp_path / "borders.csv", lane)
    borders = lane_borders(load_opendrive(path), lane)
    assert borders.lane == LaneKey(*lane)
    centre = 0.5 * (borders.left[:, :2] + borders.right[:, :2])
    heading = np.diff(centre, axis=0)
    across = (borders.left - borders.right)[:-1, :2]
    # the left border lies to the left of the direction of travel: positive cross product
    assert np.all(heading[:, 0] * across[:, 1] - heading[:, 1] * across[:, 0] > 0.0)
    np.testing.assert_allclose(np.hypot(*across.T), 4.0, atol=1e-9)  # the junction's lanes are 4 m wide


@pytest.mark.parametrize(("lane_id", "left_y", "right_y"),
                         [(1, 0.0, REVERSED_LEFT_WIDTH_M), (-1, -REVERSED_RIGHT_WIDTH_M, 0.0)])
def test_reversed_lane_matches_export(tmp_path: Path, lane_id: int, left_y: float, right_y: float) -> None:
    path = tmp_path / "reversed.xodr"
    path.write_text(reversed_lane_road())
    _assert_same_as_export(path, tmp_path / "borders.csv", ("1", 0, lane_id))
    borders = lane_borders(load_opendrive(path), ("1", 0, lane_id))
    # both lanes are driven along -x: s decreases, left and right are swapped against +t
    assert borders.s[0] == pytest.approx(REVERSED_ROAD_M) and borders.s[-1] == 0.0
    assert borders.left[0, 0] == pytest.approx(REVERSED_ROAD_M) and borders.left[-1, 0] == pytest.approx(0.0)
    np.testing.assert_allclose(borders.left[:, 1], left_y, atol=1e-9)
    np.testing.assert_allclose(borders.right[:, 1], right_y, atol=1e-9)


@pytest.mark.parametrize(("lane", "message"), [(("9", 0, -1), "no road '9'"),
                                               (("1", 0, -7), "road 1: lane section 0 has no lane -7"),
                                               (("1", 3, -1), "road 1: no lane section 3")])
def test_an_absent_lane_is_named(lane, message: str) -> None:
    with pytest.raises((KeyError, IndexError), match=message):
        lane_borders(load_opendrive(bundled_map("junction")), lane)
