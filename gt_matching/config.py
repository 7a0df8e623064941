"""Tunable thresholds of lanelet matching and error evaluation."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Final

#: The paper's GT sampling distance (sec. IV), m.
PAPER_STEP_M: Final = 0.02


@dataclass(frozen=True)
class MatchingConfig:
    """Thresholds for matching a detected lane to Lanelet2 ground truth.

    Fields:
        step_m: GT resampling distance, m (the paper uses 0.02 m).
        search_radius_m: lanelets farther than this from the sender's pose are not
            candidates (Lanelet2 matching ``maxDist``), m.
        max_heading_diff_rad: a lanelet whose direction at the pose differs from the
            pose yaw by more than this is not a candidate, rad.
        ambiguity_m: lanelets within this distance of the nearest one to the pose all count
            as the sender's lane; the detection then decides between them, m.
        max_distance_m: a detected point farther than this from its GT border is unmatched;
            a lanelet whose centreline is farther than this from every detection
            centreline sample is not followed, m.
        other_border_margin_m: a detected point is also unmatched when a border of another
            lane (any line of the map but its GT border and the borders of lanelets that
            overlap the GT lanelets) is closer than its GT border by more than this, m.
        margin_m: the GT route extends this far beyond both ends of the detection, m.
        score_step_m: spacing of the detection centreline samples that score candidate
            lanelet sequences, m.
    """

    step_m: float = PAPER_STEP_M
    search_radius_m: float = 2.0
    max_heading_diff_rad: float = math.pi / 4.0
    ambiguity_m: float = 0.5
    max_distance_m: float = 1.5
    other_border_margin_m: float = 0.10
    margin_m: float = 5.0
    score_step_m: float = 2.0

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"MatchingConfig.{field.name} must be finite and >= 0, got {value!r}")
        for name in ("step_m", "search_radius_m", "max_distance_m", "score_step_m"):
            if getattr(self, name) <= 0:
                raise ValueError(f"MatchingConfig.{name} must be > 0, got {getattr(self, name)!r}")
