"""Is the lane known far enough to stop? The stopping distance at the drive's speed.

A frame's lane is *known to the stopping distance* when both of its borders, from the ego
on, have every point within ``LANE_ACCURACY_M`` of the ground truth up to at least

    d = STOPPING_MARGIN · (v·t_r + v² / (2·a))

(m; v the ego's speed m/s, t_r the reaction time s, a the deceleration m/s²): the lane
safety measure of the CoLD paper's authors, a stopping distance with a 10 % margin.
``LANE_ACCURACY_M`` is the paper's "sufficient accuracy" (sec. III: 0.75 m keeps a 2.20 m
wide vehicle in a 4 m lane). Distances run along each border from the ego
(``groundtruth.meter.chord_stations_m``); the exact rule is
``gt_matching.metrics.known_distance_m``. See docs/metrics.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

LANE_ACCURACY_M: Final[float] = 0.75
"""The paper's sufficient lateral accuracy of a perceived lane (m, sec. III)."""
STOPPING_MARGIN: Final[float] = 1.1
"""Factor on the stopping distance (the lane safety measure's 10 % margin)."""
STOPPING_FORMULA: Final[str] = f"d = {STOPPING_MARGIN:g}·(v·t_r + v²/(2a))"
"""The stopping distance as the outputs state it."""
DEFAULT_REACTION_TIME_S: Final[float] = 2.5
"""Brake reaction time t_r (s): AASHTO, *A Policy on Geometric Design of Highways and
Streets* ("Green Book", 7th ed. 2018), sec. 3.2.2 stopping sight distance (2.5 s, above the
90th percentile of drivers' brake reaction times)."""
DEFAULT_DECELERATION_MPS2: Final[float] = 3.4
"""Deceleration a (m/s²): AASHTO Green Book sec. 3.2.2 (3.4 m/s², 11.2 ft/s²: about 90 % of
drivers brake harder, and a driver keeps steering control at it on a wet road)."""
MAX_REACTION_TIME_S: Final[float] = 60.0
"""Bound (exclusive) of the reaction time a rule accepts (s)."""
MAX_DECELERATION_MPS2: Final[float] = 100.0
"""Bound (inclusive) of the deceleration a rule accepts (m/s², about 10 g)."""


class StoppingError(ValueError):
    """A stopping rule or speed that cannot give a stopping distance; the message names it."""


@dataclass(frozen=True, slots=True)
class StoppingRule:
    """How far ahead the lane must be known: d = STOPPING_MARGIN·(v·t_r + v²/(2a)).

    Fields:
        reaction_time_s: reaction time t_r (s), 0 <= t_r < ``MAX_REACTION_TIME_S``.
        deceleration_mps2: deceleration a (m/s²), 0 < a <= ``MAX_DECELERATION_MPS2``.
    """

    reaction_time_s: float = DEFAULT_REACTION_TIME_S
    deceleration_mps2: float = DEFAULT_DECELERATION_MPS2

    def __post_init__(self) -> None:
        if not (isinstance(self.reaction_time_s, (int, float)) and 0 <= self.reaction_time_s < MAX_REACTION_TIME_S):
            raise StoppingError(f"reaction time: expected 0 <= t_r < {MAX_REACTION_TIME_S:g} s, "
                                f"got {self.reaction_time_s!r}")
        if not (isinstance(self.deceleration_mps2, (int, float))
                and 0 < self.deceleration_mps2 <= MAX_DECELERATION_MPS2):
            raise StoppingError(f"deceleration: expected 0 < a <= {MAX_DECELERATION_MPS2:g} m/s², "
                                f"got {self.deceleration_mps2!r}")

    def distance_m(self, speed_mps: float) -> float:
        """The stopping distance d (m) at ``speed_mps`` (m/s, finite, >= 0)."""
        if not (math.isfinite(speed_mps) and speed_mps >= 0):
            raise StoppingError(f"speed: expected a finite speed >= 0 m/s, got {speed_mps!r}")
        v = float(speed_mps)
        return STOPPING_MARGIN * (v * self.reaction_time_s + v * v / (2.0 * self.deceleration_mps2))

    def at(self, speed_mps: float) -> StoppingDistance:
        """This rule at one speed (what a frame record carries)."""
        return StoppingDistance(float(speed_mps), self)


@dataclass(frozen=True, slots=True)
class StoppingDistance:
    """A stopping rule at one speed.

    Fields:
        speed_mps: the ego's speed v (m/s).
        rule: the rule (t_r s, a m/s²).
    """

    speed_mps: float
    rule: StoppingRule

    def __post_init__(self) -> None:
        self.rule.distance_m(self.speed_mps)  # raises StoppingError naming a bad speed

    @property
    def distance_m(self) -> float:
        """The stopping distance d (m)."""
        return self.rule.distance_m(self.speed_mps)
