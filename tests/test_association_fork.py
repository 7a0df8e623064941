"""The "fork" association rule: a branch that starts where the ego's detection ends (the
detection runs less than FORK_SEEN_M along it) is not a lane the detection lies on, so a coop
that continues it as well as or better than the ego's lane is rejected as ambiguous; analytic
T-junction (lane width 3.5 m, turns of radius 12 m)."""

from __future__ import annotations

import math

import pytest

import fusion
from fusion import FusionParams, LaneBranch, LaneDetection
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.association import FORK_SEEN_M, branch_seen_m
from fusion.fusibility import relative_pose
from fusion.geometry import transform

W = 3.5
RADIUS_M = 12.0
FORK_M = 40.0
"""Station of the fork (the junction's entry) on the approach."""
PARAMS = {rule: FusionParams(association=rule) for rule in ("legacy", "separation", "fork")}


def _turn(sign: float) -> AnalyticRoad:
    """The approach (FORK_M straight), a 90° turn to the left (+1) or right (−1), then straight."""
    return AnalyticRoad([Segment(FORK_M), Segment(RADIUS_M * math.pi / 2, sign / RADIUS_M), Segment(100.0)])


def _ego(detection_m: float) -> LaneDetection:
    """The ego 20 m before the fork on the lane that turns left, its detection ``detection_m``
    long, the right turn reported as a branch from the fork to 15 m past it (the ego frame)."""
    left, right = _turn(1.0), _turn(-1.0)
    ego = detect(left, FORK_M - 20.0, detection_m, W / 2, -W / 2)
    seen = detect(right, FORK_M, 15.0, W / 2, -W / 2)
    relative = relative_pose(ego.pose, seen.pose)
    branch = LaneBranch(transform(seen.left, *relative), transform(seen.right, *relative))
    return LaneDetection(ego.pose, ego.left, ego.right, branches=(branch,))


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
