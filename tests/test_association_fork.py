"""The "fork" association rule: a branch that starts where the ego's detection ends (the
detection runs less than FORK_SEEN_M along it), or that the detection lies on where it stopped
short of its range, is not a lane the detection lies on, so a coop that continues it as well as
or better than the ego's lane is rejected as ambiguous; a single-lane detection that ended where
its markings stop makes a gap pair ambiguous; analytic T-junction (lane width 3.5 m, turns of
radius 12 m)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

import fusion
from fusion import FusionParams, LaneBranch, LaneDetection
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.api import assess
from fusion.association import FORK_SEEN_M, branch_seen_m
from fusion.fusibility import relative_pose
from fusion.geometry import transform
from fusion.types import ASSOCIATION_RULES, END_EARLY, END_REACHED, END_REASONS

W = 3.5
RADIUS_M = 12.0
FORK_M = 40.0
"""Station of the fork (the junction's entry) on the approach."""
PARAMS = {rule: FusionParams(association=rule) for rule in ("legacy", "separation", "fork")}


def _turn(sign: float) -> AnalyticRoad:
    """The approach (FORK_M straight), a 90° turn to the left (+1) or right (−1), then straight."""
    return AnalyticRoad([Segment(FORK_M), Segment(RADIUS_M * math.pi / 2, sign / RADIUS_M), Segment(100.0)])


def _ego(detection_m: float, end_reason: str | None = None) -> LaneDetection:
    """The ego 20 m before the fork on the lane that turns left, its detection ``detection_m``
    long (ended for ``end_reason``), the right turn reported as a branch from the fork to 15 m
    past it (the ego frame)."""
    left, right = _turn(1.0), _turn(-1.0)
    ego = detect(left, FORK_M - 20.0, detection_m, W / 2, -W / 2)
    seen = detect(right, FORK_M, 15.0, W / 2, -W / 2)
    relative = relative_pose(ego.pose, seen.pose)
    branch = LaneBranch(transform(seen.left, *relative), transform(seen.right, *relative))
    return LaneDetection(ego.pose, ego.left, ego.right, branches=(branch,), end_reason=end_reason)


def _bare(detection_m: float, end_reason: str | None) -> LaneDetection:
    """The ego of :func:`_ego` as a single-lane sensor sees it: no branch."""
    return replace(detect(_turn(1.0), FORK_M - 20.0, detection_m, W / 2, -W / 2), end_reason=end_reason)


def _coop(sign: float, past_fork_m: float) -> LaneDetection:
    """A coop ``past_fork_m`` of lane past the fork on the left (+1) or right (−1) turn."""
    return detect(_turn(sign), FORK_M + past_fork_m, 30.0, W / 2, -W / 2)


def test_branch_seen_is_the_detection_past_the_branch_start() -> None:
    """A detection ending at the fork runs 0 m along the branch. One ending 4 m into the
    left turn (θ = 4 m / R) ends a chord 2R·sin(θ/2) from the fork, at most θ off the end
    heading: its projection lies in [chord·cos θ, chord]."""
    ego = _ego(20.0)
    branch = ego.branches[0]
    assert branch_seen_m((ego.left, ego.right), (branch.left, branch.right)) == pytest.approx(0.0, abs=1e-6)
    ego = _ego(24.0)
    theta = 4.0 / RADIUS_M
    chord = 2.0 * RADIUS_M * math.sin(theta / 2.0)
    seen = branch_seen_m((ego.left, ego.right), (ego.branches[0].left, ego.branches[0].right))
    assert chord * math.cos(theta) <= seen <= chord


@pytest.mark.parametrize("past_fork_m", [15.0, 25.0, 40.0])
def test_coop_on_the_other_turn_of_a_fork_at_the_detection_end_is_ambiguous(past_fork_m: float) -> None:
    """The ego's detection ends at the junction's entry (a camera: the markings stop there).
    Under "separation" the branch counts as a lane the detection lies on (its end lies in
    both), so the coop that took the right turn is fused; under "fork" it is rejected as
    ambiguous, branch unknown, while the coop on the ego's own left turn is fused by all."""
    ego = _ego(20.0)
    other, own = _coop(-1.0, past_fork_m), _coop(1.0, past_fork_m)
    assert fusion.fuse(ego, other, params=PARAMS["legacy"]).kind == "spline"
    assert fusion.fuse(ego, other, params=PARAMS["separation"]).kind == "spline"
    rejected = fusion.fuse(ego, other, params=PARAMS["fork"])
    assert rejected.kind == "none"
    assert rejected.reason.startswith("ambiguous") and "branch unknown" in rejected.reason
    for rule in PARAMS.values():
        assert fusion.fuse(ego, own, params=rule).kind == "spline", rule.association


def test_a_fork_the_detection_runs_past_keeps_the_branch() -> None:
    """A detection that runs FORK_SEEN_M + 1 m past the fork (1.3 m into the turns of R 12 m:
    their centres 2R(1 − cos(1.3/R)) = 0.14 m apart at its end, inside each other) lies on
    both: "fork" fuses the coop on the right turn as "separation" does."""
    ego = _ego(20.0 + FORK_SEEN_M + 1.0)
    other = _coop(-1.0, 25.0)
    assert fusion.fuse(ego, other, params=PARAMS["separation"]).kind == "spline"
    assert fusion.fuse(ego, other, params=PARAMS["fork"]).kind == "spline"


def test_fork_changes_nothing_without_branches() -> None:
    """Without a reported branch "fork" decides as "separation" (the coop on the right turn is
    fused by geometry alone, as the single-lane sensor's weakness)."""
    bare = detect(_turn(1.0), FORK_M - 20.0, 20.0, W / 2, -W / 2)
    for past_fork_m in (15.0, 25.0):
        for sign in (1.0, -1.0):
            coop = _coop(sign, past_fork_m)
            separation = fusion.api.assess(bare, coop, PARAMS["separation"])
            assert fusion.api.assess(bare, coop, PARAMS["fork"]) == separation


RING_RADIUS_M = 30.0


def test_a_single_lane_detection_that_ends_where_its_markings_stop_is_ambiguous_under_fork() -> None:
    """A roundabout's ring (R 30 m): the single-lane ego's detection ends 12 m ahead where
    the markings stop at an arm's mouth. A coop on the ring 10-30 m on lies on the ego's arc
    (the arc prediction decides, confidence 0.7): "separation" fuses it, as "fork" does
    without the reason; whether the ego's lane stays on the ring or leaves at the mouth is not
    in the detection, so "fork" rejects it as ambiguous. A coop whose detection overlaps the
    ego's (a convoy) is still fused."""
    ring = AnalyticRoad([Segment(300.0, 1.0 / RING_RADIUS_M)])
    ego = detect(ring, 0.0, 12.0, W / 2, -W / 2)
    unmarked = replace(ego, end_reason="unmarked")
    for gap_m in (10.0, 20.0, 30.0):
        coop = detect(ring, 12.0 + gap_m, 30.0, W / 2, -W / 2)
        fused = assess(unmarked, coop, PARAMS["separation"])
        assert not fused.reason and fused.confidence == pytest.approx(0.7, abs=0.01)
        assert assess(ego, coop, PARAMS["fork"]) == fused
        rejected = assess(unmarked, coop, PARAMS["fork"])
        assert rejected.reason.startswith("ambiguous") and "markings stop" in rejected.reason
        assert rejected.confidence == 0.0
    convoy = detect(ring, 6.0, 30.0, W / 2, -W / 2)
    assert fusion.fuse(unmarked, convoy, params=PARAMS["fork"]).kind == "convoy"


@pytest.mark.parametrize("end_reason", [r for r in END_REASONS if r != "unmarked"])
def test_other_end_reasons_of_a_single_lane_detection_change_nothing(end_reason: str) -> None:
    """A single-lane detection that reached its range or was cut short by anything but the
    markings (view, crest, another vehicle) is decided under "fork" as without a reason."""
    stated, unknown = _bare(20.0, end_reason), _bare(20.0, None)
    for past_fork_m in (15.0, 25.0):
        for sign in (1.0, -1.0):
            coop = _coop(sign, past_fork_m)
            assert assess(stated, coop, PARAMS["fork"]) == assess(unknown, coop, PARAMS["fork"])


@pytest.mark.parametrize("rule", [rule for rule in ASSOCIATION_RULES if rule != "fork"])
def test_the_end_reason_changes_no_other_rule(rule: str) -> None:
    """Every rule but "fork" decides the same whatever the ego's end reason, with and without
    a branch, at the fork and past it."""
    params = FusionParams(association=rule)
    for detection_m in (20.0, 20.0 + FORK_SEEN_M + 1.0):
        for make in (_ego, _bare):
            unknown = make(detection_m, None)
            for end_reason in END_REASONS:
                stated = make(detection_m, end_reason)
                for sign in (1.0, -1.0):
                    coop = _coop(sign, 25.0)
                    assert assess(stated, coop, params) == assess(unknown, coop, params), (end_reason, sign)


@pytest.mark.parametrize("end_reason", END_EARLY)
def test_a_branch_the_detection_lies_on_where_it_stopped_early_is_unknown(end_reason: str) -> None:
    """The detection runs FORK_SEEN_M + 1 m past the fork, its end inside both turns, but
    stopped short of its range (hidden, out of view, unmarked): the lanes part unseen beyond
    it, so under "fork" the coop on the right turn is ambiguous (branch unknown), the coop on
    the ego's own turn fused; a detection that reached its range lies on both (fused)."""
    early = _ego(20.0 + FORK_SEEN_M + 1.0, end_reason)
    other, own = _coop(-1.0, 25.0), _coop(1.0, 25.0)
    rejected = fusion.fuse(early, other, params=PARAMS["fork"])
    assert rejected.kind == "none" and rejected.reason.startswith("ambiguous") and "branch unknown" in rejected.reason
    assert fusion.fuse(early, own, params=PARAMS["fork"]).kind == "spline"
    for reached in END_REACHED:
        assert fusion.fuse(_ego(20.0 + FORK_SEEN_M + 1.0, reached), other, params=PARAMS["fork"]).kind == "spline"
