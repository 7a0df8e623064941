"""gt_matching property tests (hypothesis): distance bounds of resampling, exact search
windows, metric orderings, and invariance of the metrics under a rigid motion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

pytest.importorskip("lanelet2")

from gt_matching import GroundTruth, MatchingConfig
from gt_matching.metrics import BorderMetrics
from gt_matching.polyline import closest_distances, resample, windowed_distances
from gt_matching.synthetic import LaneletMapBuilder, arc, offset_polyline, straight

WIDTH_M = 3.5


def curved_path(radius_m: float, turn_rad: float, vertex_step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """20 m straight, an arc, 20 m straight: centreline vertices (m) and headings (rad)."""
    first, first_h = straight((0.0, 0.0), 0.0, 20.0, vertex_step_m)
    bend, bend_h = arc(tuple(first[-1]), 0.0, radius_m, turn_rad, vertex_step_m)
    last, last_h = straight(tuple(bend[-1]), float(bend_h[-1]), 20.0, vertex_step_m)
    return np.vstack((first, bend[1:], last[1:])), np.concatenate((first_h, bend_h[1:], last_h[1:]))


paths = st.builds(
    curved_path,
    radius_m=st.floats(10.0, 200.0),
    turn_rad=st.floats(-math.pi / 2.0, math.pi / 2.0).filter(lambda t: abs(t) > 1e-3),
    vertex_step_m=st.floats(0.01, 2.0),
)


@settings(max_examples=40, deadline=None)
@given(path=paths, step_m=st.floats(0.01, 0.5), offsets=st.lists(st.floats(-1.5, 1.5), min_size=1, max_size=40))
def test_resampled_distance_is_within_half_a_step_above_exact(
    path: tuple[np.ndarray, np.ndarray], step_m: float, offsets: list[float]
) -> None:
    centre, headings = path
    picks = np.linspace(0, len(centre) - 1, len(offsets)).astype(int)
    points = np.vstack([offset_polyline(centre[[i]], d, headings[[i]]) for i, d in zip(picks, offsets)])
    points += np.array([0.013, -0.007])  # off the vertices
    exact, _ = closest_distances(points, centre)
    samples, _ = resample(centre, step_m)
    assert np.all(np.hypot(*np.diff(samples, axis=0).T) <= step_m + 1e-9)
    resampled, nearest = cKDTree(samples).query(points)
    assert np.all(exact <= resampled + 1e-12)
    assert np.all(resampled <= exact + step_m / 2.0 + 1e-9)
    sample_arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(samples, axis=0).T))))
    windowed, _ = windowed_distances(points, centre, sample_arc[nearest], reach_m=step_m)
    np.testing.assert_allclose(windowed, exact, atol=1e-9)


@given(
    distances=st.lists(st.floats(0.0, 100.0), min_size=1, max_size=200),
    length_m=st.floats(-100.0, 100.0),
)
def test_border_metrics_orderings(distances: list[float], length_m: float) -> None:
    values = np.array(distances)
    unmatched = values > 1.5
    metrics = BorderMetrics.from_distances(values, unmatched, length_m)
    tolerance = 1e-9 * max(1.0, metrics.max_error_m)
    assert metrics.max_error_m >= metrics.p95_error_m - tolerance
    assert metrics.p95_error_m >= values.min() - tolerance
    assert metrics.max_error_m >= metrics.rmse_m - tolerance
    assert metrics.rmse_m >= metrics.mean_error_m - tolerance
    assert metrics.mean_error_m == pytest.approx(float(np.mean(values)))
    assert metrics.points == len(values) and metrics.unmatched_points == int(unmatched.sum())
    assert metrics.length_m == length_m


def rigid(points: np.ndarray, angle: float, shift: tuple[float, float]) -> np.ndarray:
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return points @ rotation.T + np.array(shift)


def evaluate_moved(
    path: tuple[np.ndarray, np.ndarray],
    detection: tuple[np.ndarray, np.ndarray],
    angle: float,
    shift: tuple[float, float],
    exact: bool,
) -> tuple[object, tuple[int, ...]]:
    centre, headings = path
    builder = LaneletMapBuilder()
    cut = len(centre) // 2
    ids = (
        builder.add_lane(rigid(centre[: cut + 1], angle, shift), WIDTH_M, headings[: cut + 1] + angle),
        builder.add_lane(rigid(centre[cut:], angle, shift), WIDTH_M, headings[cut:] + angle),
    )
    lanelet_map, graph = builder.build()
    pose = (*rigid(centre[[5]], angle, shift)[0], float(headings[5]) + angle)
    left, right = (rigid(border, angle, shift) for border in detection)
    return GroundTruth(lanelet_map, graph).evaluate(left, right, pose, exact=exact), ids


@settings(max_examples=12, deadline=None)
@given(
    path=st.builds(curved_path, radius_m=st.floats(15.0, 100.0), turn_rad=st.floats(-1.5, 1.5), vertex_step_m=st.just(0.5)),
    lateral_m=st.floats(-0.5, 0.5),
    noise_m=st.floats(0.0, 0.2),
    seed=st.integers(0, 2**16),
    angle=st.floats(-math.pi, math.pi),
    shift=st.tuples(st.floats(-5e3, 5e3), st.floats(-5e3, 5e3)),
)
def test_metrics_are_invariant_under_a_rigid_motion(
    path: tuple[np.ndarray, np.ndarray],
    lateral_m: float,
    noise_m: float,
    seed: int,
    angle: float,
    shift: tuple[float, float],
) -> None:
    centre, headings = path
    rng = np.random.default_rng(seed)
    keep = slice(5, len(centre) - 5)
    detection = tuple(
        offset_polyline(centre[keep], side * WIDTH_M / 2.0 + lateral_m, headings[keep])
        + rng.normal(0.0, noise_m, (len(centre[keep]), 2))
        for side in (1.0, -1.0)
    )
    results = {}
    for exact in (False, True):
        still, still_ids = evaluate_moved(path, detection, 0.0, (0.0, 0.0), exact)
        moved, moved_ids = evaluate_moved(path, detection, angle, shift, exact)
        assert still.matched and moved.matched
        assert [still_ids.index(i) for i in still.lanelet_ids] == [moved_ids.index(i) for i in moved.lanelet_ids]
        for a, b in ((still.left, moved.left), (still.right, moved.right)):
            for field in ("mean_error_m", "rmse_m", "max_error_m", "p95_error_m", "length_m"):
                assert getattr(a, field) == pytest.approx(getattr(b, field), abs=1e-6), field
            assert a.unmatched_points == b.unmatched_points and a.points == b.points
        results[exact] = still
    for e, r in ((results[True].left, results[False].left), (results[True].right, results[False].right)):
        assert e.max_error_m <= r.max_error_m + 1e-9
        assert e.mean_error_m <= r.mean_error_m + 1e-9
        assert r.max_error_m <= e.max_error_m + results[False].step_m / 2.0 + 1e-9


@settings(max_examples=15, deadline=None)
@given(
    path=st.builds(curved_path, radius_m=st.floats(10.0, 100.0), turn_rad=st.floats(-1.5, 1.5), vertex_step_m=st.floats(0.05, 2.0)),
    lateral_m=st.floats(-1.0, 1.0),
    noise_m=st.floats(0.0, 0.3),
    seed=st.integers(0, 2**16),
    step_m=st.sampled_from([0.02, 0.05, 0.2]),
)
def test_evaluate_equals_global_closest_point_search(
    path: tuple[np.ndarray, np.ndarray], lateral_m: float, noise_m: float, seed: int, step_m: float
) -> None:
    """Per-frame metrics equal a KD-tree over all GT samples (resampled) and a brute-force
    point-to-segment search over the whole GT polyline (exact), on two lanelets whose
    coarse vertices (up to 2 m on arcs from 10 m radius) make kinks."""
    centre, headings = path
    rng = np.random.default_rng(seed)
    keep = slice(3, len(centre) - 3)
    left, right = (
        offset_polyline(centre[keep], side * WIDTH_M / 2.0 + lateral_m, headings[keep])
        + rng.normal(0.0, noise_m, (len(centre[keep]), 2))
        for side in (1.0, -1.0)
    )
    builder = LaneletMapBuilder()
    cut = len(centre) // 3
    builder.add_lane(centre[: cut + 1], WIDTH_M, headings[: cut + 1])
    builder.add_lane(centre[cut:], WIDTH_M, headings[cut:])
    lanelet_map, graph = builder.build()
    gt = GroundTruth(lanelet_map, graph, config=MatchingConfig(step_m=step_m, max_distance_m=3.0))
    pose = (*centre[3], float(headings[3]))
    found = gt.match(left, right, pose)
    resampled = gt.evaluate(left, right, pose)
    exact = gt.evaluate(left, right, pose, exact=True)
    for points, samples, vertices, r, e in (
        (left, found.left_gt_samples, found.left_gt, resampled.left, exact.left),
        (right, found.right_gt_samples, found.right_gt, resampled.right, exact.right),
    ):
        assert np.all(np.hypot(*np.diff(samples, axis=0).T) <= step_m + 1e-9)
        global_resampled = cKDTree(samples).query(points)[0]
        global_exact = closest_distances(points, vertices)[0]
        assert r.mean_error_m == pytest.approx(float(global_resampled.mean()), abs=1e-12)
        assert r.max_error_m == pytest.approx(float(global_resampled.max()), abs=1e-12)
        assert e.mean_error_m == pytest.approx(float(global_exact.mean()), abs=1e-12)
        assert e.max_error_m == pytest.approx(float(global_exact.max()), abs=1e-12)


def kinked_path(turns: list[float], segment_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices of a polyline of equal segments turning by ``turns`` (rad) at its interior
    vertices (every vertex a kink), and the bisecting heading at each vertex (rad)."""
    headings = np.concatenate(([0.0], np.cumsum(turns)))
    steps = segment_m * np.column_stack((np.cos(headings), np.sin(headings)))
    vertices = np.vstack(([0.0, 0.0], np.cumsum(steps, axis=0)))
    bisectors = np.concatenate(([0.0], headings[:-1] + 0.5 * np.asarray(turns), headings[-1:]))
    return vertices, bisectors


@settings(max_examples=25, deadline=None)
@given(
    turns=st.lists(st.floats(-0.8, 0.8), min_size=3, max_size=8),
    segment_m=st.floats(2.0, 6.0),
    noise_m=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**16),
    step_m=st.sampled_from([0.02, 0.1]),
    long_border=st.booleans(),
)
def test_route_border_distances_equal_a_kd_tree_over_its_samples_on_sharp_kinks(
    turns: list[float], segment_m: float, noise_m: float, seed: int, step_m: float, long_border: bool
) -> None:
    """Windows, the kink rule (distance * tan(turning)) and the nearest-sample search
    (coarse samples, or a KD-tree as on long borders) together find every point's nearest
    sample: on a border of two lanelets whose every vertex turns by up to 0.8 rad, points
    up to ~3 m off it."""
    from unittest import mock

    from gt_matching import route
    from gt_matching.route import RouteBorder

    centre, headings = kinked_path(turns, segment_m)
    builder = LaneletMapBuilder()
    cut = len(centre) // 2
    builder.add_lane(centre[: cut + 1], WIDTH_M, headings[: cut + 1])
    builder.add_lane(centre[cut:], WIDTH_M, headings[cut:])
    lanelet_map, graph = builder.build()
    gt = GroundTruth(lanelet_map, graph, config=MatchingConfig(step_m=step_m, max_distance_m=3.0))
    parts = sorted((g for g in gt._geometry.values() if not g.key[1]), key=lambda g: float(np.hypot(*g.centre[0])))
    border = RouteBorder(gt.lines, [gt._part(g, "left") for g in parts], set())
    rng = np.random.default_rng(seed)
    along, _ = resample(border.vertices, 0.1)
    points = along + rng.normal(0.0, noise_m, along.shape)
    with mock.patch.object(route, "KD_TREE_SAMPLES", 0 if long_border else route.KD_TREE_SAMPLES):
        found = border.distances(points, exact=False)
    expected = cKDTree(border.samples).query(points)[0]
    np.testing.assert_allclose(found.distances, expected, rtol=0.0, atol=1e-12)
    exact = border.distances(points, exact=True)
    np.testing.assert_allclose(exact.distances, closest_distances(points, border.vertices)[0], rtol=0.0, atol=1e-9)


@given(
    values=st.lists(st.floats(0.0, 100.0), min_size=1, max_size=200),
    percent=st.one_of(st.sampled_from([0.0, 50.0, 95.0, 100.0]), st.floats(0.0, 100.0)),
)
def test_partial_sort_percentile_equals_numpy(values: list[float], percent: float) -> None:
    from gt_matching.metrics import _percentile

    expected = float(np.percentile(values, percent))
    assert _percentile(np.array(values), percent) == pytest.approx(expected, rel=1e-12, abs=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    path=paths,
    gaps=st.lists(st.floats(0.01, 4.0), min_size=2, max_size=300),
    noise_m=st.floats(0.0, 0.4),
    seed=st.integers(0, 2**16),
    long_border=st.booleans(),
)
def test_route_border_distances_equal_a_kd_tree_for_unevenly_spaced_points(
    path: tuple[np.ndarray, np.ndarray], gaps: list[float], noise_m: float, seed: int, long_border: bool
) -> None:
    """Seeds interpolated by point index miss where the detected points lie unevenly apart
    (a fused lane's gap, a sparse stretch): the window then leaves the point to the global
    search (coarse samples, or the KD-tree of a long border), and every point's distance is
    a KD-tree's over the border's samples."""
    from unittest import mock

    from gt_matching import route
    from gt_matching.route import RouteBorder

    centre, headings = path
    builder = LaneletMapBuilder()
    builder.add_lane(centre, WIDTH_M, headings)
    lanelet_map, graph = builder.build()
    gt = GroundTruth(lanelet_map, graph)
    (geometry,) = (g for g in gt._geometry.values() if not g.key[1])
    border = RouteBorder(gt.lines, [gt._part(geometry, "left")], set())
    vertices = border.vertices
    along = np.minimum(np.cumsum(gaps), float(np.sum(np.hypot(*np.diff(vertices, axis=0).T))))
    cum = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(vertices, axis=0).T))))
    points = np.column_stack((np.interp(along, cum, vertices[:, 0]), np.interp(along, cum, vertices[:, 1])))
    points += np.random.default_rng(seed).normal(0.0, noise_m, points.shape)
    expected = cKDTree(border.samples).query(points)[0]
    with mock.patch.object(route, "KD_TREE_SAMPLES", 0 if long_border else route.KD_TREE_SAMPLES):
        found = border.distances(points, exact=False, others=False)
    np.testing.assert_allclose(found.distances, expected, rtol=0.0, atol=1e-12)
