"""gt_matching: lanelet matching, GT assembly and closest-point metrics on small
Lanelet2 maps built in Python with known geometry (offsets, arcs, a junction)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

pytest.importorskip("lanelet2")

from gt_matching import GroundTruth, MatchingConfig, MatchingError, evaluate_lane, match_lane
from gt_matching.polyline import as_polyline, closest_distances
from gt_matching.synthetic import LaneletMapBuilder, arc, offset_polyline, straight

WIDTH_M = 3.5
HALF_M = WIDTH_M / 2.0
VERTEX_STEP_M = 0.1


@dataclass(frozen=True)
class Lane:
    """Centreline vertices (m) and headings (rad) of a lane path, in driving order."""

    centre: np.ndarray
    headings: np.ndarray

    def then(self, other: Lane) -> Lane:
        return Lane(np.vstack((self.centre, other.centre[1:])), np.concatenate((self.headings, other.headings[1:])))

    def borders(self, start_m: float, end_m: float, shift_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Detected borders between arc lengths start_m and end_m of the centreline, moved
        shift_m to the left (concentric on arcs)."""
        s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(self.centre, axis=0).T))))
        keep = (s >= start_m - 1e-9) & (s <= end_m + 1e-9)
        centre, headings = self.centre[keep], self.headings[keep]
        return offset_polyline(centre, HALF_M + shift_m, headings), offset_polyline(centre, -HALF_M + shift_m, headings)


def lane(path: tuple[np.ndarray, np.ndarray]) -> Lane:
    return Lane(*path)


@dataclass(frozen=True)
class JunctionMap:
    """Approach (0,0)->(40,0) heading east, a junction with straight / left (r 20 m) /
    right (r 10 m) lanelets, and 40 m exits; a second, parallel approach lane to its left."""

    gt: GroundTruth
    map: object
    graph: object
    ids: dict[str, int]
    paths: dict[str, Lane]


@pytest.fixture(scope="session")
def junction() -> JunctionMap:
    paths = {
        "approach": lane(straight((0.0, 0.0), 0.0, 40.0, VERTEX_STEP_M)),
        "neighbour": lane(straight((0.0, WIDTH_M), 0.0, 40.0, VERTEX_STEP_M)),
        "straight": lane(straight((40.0, 0.0), 0.0, 20.0, VERTEX_STEP_M)),
        "right": lane(arc((40.0, 0.0), 0.0, 10.0, -math.pi / 2.0, VERTEX_STEP_M)),
        "left": lane(arc((40.0, 0.0), 0.0, 20.0, math.pi / 2.0, VERTEX_STEP_M)),
        "straight_exit": lane(straight((60.0, 0.0), 0.0, 40.0, VERTEX_STEP_M)),
        "right_exit": lane(straight((50.0, -10.0), -math.pi / 2.0, 40.0, VERTEX_STEP_M)),
        "left_exit": lane(straight((60.0, 20.0), math.pi / 2.0, 40.0, VERTEX_STEP_M)),
    }
    builder = LaneletMapBuilder()
    ids = {name: builder.add_lane(path.centre, WIDTH_M, path.headings) for name, path in paths.items()}
    lanelet_map, graph = builder.build()
    return JunctionMap(GroundTruth(lanelet_map, graph), lanelet_map, graph, ids, paths)


@pytest.fixture(scope="session")
def ring() -> tuple[GroundTruth, Lane, int]:
    """One lanelet on a circle of radius 30 m (counter-clockwise, 300 degrees), centre at the origin."""
    path = lane(arc((0.0, -30.0), 0.0, 30.0, math.radians(300.0), 0.05))
    builder = LaneletMapBuilder()
    lanelet_id = builder.add_lane(path.centre, WIDTH_M, path.headings)
    lanelet_map, graph = builder.build()
    return GroundTruth(lanelet_map, graph), path, lanelet_id


def route(junction: JunctionMap, *names: str) -> Lane:
    paths = [junction.paths[name] for name in names]
    joined = paths[0]
    for path in paths[1:]:
        joined = joined.then(path)
    return joined


def test_straight_offset_reads_offset_exact_and_resampled(junction: JunctionMap) -> None:
    left, right = route(junction, "approach").borders(5.0, 35.0, shift_m=0.30)
    exact = junction.gt.evaluate(left, right, (5.0, 0.3, 0.0), exact=True)
    resampled = junction.gt.evaluate(left, right, (5.0, 0.3, 0.0))
    for metrics, tolerance in ((exact, 1e-3), (resampled, 1e-2)):
        assert metrics.matched and metrics.mismatch is None
        assert metrics.lanelet_ids[0] == junction.ids["approach"]
        for border in (metrics.left, metrics.right):
            assert border.mean_error_m == pytest.approx(0.30, abs=tolerance)
            assert border.max_error_m == pytest.approx(0.30, abs=tolerance)
            assert border.points == len(left) and border.unmatched_points == 0
            assert border.length_m == pytest.approx(30.0, abs=0.02)


@pytest.mark.parametrize("shift_m", [0.30, -0.30])
def test_arc_offset_reads_offset(ring: tuple[GroundTruth, Lane, int], shift_m: float) -> None:
    gt, path, lanelet_id = ring
    left, right = path.borders(10.0, 100.0, shift_m=shift_m)
    pose = (*path.centre[200], float(path.headings[200]))
    exact = gt.evaluate(left, right, pose, exact=True)
    resampled = gt.evaluate(left, right, pose)
    assert exact.lanelet_ids == resampled.lanelet_ids == (lanelet_id,)
    for border in (exact.left, exact.right):
        assert border.mean_error_m == pytest.approx(0.30, abs=1e-3)
        assert border.max_error_m == pytest.approx(0.30, abs=1e-3)
    for border in (resampled.left, resampled.right):
        assert border.mean_error_m == pytest.approx(0.30, abs=1e-2)
        assert border.max_error_m == pytest.approx(0.30, abs=1e-2)
    # Along the GT border of radius 30 -/+ 1.75 m the detection spans (its angle) * radius.
    angles = np.unwrap(np.arctan2(left[[0, -1], 1], left[[0, -1], 0]))
    span = float(angles[1] - angles[0])
    assert exact.left.length_m == pytest.approx(span * (30.0 - HALF_M), abs=1e-3)
    assert exact.right.length_m == pytest.approx(span * (30.0 + HALF_M), abs=1e-3)
    assert resampled.left.length_m == pytest.approx(span * (30.0 - HALF_M), abs=0.02)


@pytest.mark.parametrize("step_m", [0.02, 0.1])
@pytest.mark.parametrize("lateral_m", [0.0, 0.25])
def test_resampling_floor_closed_form(junction: JunctionMap, step_m: float, lateral_m: float) -> None:
    """Points halfway between GT samples, lateral_m off a straight GT: the resampled distance
    is sqrt(lateral^2 + (step/2)^2), the exact one is lateral_m."""
    x = 10.0 + step_m * np.arange(200) + step_m / 2.0
    left = np.column_stack((x, np.full_like(x, HALF_M + lateral_m)))
    right = np.column_stack((x, np.full_like(x, -HALF_M + lateral_m)))
    resampled = evaluate_lane(junction.map, junction.graph, left, right, (10.0, 0.0, 0.0), step=step_m)
    exact = evaluate_lane(junction.map, junction.graph, left, right, (10.0, 0.0, 0.0), step=step_m, exact=True)
    floor = math.hypot(lateral_m, step_m / 2.0)
    for border in (resampled.left, resampled.right):
        assert border.mean_error_m == pytest.approx(floor, abs=1e-9)
        assert border.max_error_m <= floor + 1e-9
    for border in (exact.left, exact.right):
        assert border.max_error_m == pytest.approx(lateral_m, abs=1e-9)
    assert resampled.step_m == step_m


@pytest.mark.parametrize(
    ("turn", "end_m"), [("right", 40.0 + 10.0 * math.pi / 2.0 + 20.0), ("straight", 80.0), ("left", 40.0 + 10.0 * math.pi + 20.0)]
)
def test_junction_detection_follows_its_turn(junction: JunctionMap, turn: str, end_m: float) -> None:
    path = route(junction, "approach", turn, f"{turn}_exit")
    left, right = path.borders(15.0, end_m, shift_m=0.1)
    found = junction.gt.match(left, right, (15.0, 0.0, 0.0))
    assert found.matched
    assert found.lanelet_ids == (junction.ids["approach"], junction.ids[turn], junction.ids[f"{turn}_exit"])
    metrics = junction.gt.evaluate(left, right, (15.0, 0.0, 0.0), exact=True)
    for border in (metrics.left, metrics.right):
        assert border.max_error_m == pytest.approx(0.1, abs=1e-3)
        assert border.unmatched_points == 0


def test_pose_inside_junction_is_disambiguated_by_the_detection(junction: JunctionMap) -> None:
    """At 1 m into the junction all three turn lanelets contain the pose."""
    path = route(junction, "approach", "left", "left_exit")
    left, right = path.borders(41.0, 85.0)
    found = junction.gt.match(left, right, (41.0, 0.0, 0.0))
    assert set(found.pose_lanelet_ids) == {junction.ids[name] for name in ("straight", "left", "right")}
    assert found.matched
    assert found.lanelet_ids == (junction.ids["approach"], junction.ids["left"], junction.ids["left_exit"])


def test_gt_covers_detection_plus_margin(junction: JunctionMap) -> None:
    left, right = route(junction, "approach", "straight", "straight_exit").borders(10.0, 70.0)
    found = junction.gt.match(left, right, (10.0, 0.0, 0.0))
    margin = junction.gt.config.margin_m
    for detected, gt in ((left, found.left_gt), (right, found.right_gt)):
        _, arc_m = closest_distances(detected[[0, -1]], gt)
        gt_length = float(np.sum(np.hypot(*np.diff(gt, axis=0).T)))
        assert arc_m[0] >= margin and gt_length - arc_m[1] >= margin
        assert np.all(np.hypot(*np.diff(gt, axis=0).T) < 1.0), "GT border has a gap"


def test_margin_extends_gt_into_the_junction_after_the_detection(junction: JunctionMap) -> None:
    """The detection ends 1.6 m before the junction; its mid-line is then farther than
    max_distance_m from every junction lanelet, yet the GT still extends margin_m beyond."""
    left, right = route(junction, "approach").borders(10.0, 38.4)
    found = junction.gt.match(left, right, (10.0, 0.0, 0.0))
    assert found.lanelet_ids[0] == junction.ids["approach"]
    assert found.lanelet_ids[1] in {junction.ids[name] for name in ("straight", "left", "right")}
    _, arc_m = closest_distances(right[[-1]], found.right_gt)
    gt_length = float(np.sum(np.hypot(*np.diff(found.right_gt, axis=0).T)))
    assert gt_length - arc_m[0] >= junction.gt.config.margin_m


def test_detection_behind_the_pose_pulls_in_the_predecessor(junction: JunctionMap) -> None:
    path = route(junction, "approach", "right", "right_exit")
    left, right = path.borders(30.0, 60.0)
    pose = (*path.centre[int(round(42.0 / VERTEX_STEP_M))], float(path.headings[420]))
    found = junction.gt.match(left, right, pose)
    assert found.lanelet_ids[:2] == (junction.ids["approach"], junction.ids["right"])


def test_detection_in_the_adjacent_lane_is_flagged(junction: JunctionMap) -> None:
    left, right = route(junction, "neighbour").borders(5.0, 35.0)
    metrics = junction.gt.evaluate(left, right, (5.0, 0.0, 0.0))
    assert not metrics.matched
    assert str(junction.ids["neighbour"]) in metrics.mismatch and "x=5.000" in metrics.mismatch
    assert metrics.lanelet_ids[0] == junction.ids["approach"]
    for border in (metrics.left, metrics.right):
        assert border.mean_error_m == pytest.approx(WIDTH_M, abs=0.01)
        assert border.unmatched_points == border.points


def test_pose_between_lanes_is_decided_by_the_detection(junction: JunctionMap) -> None:
    left, right = route(junction, "neighbour").borders(5.0, 35.0)
    found = junction.gt.match(left, right, (5.0, HALF_M - 0.1, 0.0))
    assert set(found.pose_lanelet_ids) == {junction.ids["approach"], junction.ids["neighbour"]}
    assert found.matched and found.lanelet_ids == (junction.ids["neighbour"],)


def test_detection_off_every_lane_is_flagged(junction: JunctionMap) -> None:
    left, right = route(junction, "approach").borders(5.0, 35.0, shift_m=-2.5)
    metrics = junction.gt.evaluate(left, right, (5.0, 0.0, 0.0))
    assert not metrics.matched and "off the lane" in metrics.mismatch


def test_reversed_detection_is_flagged(junction: JunctionMap) -> None:
    left, right = route(junction, "approach").borders(5.0, 35.0)
    metrics = junction.gt.evaluate(right[::-1], left[::-1], (5.0, 0.0, 0.0))
    assert not metrics.matched and "against the driving direction" in metrics.mismatch
    assert metrics.left.length_m == pytest.approx(-30.0, abs=0.02)
    assert not junction.gt.match(right[::-1], left[::-1], (5.0, 0.0, 0.0)).matched


def test_outliers_are_counted_and_kept(junction: JunctionMap) -> None:
    left, right = route(junction, "approach").borders(5.0, 35.0)
    left = left.copy()
    left[100:110, 1] += 2.0
    metrics = junction.gt.evaluate(left, right, (5.0, 0.0, 0.0), exact=True)
    assert metrics.matched
    assert metrics.left.unmatched_points == 10 and metrics.left.points == len(left)
    assert metrics.left.max_error_m == pytest.approx(2.0, abs=1e-9)
    assert metrics.left.mean_error_m == pytest.approx(2.0 * 10 / len(left), abs=1e-9)
    assert metrics.right.unmatched_points == 0


def test_point_closer_to_another_lanes_border_is_unmatched(junction: JunctionMap) -> None:
    """With max distance 5 m only the other-border rule applies: right-border points moved
    2.5 m left are 1.0 m from the lane's left border, 2.5 m from their own."""
    gt = GroundTruth(junction.map, junction.graph, config=MatchingConfig(max_distance_m=5.0))
    left, right = route(junction, "approach").borders(5.0, 35.0)
    right = right.copy()
    right[:50, 1] += 2.5
    metrics = gt.evaluate(left, right, (5.0, 0.0, 0.0))
    assert metrics.right.unmatched_points == 50
    assert metrics.right.max_error_m == pytest.approx(2.5, abs=0.01)
    assert metrics.left.unmatched_points == 0


def test_errors_without_the_other_lane_check_keep_the_distances(junction: JunctionMap) -> None:
    """others=False: the same distances; only points beyond max_distance_m are unmatched.
    Right-border points moved 2.0 m left are 1.5 m from the left border (unmatched by the
    other-border rule), those moved 2.5 m right are beyond max_distance_m = 2.2 m."""
    gt = GroundTruth(junction.map, junction.graph, config=MatchingConfig(max_distance_m=2.2))
    left, right = route(junction, "approach").borders(5.0, 35.0)
    right = right.copy()
    right[:50, 1] += 2.0
    right[50:60, 1] -= 2.5
    match = gt.match(left, right, (5.0, 0.0, 0.0))
    checked, unchecked = gt.errors(left, right, match), gt.errors(left, right, match, others=False)
    np.testing.assert_array_equal(checked.right.distances_m, unchecked.right.distances_m)
    assert checked.right.metrics().unmatched_points == 60
    assert unchecked.right.metrics().unmatched_points == 10


def test_match_lane_function_agrees_with_ground_truth(junction: JunctionMap) -> None:
    left, right = route(junction, "approach", "right", "right_exit").borders(15.0, 75.0)
    found = match_lane(junction.map, junction.graph, left, right, (15.0, 0.0, 0.0))
    assert found.lanelet_ids == junction.gt.match(left, right, (15.0, 0.0, 0.0)).lanelet_ids
    np.testing.assert_array_equal(found.left_gt, junction.gt.match(left, right, (15.0, 0.0, 0.0)).left_gt)


@pytest.mark.parametrize(
    ("left", "right", "pose", "message"),
    [
        (np.empty((0, 2)), None, (5.0, 0.0, 0.0), "left border: needs at least 2 points"),
        (None, np.array([[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]]), (5.0, 0.0, 0.0), "right border: point 1 is not finite"),
        (np.zeros((4, 3)), None, (5.0, 0.0, 0.0), "left border: expected an (N, 2) array"),
        (np.zeros((4, 2)), None, (5.0, 0.0, 0.0), "left border: all 4 points coincide"),
        (None, None, (500.0, -20.0, 0.0), "no lanelet within 2.0 m of the pose (x=500.000 m, y=-20.000 m"),
        (None, None, (5.0, 0.0, math.pi), "runs within 0.785 rad of its yaw"),
        (None, None, (5.0, float("nan"), 0.0), "pose (x=5.0, y=nan, yaw=0.0) is not finite"),
        (None, None, (5.0, 0.0), "expected (x, y, yaw)"),
    ],
)
def test_bad_input_raises_matching_error(
    junction: JunctionMap, left: np.ndarray | None, right: np.ndarray | None, pose: tuple[float, ...], message: str
) -> None:
    good_left, good_right = route(junction, "approach").borders(5.0, 35.0)
    with pytest.raises(MatchingError) as error:
        junction.gt.evaluate(good_left if left is None else left, good_right if right is None else right, pose)
    assert message in str(error.value)


def test_as_polyline_tells_a_closed_ring_from_coinciding_points() -> None:
    """A ring ends where it starts (its middle is 1 m away): accepted as it is; points all
    within 1e-13 m of the first, the last farthest, coincide."""
    ring = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    assert np.array_equal(as_polyline("ring", ring), ring)
    with pytest.raises(MatchingError, match="dot: all 3 points coincide"):
        as_polyline("dot", np.array([[0.0, 0.0], [5e-14, 0.0], [0.0, 1e-13]]))


def test_match_many_equals_match_one_by_one(junction: JunctionMap) -> None:
    """Lanes at two poses (sharing lanelets), a reversed lane, one with bad input and one
    off every lanelet: each slot holds ``match``'s result bit for bit, or its error."""
    gt = junction.gt
    lanes = [
        (*route(junction, "approach").borders(5.0, 35.0), (5.0, 0.0, 0.0)),
        (*route(junction, "approach", "right", "right_exit").borders(15.0, 75.0), (15.0, 0.0, 0.0)),
        (*route(junction, "approach", "left", "left_exit").borders(15.0, 75.0), (15.0, 0.0, 0.0)),
        (*route(junction, "approach", "straight").borders(15.0, 55.0, shift_m=0.4), (15.0, 0.0, 0.0)),
        (*(border[::-1] for border in route(junction, "approach").borders(5.0, 35.0)[::-1]), (5.0, 0.0, 0.0)),
        (np.zeros((4, 2)), route(junction, "approach").borders(5.0, 35.0)[1], (5.0, 0.0, 0.0)),
        (*route(junction, "approach").borders(5.0, 35.0), (500.0, -20.0, 0.0)),
    ]
    found = gt.match_many(lanes)
    assert len(found) == len(lanes)
    for item, (left, right, pose) in zip(found, lanes):
        try:
            expected = gt.match(left, right, pose)
        except MatchingError as exc:
            assert isinstance(item, MatchingError) and str(item) == str(exc)
            continue
        assert not isinstance(item, MatchingError)
        assert (item.lanelet_ids, item.route_key, item.pose_lanelet_ids, item.matched, item.mismatch) == (
            expected.lanelet_ids, expected.route_key, expected.pose_lanelet_ids, expected.matched, expected.mismatch)
        np.testing.assert_array_equal(item.left_gt, expected.left_gt)
        np.testing.assert_array_equal(item.right_gt, expected.right_gt)
    assert [isinstance(item, MatchingError) for item in found] == [False] * 5 + [True] * 2
    assert found[1].lanelet_ids[-1] == junction.ids["right_exit"]
    assert found[2].lanelet_ids[-1] == junction.ids["left_exit"]
    assert not found[4].matched


def test_config_rejects_bad_thresholds() -> None:
    with pytest.raises(ValueError, match="step_m must be > 0"):
        MatchingConfig(step_m=0.0)
    with pytest.raises(ValueError, match="margin_m must be finite"):
        MatchingConfig(margin_m=float("inf"))


def test_coarse_near_returns_every_line_sample_within_reach(junction: JunctionMap) -> None:
    lines = junction.gt.lines
    rng = np.random.default_rng(3)
    for point in rng.uniform((-10.0, -60.0), (110.0, 70.0), (100, 2)):
        found = set(lines.coarse_near(point[None], 3.0).tolist())
        within = np.flatnonzero(np.hypot(*(lines.coarse - point).T) <= 3.0)
        assert set(within.tolist()) <= found
