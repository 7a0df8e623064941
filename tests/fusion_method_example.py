"""A fusion method defined outside the package, for the method protocol tests
(``cold-eval --method fusion_method_example:straight_bridge``)."""

from __future__ import annotations

import numpy as np

import fusion
from cold_maps.simulation.detection import world_borders


def _bridged(ego: np.ndarray, coop: np.ndarray, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
    """``ego``, points on the straight segment to ``coop``'s start every ``spacing_m`` at
    most, then ``coop``; and the source of every point."""
    steps = max(2, int(np.ceil(np.linalg.norm(coop[0] - ego[-1]) / spacing_m)))
    t = np.linspace(0.0, 1.0, steps + 1)[1:-1, None]
    gap = ego[-1] + t * (coop[0] - ego[-1])
    sources = np.concatenate([np.full(len(ego), fusion.Source.EGO), np.full(len(gap), fusion.Source.INTERPOLATED),
                              np.full(len(coop), fusion.Source.COOP)]).astype(np.int8)
    return np.vstack([ego, gap, coop]), sources


def straight_bridge(ego: fusion.LaneDetection, coop: fusion.LaneDetection,
                    params: fusion.FusionParams) -> fusion.FusionResult:
    """Joins each ego border's end to the coop border's start by a straight segment (world
    frame): exact on a straight road, a chord across a bend. Pairs the paper's check finds
    not fusible are rejected with its reason."""
    fusible, reason = fusion.is_fusible(ego, coop, params, mode="spline")
    if not fusible:
        return _rejected(ego, reason)
    (ego_left, ego_right), (coop_left, coop_right) = world_borders(ego), world_borders(coop)
    left, left_source = _bridged(ego_left, coop_left, params.spacing_m)
    right, right_source = _bridged(ego_right, coop_right, params.spacing_m)
    gap_m = float(np.linalg.norm((coop_left[0] + coop_right[0] - ego_left[-1] - ego_right[-1]) / 2))
    return fusion.FusionResult(left, right, left_source, right_source, "spline", gap_m)


def never_fuses(ego: fusion.LaneDetection, coop: fusion.LaneDetection,
                params: fusion.FusionParams) -> fusion.FusionResult:
    """Rejects every pair (returns the ego lane with a reason)."""
    return _rejected(ego, "refuses on principle")


def _rejected(ego: fusion.LaneDetection, reason: str) -> fusion.FusionResult:
    left, right = world_borders(ego)
    sources = np.zeros(len(left), dtype=np.int8), np.zeros(len(right), dtype=np.int8)
    return fusion.FusionResult(left, right, *sources, "none", 0.0, reason)


STATED_SIGMA_M = 0.05
"""The lateral 1σ :func:`stated_sigma` lets both detections state on every point (m)."""


def stated_sigma(ego: fusion.LaneDetection, coop: fusion.LaneDetection,
                 params: fusion.FusionParams) -> fusion.FusionResult:
    """The paper's spline fusion of the two detections stating a lateral σ of
    :data:`STATED_SIGMA_M` on every point (the result carries the fused σ)."""
    from dataclasses import replace

    ego, coop = (replace(d, left_sigma=np.full(len(d.left), STATED_SIGMA_M),
                         right_sigma=np.full(len(d.right), STATED_SIGMA_M)) for d in (ego, coop))
    return fusion.fuse(ego, coop, mode="spline", interpolation="paper", params=params)


STALL_DIR_ENV = "COLD_TEST_STALL_DIR"
"""Environment variable naming the folder where :func:`stalls` marks a stalled process."""
STALL_AFTER_CALLS = 500
"""Calls of :func:`stalls` in one process before it stalls."""
STALL_S = 120.0
"""How long a stalled call waits before it gives up (s): longer than any test waits."""
_calls = 0


def stalls(ego: fusion.LaneDetection, coop: fusion.LaneDetection,
           params: fusion.FusionParams) -> fusion.FusionResult:
    """Rejects every pair, and at the :data:`STALL_AFTER_CALLS`-th call in a process writes a
    file named by the process id into the folder ``$COLD_TEST_STALL_DIR`` and sleeps: a run
    that a test interrupts is then surely still running, whatever the machine's load."""
    import os
    import time
    from pathlib import Path

    global _calls
    _calls += 1
    if _calls == STALL_AFTER_CALLS:
        (Path(os.environ[STALL_DIR_ENV]) / str(os.getpid())).touch()
        time.sleep(STALL_S)
    return _rejected(ego, "stalls on principle")
