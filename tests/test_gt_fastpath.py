"""gt_matching fast paths against straightforward references on random frames of a grid
map: nearest GT samples, exact closest points, other lanes' borders closer, metrics, and
the mid-line arc lengths that decide the driving direction."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

pytest.importorskip("lanelet2")

from gt_matching import GroundTruth, LaneMatch
from gt_matching.geometry import LaneletGeometry
from gt_matching.ground_truth import _sequence_arc
from gt_matching.metrics import BorderErrors
from gt_matching.polyline import arc_lengths, closest_distances
from gt_matching.route import KD_TREE_CALLS
from gt_matching.synthetic import grid_network, sequence_borders

TOLERANCE_M = 1e-9
DETECTION_M = 60.0


@pytest.fixture(scope="module")
def grid() -> tuple[Any, Any, GroundTruth]:
    lanelet_map, graph = grid_network(3, 3)
    return lanelet_map, graph, GroundTruth(lanelet_map, graph)


def random_frames(lanelet_map: Any, graph: Any, count: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, tuple]]:
    """Detections (left, right, pose) along random routes: DETECTION_M of each border every
    0.1 m from a random start, with N(0, 5 cm) noise, every third with N(0, 0.6 m) noise
    on the left and the right one shifted 1.5 m (far points, other lanes' borders closer)."""
    import lanelet2

    rules = lanelet2.traffic_rules.create(
        lanelet2.traffic_rules.Locations.Germany, lanelet2.traffic_rules.Participants.Vehicle
    )
    lanelets = [ll for ll in lanelet_map.laneletLayer if rules.canPass(ll)]
    rng = np.random.default_rng(seed)
    frames = []
    while len(frames) < count:
        route = [lanelets[rng.integers(len(lanelets))]]
        while sum(LaneletGeometry.of(ll).length_m for ll in route) < DETECTION_M + 40.0 and graph.following(route[-1]):
            following = graph.following(route[-1])
            route.append(following[rng.integers(len(following))])
        left, right = sequence_borders(route, 0.1)
        s = arc_lengths(0.5 * (left + right))
        if s[-1] < DETECTION_M + 20.0:
            continue
        start = rng.uniform(0.0, s[-1] - DETECTION_M)
        keep = (s >= start) & (s <= start + DETECTION_M)
        mid = 0.5 * (left[keep] + right[keep])
        pose = (float(mid[0, 0]), float(mid[0, 1]), float(np.arctan2(*(mid[5] - mid[0])[::-1])))
        left, right = (b[keep] + rng.normal(0.0, 0.05, b[keep].shape) for b in (left, right))
        if len(frames) % 3 == 1:
            left, right = left + rng.normal(0.0, 0.6, left.shape), right + np.array([0.0, 1.5])
        frames.append((left, right, pose))
    return frames


def reference_errors(
    gt: GroundTruth, points: np.ndarray, side: str, match: LaneMatch, exact: bool
) -> BorderErrors:
    """Per-point errors by plain searches: every GT sample (each lanelet border resampled,
    joined) or every GT segment, and every sample of each other line of the map near the
    points (KD-trees)."""
    config = gt.config
    samples = match.left_gt_samples if side == "left" else match.right_gt_samples
    vertices = match.left_gt if side == "left" else match.right_gt
    resampled, nearest = cKDTree(samples).query(points)
    if exact:
        distances, arc = closest_distances(points, vertices)
    else:
        distances, arc = resampled, closest_distances(samples[nearest], vertices)[1]
    lanelets = [gt._geometry[key] for key in match.route_key]
    ignored = {getattr(g, f"{side}_line") for g in lanelets} | {
        int(line.id)
        for g in lanelets
        for other in gt.routing_graph.conflicting(g.lanelet)
        if hasattr(other, "leftBound")
        for line in (other.leftBound, other.rightBound)
    }
    low, high = points.min(axis=0) - resampled.max(), points.max(axis=0) + resampled.max()
    other = np.full(len(points), np.inf)
    for line, slot in gt.lines.slot_of_line.items():
        line_vertices = gt.lines.vertices[slot]
        near = np.all(line_vertices.max(axis=0) >= low) and np.all(line_vertices.min(axis=0) <= high)
        if line not in ignored and near:
            other = np.minimum(other, cKDTree(gt.lines.samples(slot, config.step_m)).query(points)[0])
    unmatched = (distances > config.max_distance_m) | (other < resampled - config.other_border_margin_m)
    return BorderErrors(distances_m=distances, arc_m=arc, unmatched=unmatched)


def test_errors_and_metrics_equal_brute_force(grid: tuple[Any, Any, GroundTruth]) -> None:
    lanelet_map, graph, gt = grid
    unmatched = 0
    for left, right, pose in random_frames(lanelet_map, graph, 12, seed=3):
        match = gt.match(left, right, pose)
        # The first calls search windows; past KD_TREE_CALLS resampled ones the KD-tree answers.
        for repeats, exact in ((1, True), (KD_TREE_CALLS + 2, False), (1, True)):
            expected = {
                side: reference_errors(gt, points, side, match, exact)
                for side, points in (("left", left), ("right", right))
            }
            for _ in range(repeats):
                errors = gt.errors(left, right, match, exact=exact)
                for found, reference in ((errors.left, expected["left"]), (errors.right, expected["right"])):
                    np.testing.assert_allclose(found.distances_m, reference.distances_m, rtol=0, atol=TOLERANCE_M)
                    np.testing.assert_allclose(found.arc_m, reference.arc_m, rtol=0, atol=TOLERANCE_M)
                    np.testing.assert_array_equal(found.unmatched, reference.unmatched)
                    metrics, distances = found.metrics(), reference.distances_m
                    assert metrics.mean_error_m == pytest.approx(np.mean(distances), abs=TOLERANCE_M)
                    assert metrics.rmse_m == pytest.approx(np.sqrt(np.mean(distances**2)), abs=TOLERANCE_M)
                    assert metrics.p95_error_m == pytest.approx(np.percentile(distances, 95.0), abs=TOLERANCE_M)
                    assert metrics.max_error_m == np.max(distances)
                    assert metrics.unmatched_points == np.count_nonzero(reference.unmatched)
            unmatched += sum(int(np.count_nonzero(r.unmatched)) for r in expected.values())
    assert unmatched > 0  # the shifted detections exercise the other-lane check


def test_sequence_arc_equals_per_point_search(grid: tuple[Any, Any, GroundTruth]) -> None:
    lanelet_map, graph, gt = grid
    rng = np.random.default_rng(5)
    for left, right, pose in random_frames(lanelet_map, graph, 6, seed=4):
        lanelets = [gt._geometry[key] for key in gt.match(left, right, pose).route_key]
        points = 0.5 * (left + right)[::20] + rng.normal(0.0, 0.3, (len(left[::20]), 2))
        expected = []
        for point in points:
            gaps = [np.min(np.hypot(*(g.centre - point).T)) for g in lanelets]
            k = int(np.argmin(gaps))
            vertex = int(np.argmin(np.hypot(*(lanelets[k].centre - point).T)))
            expected.append(sum(g.length_m for g in lanelets[:k]) + lanelets[k].centre_arc_m[vertex])
        found = _sequence_arc(lanelets, lambda g: g.centre_nearest(points))
        np.testing.assert_allclose(found, expected, rtol=0, atol=TOLERANCE_M)


@pytest.mark.parametrize("kept", [None, 3])
def test_preparing_on_first_use_gives_the_same_matches_and_errors(grid: tuple[Any, Any, GroundTruth],
                                                                  kept: int | None,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """prepare_all=False builds lanelet geometry, border samples, clearances and KD-trees
    only for the lanelets and lines a frame needs, keeping the latest ``PART_CACHE_SIZE``
    border parts and ``GEOMETRY_CACHE_SIZE`` lanelets (``kept``: so few that they are
    dropped and built again, also within one match), and without a routing graph
    the relations only for the lanelets a frame reaches; matches and errors (other-lane
    check included) are bit-identical, also for a match made by another GroundTruth of the map."""
    from dataclasses import replace

    from gt_matching import MatchingError, ground_truth

    if kept is not None:
        monkeypatch.setattr(ground_truth, "PART_CACHE_SIZE", kept)
        monkeypatch.setattr(ground_truth, "GEOMETRY_CACHE_SIZE", kept)
    lanelet_map, graph, prepared = grid
    lazy = GroundTruth(lanelet_map, graph, prepare_all=False)
    no_graph = GroundTruth(lanelet_map, prepare_all=False)
    assert not lazy._parts and not lazy._geometry
    assert not lazy.lines._trees
    for left, right, pose in random_frames(lanelet_map, graph, 12, seed=7):
        match = prepared.match(left, right, pose)
        for first_use in (lazy, no_graph):
            lazy_match = first_use.match(left, right, pose)
            assert (lazy_match.route_key, lazy_match.matched, lazy_match.mismatch) == (
                match.route_key, match.matched, match.mismatch)
            np.testing.assert_array_equal(lazy_match.left_gt, match.left_gt)
            for exact in (True, False):
                expected = prepared.errors(left, right, match, exact=exact)
                found = first_use.errors(left, right, lazy_match, exact=exact)
                unseen = GroundTruth(lanelet_map, prepare_all=False).errors(left, right, match, exact=exact)
                for a, b, c in ((found.left, expected.left, unseen.left), (found.right, expected.right, unseen.right)):
                    for field in ("distances_m", "arc_m", "unmatched"):
                        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
                        np.testing.assert_array_equal(getattr(c, field), getattr(b, field))
    built = sum("clearances" in vars(part) for part in lazy._parts.values())
    assert 0 < built <= len(lazy._parts) < len(prepared._parts)
    assert 0 < len(lazy._geometry) < len(prepared._geometry)
    missing = max(lanelet.id for lanelet in lanelet_map.laneletLayer) + 1
    with pytest.raises(MatchingError, match=f"lanelets \\[\\({missing}, False\\)\\] of the match are not"):
        lazy.errors(left, right, replace(match, route_key=(*match.route_key, (missing, False))))
    if kept is not None:
        assert len(lazy._parts) == len(lazy.lines._trees) == len(lazy.lines._samples) == len(lazy._geometry) == kept


def test_routes_dropped_for_their_samples_give_the_same_errors(grid: tuple[Any, Any, GroundTruth],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Beyond ``ROUTE_CACHE_SAMPLES`` the older assembled routes keep only their borders' call
    counts (a budget of one sample: only the latest stays assembled); used again they are
    assembled anew and continue their counts, so the resampled distances (windows for a
    short border's first ``KD_TREE_CALLS`` calls, its KD-tree after) and the exact errors
    are bit-identical to those of a GroundTruth that keeps every route."""
    from gt_matching import ground_truth

    lanelet_map, graph, _ = grid
    frames = random_frames(lanelet_map, graph, 4, seed=5)
    found: dict[str, list[Any]] = {}
    routes: dict[str, Any] = {}
    for kind, budget in (("keeping", ground_truth.ROUTE_CACHE_SAMPLES), ("shedding", 1)):
        monkeypatch.setattr(ground_truth, "ROUTE_CACHE_SAMPLES", budget)
        gt = GroundTruth(lanelet_map, graph, prepare_all=False)
        found[kind] = []
        for _ in range(KD_TREE_CALLS + 2):
            for left, right, pose in frames:
                found[kind] += [gt.errors(left, right, gt.match(left, right, pose), exact=exact) for exact in (False, True)]
                assembled = sum(isinstance(route, ground_truth._Route) for route in gt._routes.values())
                assert assembled == (1 if kind == "shedding" else len(gt._routes))
        routes[kind] = {keys: route if isinstance(route, tuple) else (route.left.calls, route.right.calls)
                        for keys, route in gt._routes.items()}
    for expected, errors in zip(found["keeping"], found["shedding"], strict=True):
        for a, b in ((errors.left, expected.left), (errors.right, expected.right)):
            for field in ("distances_m", "arc_m", "unmatched"):
                np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert len(routes["keeping"]) == len(frames)
    assert min(min(pair) for pair in routes["keeping"].values()) > KD_TREE_CALLS
    assert routes["shedding"] == routes["keeping"]


def test_lanes_matched_at_one_pose_share_its_candidates(grid: tuple[Any, Any, GroundTruth]) -> None:
    """Every lane of a frame is matched at the ego's pose: Lanelet2's matching runs once per
    pose, and each lane's match equals that of a GroundTruth that never saw the pose."""
    from unittest import mock

    lanelet_map, graph, _ = grid
    gt = GroundTruth(lanelet_map, graph, prepare_all=False)
    for left, right, pose in random_frames(lanelet_map, graph, 6, seed=11):
        lanes = [(left, right), (left + 0.3, right + 0.3), (left[: len(left) // 2], right[: len(right) // 2])]
        with mock.patch.object(GroundTruth, "_find_candidates", autospec=True,
                               side_effect=GroundTruth._find_candidates) as find:
            matches = [gt.match(*lane, pose) for lane in lanes]
        assert find.call_count == 1
        for lane, match in zip(lanes, matches):
            fresh = GroundTruth(lanelet_map, graph, prepare_all=False).match(*lane, pose)
            assert (match.route_key, match.matched, match.mismatch) == (fresh.route_key, fresh.matched, fresh.mismatch)
            np.testing.assert_array_equal(match.left_gt, fresh.left_gt)
