"""Ground-truth measuring fast paths against the straightforward computations they replace,
bit for bit: capped closest-point distances through a segment index, the meter's
per-border figures (perception range, distances ahead, points past the GT ends), and the
block API (``GroundTruthMeter.measure_many``) against measuring lane by lane and against a
brute-force search of the GT samples, on the lanes of real runs on bundled maps."""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cold_maps.groundtruth.meter import (FIGURE_BORDERS, GT_END_TOLERANCE_M, RANGE_CHORD_M, RANGE_ERROR_THRESHOLD_M,
                                         GroundTruthMeter, Measurement, _end_direction, ahead_of_m, border_figures,
                                         covered_length_m, gt_ends, points_past_ends)
from gt_matching.polyline import CAPPED_NEIGHBOURS, INDEX_PIECE_M, SegmentIndex, arc_lengths, closest_distances
from conftest import bundled_map


def _polyline(seed: int, count: int, scale: float) -> np.ndarray:
    """A random walk of ``count`` vertices with steps up to ``scale`` m, some repeated."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, scale, (count - 1, 2))
    steps[rng.random(count - 1) < 0.1] = 0.0
    return np.vstack(([0.0, 0.0], np.cumsum(steps, axis=0)))


@given(st.integers(0, 2**32 - 1), st.integers(2, 60), st.floats(0.01, 5.0), st.floats(0.0, 4.0))
def test_capped_distances_equal_the_brute_force_bit_for_bit(seed: int, count: int, scale: float, cap: float) -> None:
    vertices = _polyline(seed, count, scale)
    if not np.any(np.hypot(*np.diff(vertices, axis=0).T) > 0.0):
        vertices[-1] += 1.0
    rng = np.random.default_rng(seed + 1)
    low, high = vertices.min(axis=0) - 2.0 * cap - 1.0, vertices.max(axis=0) + 2.0 * cap + 1.0
    points = rng.uniform(low, high, (40, 2))
    points[:10] = vertices[rng.integers(0, count, 10)] + rng.normal(0.0, 0.01, (10, 2))
    expected = np.minimum(closest_distances(points, vertices)[0], cap)
    assert np.array_equal(SegmentIndex(vertices).capped(points, cap), expected)


@pytest.mark.parametrize("cap", [0.05, 1.5])
def test_capped_distances_among_more_pieces_than_asked_for_at_once_equal_the_brute_force(cap: float) -> None:
    """A zigzag of 5 cm segments: every point near it has more than ``CAPPED_NEIGHBOURS``
    piece midpoints within its search radius (the segments past the nearest ones are found
    too)."""
    vertices = np.column_stack((np.arange(60) * 0.05, 0.03 * (np.arange(60) % 2)))
    points = np.random.default_rng(5).uniform((0.3, -0.05), (2.7, 0.08), (50, 2))
    middles = 0.5 * (vertices[1:] + vertices[:-1])
    within = np.hypot(*(points[:, None, :] - middles[None]).transpose(2, 0, 1)) <= INDEX_PIECE_M / 2.0
    assert np.all(within.sum(axis=1) > CAPPED_NEIGHBOURS)
    expected = np.minimum(closest_distances(points, vertices)[0], cap)
    assert np.array_equal(SegmentIndex(vertices).capped(points, cap), expected)


def _covered_reference(border: np.ndarray, errors_m: np.ndarray, threshold_m: float) -> float:
    """``covered_length_m`` as first written: every run of points within the threshold, its
    chord ends through ``np.unique``."""
    within = np.concatenate(([False], errors_m <= threshold_m, [False]))
    edges = np.flatnonzero(np.diff(within.astype(np.int8)))
    arc = arc_lengths(border)
    total = 0.0
    for first, end in zip(edges[::2], edges[1::2]):
        stations = (arc[first:end] - arc[first]) // RANGE_CHORD_M
        chord_ends = np.concatenate(([first], first + 1 + np.flatnonzero(np.diff(stations)), [end - 1]))
        total += float(np.sum(np.hypot(*np.diff(border[np.unique(chord_ends)], axis=0).T)))
    return total


def _ahead_reference(border: np.ndarray, pose: tuple[float, float, float] | None) -> np.ndarray:
    """``ahead_of_m`` as first written (its own chord stations)."""
    arc = arc_lengths(border)
    chunks = arc // RANGE_CHORD_M
    ends = np.concatenate(([0], 1 + np.flatnonzero(chunks[1:] != chunks[:-1])))
    if ends[-1] != arc.size - 1:
        ends = np.append(ends, arc.size - 1)
    chords = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(border[ends], axis=0).T))))
    stations = np.interp(arc, arc[ends], chords)
    if pose is None:
        return stations
    x, y, yaw = pose
    start = math.cos(yaw) * (border[0, 0] - x) + math.sin(yaw) * (border[0, 1] - y)
    return stations + max(start, 0.0)


def _past_reference(points: np.ndarray, gt: np.ndarray, distances_m: np.ndarray, step_m: float) -> int:
    """``points_past_ends`` as first written: the end directions found on every call."""
    count = 0
    for end, inner in ((gt[-1], gt[-2::-1]), (gt[0], gt[1:])):
        direction = _end_direction(end, inner)
        if direction is None:
            continue
        offset = points - end
        past = np.flatnonzero(offset @ direction > GT_END_TOLERANCE_M)
        if past.size:
            count += int(np.count_nonzero(np.hypot(*offset[past].T) <= distances_m[past] + step_m))
    return count


@given(st.integers(0, 2**32 - 1), st.integers(1, 300), st.floats(0.001, 1.0), st.floats(0.0, 1.0))
def test_border_figures_equal_the_first_written_ones_bit_for_bit(seed: int, count: int, scale: float,
                                                                  far_share: float) -> None:
    """Range, distances ahead and points past the ends, with runs of points near and far."""
    border = _polyline(seed, count, scale)
    rng = np.random.default_rng(seed + 2)
    errors = rng.uniform(0.0, 0.9, count)
    errors[rng.random(count) < far_share] = 1.5
    pose = (float(border[0, 0]) - 1.0, float(border[0, 1]), float(rng.uniform(-np.pi, np.pi)))
    assert covered_length_m(border, errors) == _covered_reference(border, errors, RANGE_ERROR_THRESHOLD_M)
    for at in (pose, None):
        assert np.array_equal(ahead_of_m(border, at), _ahead_reference(border, at))
    if count >= 2:
        gt = _polyline(seed + 3, 40, 0.3)
        distances = rng.uniform(0.0, 3.0, count)
        assert points_past_ends(border, gt, distances, 0.02) == _past_reference(border, gt, distances, 0.02)
        assert points_past_ends(border, gt_ends(gt), distances, 0.02) == _past_reference(border, gt, distances, 0.02)


def _assert_figures_per_border(seed: int, borders: int, scale: float, far_share: float) -> None:
    """``border_figures`` of ``borders`` borders of 2 to 200 points, some ending at (or
    running past) an end of the GT, some with points beyond the range threshold, with and
    without poses, equal their per-border figures bit for bit."""
    rng = np.random.default_rng(seed)
    gt = _polyline(seed + 1, 40, 0.3)
    lanes, errors, poses = [], [], []
    for index in range(borders):
        border = _polyline(seed + 2 + index, int(rng.integers(2, 200)), scale)
        if rng.random() < 0.5:
            border += gt[[0, -1][index % 2]] - border[int(rng.integers(0, len(border)))]
        lanes.append(border)
        errors.append(rng.uniform(0.0, 0.9, len(border)))
        errors[-1][rng.random(len(border)) < far_share] = 1.5
        poses.append(None if index % 3 == 2 else (float(border[0, 0]) - 1.0, float(border[0, 1]),
                                                 float(rng.uniform(-np.pi, np.pi))))
    found = border_figures(lanes, errors, poses, gt_ends(gt), 0.02)
    pasts = [points_past_ends(border, gt, error, 0.02) for border, error in zip(lanes, errors)]
    assert [past for past, _, _ in found] == pasts
    for (_, covered, ahead), border, error, pose in zip(found, lanes, errors, poses):
        assert covered == covered_length_m(border, error)
        assert np.array_equal(ahead, ahead_of_m(border, pose))


@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.floats(0.001, 1.0), st.floats(0.0, 0.3))
def test_border_figures_of_many_borders_equal_the_per_border_ones_bit_for_bit(seed: int, borders: int, scale: float,
                                                                             far_share: float) -> None:
    """A few borders: one pass."""
    _assert_figures_per_border(seed, borders, scale, far_share)


@pytest.mark.parametrize("seed", [3, 17])
def test_border_figures_in_several_passes_equal_the_per_border_ones_bit_for_bit(seed: int) -> None:
    """More borders than ``FIGURE_BORDERS``: three passes, the last a short one."""
    _assert_figures_per_border(seed, 2 * FIGURE_BORDERS + 3, 0.2, 0.1)


def _captured_calls(map_path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[tuple]:
    """The lanes a short ``cold-eval`` run (with coops and lanes on) measures
    (``GroundTruthMeter.measure_many``, one call per block of frames), in order."""
    from cold_maps.cli import evaluate

    calls = []
    measure_many = GroundTruthMeter.measure_many

    def recorded(self, lanes):  # type: ignore[no-untyped-def]
        calls.extend((np.array(left), np.array(right), tuple(pose),
                      None if reference is None else tuple(np.array(side) for side in reference))
                     for left, right, pose, reference in lanes)
        return measure_many(self, lanes)

    with monkeypatch.context() as patch:
        patch.setattr(GroundTruthMeter, "measure_many", recorded)
        status = evaluate.main(["--map", str(map_path), "--frames", "12", "--workers", "1", "--no-plots",
                                "--no-mcap", "--no-progress", "--out", str(tmp_path / "out")])
    assert status == 0 and calls
    return calls


def _brute_force(points: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """Each point's distance (m) to its nearest sample, over all samples (rows of 64 points)."""
    found = []
    for first in range(0, len(points), 64):
        chunk = points[first:first + 64]
        dx = samples[:, 0] - chunk[:, :1]
        dy = samples[:, 1] - chunk[:, 1:]
        found.append(np.sqrt(np.min(dx * dx + dy * dy, axis=1)))
    return np.concatenate(found)


def _same(found: Measurement | Exception, expected: Measurement | Exception) -> bool:
    """Whether two measurements (or errors) agree in every field, bit for bit."""
    if isinstance(expected, Exception):
        return isinstance(found, Exception) and str(found) == str(expected)
    assert isinstance(found, Measurement)
    return all(np.array_equal(getattr(found, item.name), getattr(expected, item.name))
               if isinstance(getattr(expected, item.name), np.ndarray)
               else getattr(found, item.name) == getattr(expected, item.name) for item in fields(Measurement))


@pytest.mark.parametrize("name", ["junction", "curve90"])
def test_measure_many_equals_measure_one_by_one_on_the_bundled_maps(name: str, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks of 5 and of all calls of a run against fresh meters measuring one by one; the
    distances also against a brute-force search over all GT samples."""
    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from cold_maps.network.lane_graph import load_graph
    from converters import load_lanelet2
    from gt_matching import GroundTruth, MatchingError

    map_path = bundled_map(name)
    calls = _captured_calls(map_path, tmp_path, monkeypatch)
    graph = load_graph(map_path)
    lanelet_map, routing = load_lanelet2(map_path, converter=converter_named("engine", graph.odr_map))

    def fresh() -> GroundTruthMeter:
        return GroundTruthMeter(GroundTruth(lanelet_map, routing, prepare_all=False))

    single = fresh()
    expected: list[Measurement | Exception] = []
    for left, right, pose, reference in calls:
        try:
            expected.append(single.measure(left, right, pose, reference=reference))
        except MatchingError as exc:
            expected.append(exc)
    checked = 0
    for item, (left, right, pose, reference) in list(zip(expected, calls))[::5]:
        if isinstance(item, Measurement):
            match = single.match(*(reference or (left, right)), pose)
            assert np.array_equal(item.left_errors_m, _brute_force(left, match.left_gt_samples))
            assert np.array_equal(item.right_errors_m, _brute_force(right, match.right_gt_samples))
            checked += 1
    assert checked
    for block in (5, len(calls)):
        meter = fresh()
        found = [item for first in range(0, len(calls), block)
                 for item in meter.measure_many(calls[first:first + block])]
        assert all(_same(item, reference) for item, reference in zip(found, expected))
