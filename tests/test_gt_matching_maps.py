"""gt_matching on a real converted map (CARLA Town01 through ``converters``): detections
sampled from random lanelet sequences are matched back to those lanelets, with exact
error 0 and resampled error within half a step; shifted ones read their shift."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("lanelet2")

from gt_matching import GroundTruth
from gt_matching.synthetic import sequence_borders

DETECTION_STEP_M = 0.1
DETECTION_M = 60.0
DRIVES = 12


@pytest.fixture(scope="session")
def town01(town01_path) -> tuple[object, object, GroundTruth]:
    from converters import load_lanelet2

    lanelet_map, graph = load_lanelet2(town01_path)
    return lanelet_map, graph, GroundTruth(lanelet_map, graph)


def random_sequences(gt: GroundTruth, count: int, seed: int) -> list[list[object]]:
    """Lanelet sequences of >= DETECTION_M + 20 m along the routing graph from lanelets
    vehicles may use (seeded, so every run checks the same ones)."""
    rng = np.random.default_rng(seed)
    starts = [ll for ll in gt.lanelet_map.laneletLayer if gt.traffic_rules.canPass(ll)]
    found: list[list[object]] = []
    while len(found) < count:
        sequence = [starts[rng.integers(len(starts))]]
        length = gt._lanelet(sequence[0]).length_m
        while length < DETECTION_M + 20.0 and gt.routing_graph.following(sequence[-1]):
            following = gt.routing_graph.following(sequence[-1])
            sequence.append(following[rng.integers(len(following))])
            length += gt._lanelet(sequence[-1]).length_m
        if length >= DETECTION_M + 20.0:
            found.append(sequence)
    return found


def detection(sequence: list[object]) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float], set[int]]:
    """DETECTION_M of the sequence's borders from 10 m after its start, the pose at the
    detection start, and the ids of the lanelets it spans."""
    left, right = sequence_borders(sequence, DETECTION_STEP_M)
    mid = 0.5 * (left + right)
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(mid, axis=0).T))))
    keep = (s >= 10.0) & (s <= 10.0 + DETECTION_M)
    first = int(np.argmax(keep))
    yaw = float(np.arctan2(*(mid[first + 5] - mid[first])[::-1]))
    ends = np.cumsum([0] + [len(sequence_borders([ll], DETECTION_STEP_M)[0]) - (i > 0) for i, ll in enumerate(sequence)])
    spanned = {int(ll.id) for ll, lo, hi in zip(sequence, ends[:-1], ends[1:]) if keep[lo:hi].any()}
    return left[keep], right[keep], (float(mid[first, 0]), float(mid[first, 1]), yaw), spanned


def test_detections_on_town01_match_their_own_lanelets(town01) -> None:
    _, _, gt = town01
    for sequence in random_sequences(gt, DRIVES, seed=11):
        left, right, pose, spanned = detection(sequence)
        exact = gt.evaluate(left, right, pose, exact=True)
        resampled = gt.evaluate(left, right, pose)
        assert exact.matched, exact.mismatch
        assert spanned <= set(exact.lanelet_ids), (spanned, exact.lanelet_ids)
        for e, r in ((exact.left, resampled.left), (exact.right, resampled.right)):
            assert e.max_error_m < 1e-6
            assert r.max_error_m <= gt.config.step_m / 2.0 + 1e-9
            assert e.unmatched_points == 0 and r.unmatched_points == 0


def test_shifted_detections_on_town01_read_their_shift(town01) -> None:
    """Every point moved 0.2 m perpendicular to its border reads 0.2 m wherever the border
    is straighter than the point's distance (most of it; kinks at vertices bend it)."""
    _, _, gt = town01
    for sequence in random_sequences(gt, DRIVES // 2, seed=12):
        left, right, pose, _ = detection(sequence)
        shifted = []
        for border in (left, right):
            ahead = np.gradient(border, axis=0)
            normal = np.column_stack((-ahead[:, 1], ahead[:, 0])) / np.hypot(*ahead.T)[:, None]
            shifted.append(border + 0.2 * normal)
        metrics = gt.evaluate(*shifted, pose, exact=True)
        assert metrics.matched, metrics.mismatch
        for border in (metrics.left, metrics.right):
            assert border.p95_error_m == pytest.approx(0.2, abs=0.01)
            assert border.max_error_m <= 0.2 + 1e-6
