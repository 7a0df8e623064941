"""gt_matching.polyline: resampling, closest-point distances and fractions in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hypothesis import given
from hypothesis import strategies as st

from gt_matching.polyline import (
    angle_difference,
    arc_lengths,
    arc_lengths_many,
    at_fractions,
    closest_distances,
    closest_many,
    mid_line,
    resample,
    resample_many,
    windowed_distances,
)

L_SHAPE = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]])  # 7 m long, corner at 3 m


def test_resample_spacing_ends_and_segments() -> None:
    samples, segment = resample(L_SHAPE, 0.4)
    assert len(samples) == math.ceil(7.0 / 0.4) + 1
    np.testing.assert_allclose(samples[[0, -1]], L_SHAPE[[0, -1]])
    np.testing.assert_allclose(samples[8], [3.0, 0.2])  # 3.2 m along: 0.2 m up the second leg
    assert segment[7] == 0 and segment[8] == 1
    gaps = np.hypot(*np.diff(samples, axis=0).T)
    assert np.all(gaps <= 0.4 + 1e-12)
    assert gaps[-1] == pytest.approx(0.2)  # 7 = 17 * 0.4 + 0.2


def test_closest_distances_closed_form() -> None:
    points = np.array([[1.0, -2.0], [5.0, 1.0], [-3.0, -4.0], [3.0, 6.0]])
    distances, arc = closest_distances(points, L_SHAPE)
    np.testing.assert_allclose(distances, [2.0, 2.0, 5.0, 2.0])
    np.testing.assert_allclose(arc, [1.0, 4.0, 0.0, 7.0])


def test_windowed_equals_brute_force_within_reach() -> None:
    points = np.array([[1.0, -0.5], [3.5, 2.0]])
    near = np.array([1.1, 4.9])
    np.testing.assert_allclose(windowed_distances(points, L_SHAPE, near, 0.5), closest_distances(points, L_SHAPE))


def test_at_fractions_and_mid_line() -> None:
    np.testing.assert_allclose(at_fractions(L_SHAPE, np.array([0.0, 3.0 / 7.0, 0.5, 1.0])),
                               [[0.0, 0.0], [3.0, 0.0], [3.0, 0.5], [3.0, 4.0]])
    left = np.array([[0.0, 1.0], [10.0, 1.0]])
    right = np.array([[0.0, -3.0], [5.0, -3.0], [10.0, -3.0]])
    centre = mid_line(left, right, 2.5)
    np.testing.assert_allclose(centre, np.column_stack((np.linspace(0.0, 10.0, 5), np.full(5, -1.0))))


@pytest.mark.parametrize(("a", "b", "expected"), [(0.1, -0.1, 0.2), (math.pi - 0.1, -math.pi + 0.1, 0.2), (0.0, math.pi, math.pi)])
def test_angle_difference_wraps(a: float, b: float, expected: float) -> None:
    assert angle_difference(a, b) == pytest.approx(expected)


def test_nearest_distances_are_exact_on_rings_and_short_borders() -> None:
    from gt_matching.polyline import closest_distances, nearest_distances

    rng = np.random.default_rng(7)
    # a closed ring of radius 5 m in 40 chords: a point just before the seam is on the ring,
    # not 2·r·sin(angle/2) away at the other end (the windowed search's false alarm)
    angles = np.linspace(0.0, 2.0 * math.pi, 41)
    ring = 5.0 * np.column_stack((np.cos(angles), np.sin(angles)))
    near_seam = (0.1 * ring[-2] + 0.9 * ring[-1])[None, :]  # on the last chord, 8 cm before the seam
    distance, arc = nearest_distances(near_seam, ring)
    chord = float(np.hypot(*(ring[1] - ring[0])))
    assert distance[0] == pytest.approx(0.0, abs=1e-9) and arc[0] == pytest.approx(39.9 * chord, abs=1e-9)
    for _ in range(100):
        vertices = np.cumsum(rng.normal(size=(int(rng.integers(2, 25)), 2)), axis=0)
        points = rng.normal(scale=4.0, size=(30, 2))
        exact, _ = nearest_distances(points, vertices)
        brute, _ = closest_distances(points, vertices)
        np.testing.assert_allclose(exact, brute, atol=1e-12)


@given(st.integers(0, 2**32 - 1), st.lists(st.integers(2, 80), min_size=1, max_size=8))
def test_many_polylines_at_once_equal_one_by_one_bit_for_bit(seed: int, counts: list[int]) -> None:
    """Random walks (some steps repeated, some tiny, far from the origin) and a point near
    each: arc lengths and closest points as for each polyline alone."""
    rng = np.random.default_rng(seed)
    polylines = []
    for count in counts:
        steps = rng.normal(0.0, float(rng.choice([1e-3, 0.1, 2.0])), (count - 1, 2))
        steps[rng.random(count - 1) < 0.2] = 0.0
        polylines.append(np.vstack(([0.0, 0.0], np.cumsum(steps, axis=0))) + rng.normal(0.0, 1e4, 2))
    points = np.array([polyline[rng.integers(len(polyline))] + rng.normal(0.0, 1.0, 2) for polyline in polylines])
    assert np.concatenate([arc_lengths(p) for p in polylines]).tobytes() == arc_lengths_many(polylines).tobytes()
    distance, along = closest_many(points, polylines)
    for index, polyline in enumerate(polylines):
        alone = closest_distances(points[index:index + 1], polyline)
        assert (alone[0][0], alone[1][0]) == (distance[index], along[index])


@given(st.integers(0, 2**32 - 1), st.sampled_from([0.02, 0.5, 2.0, 7.3]))
def test_resample_many_is_resample_of_each_line_bit_for_bit(seed: int, step_m: float) -> None:
    """Lines of 2 to 40 vertices, steps from 1 mm to 2 m with repeated vertices (zero-length
    segments and whole zero-length lines), far from the origin."""
    rng = np.random.default_rng(seed)
    polylines = []
    for count in rng.integers(2, 40, int(rng.integers(1, 12))).tolist():
        steps = rng.normal(0.0, float(rng.choice([1e-3, 0.1, 2.0])), (count - 1, 2))
        steps[rng.random(count - 1) < float(rng.choice([0.2, 1.0]))] = 0.0
        polylines.append(np.vstack(([0.0, 0.0], np.cumsum(steps, axis=0))) + rng.normal(0.0, 1e4, 2))
    batched = resample_many(polylines, step_m)
    assert len(batched) == len(polylines)
    for polyline, points in zip(polylines, batched):
        assert points.tobytes() == resample(polyline, step_m)[0].tobytes()
