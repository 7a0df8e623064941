"""What the fusion keeps between calls (a pair's work, the weighted end-fit designs) changes
no result: bit for bit the values of fresh calls on fresh detections."""

from __future__ import annotations

import numpy as np
import pytest

import fusion
import fusion.api
import fusion.geometry
from fusion import FusionParams, LaneDetection
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.geometry import fit_ends

ROAD = AnalyticRoad([Segment(40.0), Segment(60.0, 1.0 / 60.0), Segment(80.0)], yaw0=0.4)


def noisy(s_from: float, seed: int, lane_m: float = 0.0) -> LaneDetection:
    """A 30 m detection on :data:`ROAD` (of the lane ``lane_m`` to the left) with 3 cm noise
    and a σ growing with the distance ahead."""
    rng = np.random.default_rng(seed)
    det = detect(ROAD, s_from, 30.0, 1.75 + lane_m, -1.75 + lane_m)
    left, right = (b + rng.normal(0.0, 0.03, b.shape) for b in (det.left, det.right))
    return LaneDetection(det.pose, left, right, left_sigma=0.02 + 0.004 * np.abs(left[:, 0]),
                         right_sigma=0.02 + 0.004 * np.abs(right[:, 0]))


def copy(detection: LaneDetection) -> LaneDetection:
    """The same detection as a new object (new arrays)."""
    return LaneDetection(detection.pose, detection.left.copy(), detection.right.copy(),
                         left_sigma=detection.left_sigma.copy(), right_sigma=detection.right_sigma.copy())


def same(a: fusion.FusionResult, b: fusion.FusionResult) -> bool:
    arrays = ("left", "right", "left_source", "right_source", "left_sigma", "right_sigma")
    return (a.kind, a.reason, a.confidence) == (b.kind, b.reason, b.confidence) and all(
        np.array_equal(getattr(a, name), getattr(b, name)) for name in arrays)


def fresh(call):
    """``call()`` with nothing kept from earlier calls."""
    fusion.api._PAIRS.clear()
    fusion.api._EGOS.clear()
    fusion.geometry._DESIGNS.clear()
    return call()


@pytest.mark.parametrize("gap_m", [12.0, -8.0])  # spline fusion across a gap; convoy over an overlap
def test_a_pair_fused_again_and_among_other_pairs_gives_the_fresh_values(gap_m: float) -> None:
    params = FusionParams(convoy_weights="inverse-variance")
    egos = [noisy(5.0 + k, seed=k) for k in range(3)]
    coops = [noisy(35.0 + k + gap_m, seed=10 + k, lane_m=3.5 * (k == 2)) for k in range(3)]  # the last: refused
    calls = [(e, c, mode, interpolation) for e, c in zip(egos, coops) for mode in ("auto", "spline")
             for interpolation in ("paper", "hermite")]
    expected = [fresh(lambda: fusion.fuse(copy(e), copy(c), mode=m, interpolation=i, params=params))
                for e, c, m, i in calls]
    checks = [fresh(lambda: fusion.is_fusible(copy(e), copy(c), params, mode=m)) for e, c, m, _ in calls]
    assert {r.kind for r in expected} >= {"spline" if gap_m > 0 else "convoy", "none"}
    fusion.api._PAIRS.clear()
    for _ in range(2):  # the second round from what the first kept
        for call, want, check in zip(calls, expected, checks):
            e, c, m, i = call
            assert same(fusion.fuse(e, c, mode=m, interpolation=i, params=params), want)
            assert fusion.is_fusible(e, c, params, mode=m) == check
    for k in range(fusion.api._MAX_PAIRS + 1):  # more pairs than are kept: the first ones are dropped
        fusion.fuse(egos[0], noisy(40.0, seed=100 + k), params=params)
    assert len(fusion.api._PAIRS) == fusion.api._MAX_PAIRS
    assert same(fusion.fuse(*calls[0][:2], mode=calls[0][2], interpolation=calls[0][3], params=params), expected[0])


def test_pairs_refused_with_one_ego_keep_their_own_gap_and_reason() -> None:
    """The refused pairs of one ego share the ego lane's arrays, each with its pair's gap and
    reason: the values of fresh calls."""
    ego = noisy(20.0, seed=1)
    coops = [noisy(5.0, seed=2), noisy(62.0, seed=3, lane_m=3.5), noisy(120.0, seed=4)]  # behind, beside, too far
    expected = [fresh(lambda: fusion.fuse(copy(ego), copy(c), mode="spline")) for c in coops]
    assert [r.kind for r in expected] == ["none"] * 3 and len({r.reason for r in expected}) == 3
    fusion.api._PAIRS.clear()
    fusion.api._EGOS.clear()
    found = [fusion.fuse(ego, c, mode="spline") for c in coops]
    assert all(same(a, b) and a.gap_m == b.gap_m for a, b in zip(found, expected))
    assert found[1].left is found[0].left


def test_weighted_end_fits_are_the_same_kept_and_each_design_the_same_made_alone() -> None:
    """The memo relies on a border's weighted design being its own: made in one stack with
    other borders' weights, it equals the one made alone, bit for bit."""
    dets = [noisy(5.0 + 3 * k, seed=k) for k in range(4)]
    borders = [dets[0].left, dets[1].right, dets[2].left, dets[3].right]
    sigmas = [dets[0].left_sigma, dets[1].right_sigma, dets[2].left_sigma, None]
    at_end = [True, False, True, False]
    windows = (2.0, 3.0, 4.5, 6.0)
    made = fresh(lambda: fit_ends(borders, at_end, windows, 5.0, sigmas))
    assert fit_ends(borders, at_end, windows, 5.0, sigmas) == made  # every design kept
    assert sum(key[2] is not None for key in fusion.geometry._DESIGNS) == 3  # the last border is unweighted
    weights = np.array([fusion.geometry._fit_weights(sigma, end)[:61] for sigma, end in zip(sigmas[:3], at_end)])
    counts = (21, 31, 46, 61)
    stacked = fusion.geometry._designs(counts, 50, weights)
    for row, design in zip(weights, stacked):
        (alone,) = fusion.geometry._designs(counts, 50, row[None])
        assert alone.rows.tobytes() == design.rows.tobytes()
        assert (alone.p1_gains, alone.p2_gains, alone.p3_gain, alone.cubic_leaks, alone.quartic_leaks,
                alone.p3_quartic_leak) == (design.p1_gains, design.p2_gains, design.p3_gain, design.cubic_leaks,
                                           design.quartic_leaks, design.p3_quartic_leak)
    assert len({design.rows.tobytes() for design in stacked}) == 3  # three different weightings


def test_pairs_fused_from_several_threads_give_the_values_of_one_thread() -> None:
    """Threads that fuse more pairs than are kept, at once, each get the values fused alone."""
    from concurrent.futures import ThreadPoolExecutor

    params = FusionParams(convoy_weights="inverse-variance")
    egos = [noisy(5.0 + k, seed=k) for k in range(4)]
    coops = [noisy(33.0 + 2 * k, seed=20 + k, lane_m=3.5 * (k % 5 == 4)) for k in range(12)]
    calls = [(e, c, i) for e in egos for c in coops for i in ("paper", "hermite")]  # 96 calls, 48 pairs
    expected = [fresh(lambda: fusion.fuse(copy(e), copy(c), interpolation=i, params=params)) for e, c, i in calls]
    fusion.api._PAIRS.clear()

    def fuse_all(offset: int) -> list[bool]:
        order = calls[offset:] + calls[:offset]
        found = [fusion.fuse(e, c, interpolation=i, params=params) for e, c, i in order]
        return [same(result, expected[(offset + n) % len(calls)]) for n, result in enumerate(found)]

    with ThreadPoolExecutor(max_workers=4) as pool:
        outcomes = list(pool.map(fuse_all, (0, 24, 48, 72)))
    assert all(all(outcome) for outcome in outcomes)
    assert len(fusion.api._PAIRS) == fusion.api._MAX_PAIRS
    assert {r.kind for r in expected} >= {"convoy", "none"}
