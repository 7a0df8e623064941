"""fusion.fuse_chain: an ego and K coops link by link; a failing link ends the chain."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import fusion
from fusion.analytic import AnalyticRoad, Segment, detect, detect_lanes, with_history
from fusion.geometry import distance_to_polyline

LANE = (0.0, -3.5)
ROAD = AnalyticRoad([Segment(60.0), Segment(100.0, 1.0 / 80.0), Segment(200.0)])


def _coop(s, lane=LANE, history_m=0.0, name=""):
    det = detect(ROAD, s, 30.0, *lane, sender=name)
    return with_history(ROAD, det, s, history_m, *lane) if history_m else det


def _max_error(result):
    return max(float(distance_to_polyline(b, ROAD.border(o)).max()) for b, o in ((result.left, LANE[0]),
                                                                                   (result.right, LANE[1])))


def test_three_links_reach_the_last_coop():
    ego = detect(ROAD, 0.0, 30.0, *LANE)
    coops = [_coop(50.0 * i, name=f"c{i}") for i in (1, 2, 3)]
    chain = fusion.fuse_chain(ego, coops, interpolation="hermite")
    assert chain.vehicles == 4 and not chain.reason
    assert [link.sender for link in chain.links] == ["c1", "c2", "c3"]
    assert all(link.kind == "spline" and 19.5 < link.gap_m < 20.5 for link in chain.links)
    # the lane runs from the ego to the last coop's end: 180 m of reference line
    assert chain.left[0] == pytest.approx(ROAD.border(LANE[0])[0])
    assert np.hypot(*(chain.left[-1] - ROAD.border(LANE[0], 0.0, 180.0)[-1])) < 0.1 + 1e-6  # within one step
    assert _max_error(chain) < 0.05  # arcs and straights: hermite is near exact
    counts = np.bincount(chain.left_source, minlength=5)
    assert counts[fusion.Source.EGO] == 301 and counts[fusion.Source.COOP] == 3 * 300
    assert 3 * 195 < counts[fusion.Source.INTERPOLATED] < 3 * 205


def test_a_failing_link_ends_the_chain_with_its_reason():
    ego = detect(ROAD, 0.0, 30.0, *LANE)
    coops = [_coop(50.0, name="c1"), _coop(100.0, lane=(3.5, 0.0), name="neighbour"), _coop(150.0, name="c3")]
    chain = fusion.fuse_chain(ego, coops)
    assert chain.vehicles == 2
    assert [link.kind for link in chain.links] == ["spline", "none"]  # c3 is never tried
    assert chain.links[-1].sender == "neighbour" and chain.reason == chain.links[-1].reason
    assert "another lane" in chain.reason
    pair = fusion.fuse(ego, coops[0])
    np.testing.assert_array_equal(chain.left, pair.left)
    np.testing.assert_array_equal(chain.right_source, pair.right_source)


def test_a_first_link_failing_leaves_the_ego_lane():
    ego = detect(ROAD, 0.0, 30.0, *LANE)
    behind = _coop(0.0, name="behind")
    chain = fusion.fuse_chain(ego, [behind])
    assert chain.vehicles == 1 and "not ahead" in chain.reason
    assert (chain.left_source == fusion.Source.EGO).all()
    np.testing.assert_allclose(chain.left, fusion.fuse(ego, behind).left)


def test_chain_with_histories_labels_history_points():
    ego = detect(ROAD, 0.0, 30.0, *LANE)
    coops = [_coop(50.0 * i, history_m=100.0, name=f"c{i}") for i in (1, 2)]
    chain = fusion.fuse_chain(ego, coops)
    assert chain.vehicles == 3
    assert [link.kind for link in chain.links] == ["history", "history"]
    assert _max_error(chain) < 1e-3
    history = np.count_nonzero(chain.right_source == fusion.Source.COOP_HISTORY)
    assert history > 2 * 190


def test_convoy_chain_and_bad_input():
    ego = detect(ROAD, 0.0, 30.0, *LANE)
    chain = fusion.fuse_chain(ego, [_coop(25.0), _coop(50.0)], mode="convoy")
    assert chain.vehicles == 3 and {link.kind for link in chain.links} == {"convoy"}
    assert _max_error(chain) < 0.01
    with pytest.raises(fusion.InvalidDetectionError, match=r"coops\[1\]"):
        fusion.fuse_chain(ego, [_coop(25.0), "lane"])
    assert math.isfinite(chain.links[0].gap_m)


S_BEND = AnalyticRoad([Segment(100.0), Segment(20.0, 1 / 50.0), Segment(20.0, -1 / 50.0), Segment(100.0)])


@pytest.mark.parametrize("d_s", [20.0, 30.0])
def test_chain_links_keep_neighbour_lanes_and_road_edges(d_s):
    """Multi-lane detections on a two-lane road with an S-bend (R 50 m) between the first coop
    (a convoy link: 25 m ahead of the ego) and the second: the second link's ego, the part of
    the first coop's detection past the overlap, keeps its neighbour lanes and road edges, so
    it decides like the pair of the two coops: the same lane is fused (both edges agree), the
    right neighbour lane, which the geometry alone passes across the S-bend, is rejected by
    the road edges."""
    width, end = 3.5, 111.0
    ego = detect_lanes(S_BEND, end - 55.0, 30.0, 1, 2, width)
    first = detect_lanes(S_BEND, end - 30.0, 30.0, 1, 2, width, sender="first")
    same = detect_lanes(S_BEND, end + d_s, 30.0, 1, 2, width, sender="same")
    beside = detect_lanes(S_BEND, end + d_s, 30.0, 0, 2, width, sender="beside")
    chain = fusion.fuse_chain(ego, [first, same])
    assert chain.vehicles == 3 and [link.kind for link in chain.links] == ["convoy", "spline"]
    pair = fusion.fuse(first, same)  # both road edges agree: the top level, graded by the margin used
    assert pair.kind == "spline" and 0.5 <= pair.confidence <= 1.0
    rejected = fusion.fuse_chain(ego, [first, beside])
    assert rejected.vehicles == 2 and rejected.reason == fusion.fuse(first, beside).reason
    assert "road edge" in rejected.reason
    single = [replace(d, neighbours=(), road_edges=None) for d in (first, beside)]
    assert fusion.fuse(*single).kind == "spline"  # the S-bend weakness without the edges
