"""Plans that fit the map: what of a :class:`MapPlan` a map's longest route can drive.

A drive needs a route of ``required_route_length`` metres: the ego's frames, the farthest
coop ahead with its sensor range, and room behind for the ``behind`` distractor (as far
behind as the farthest distractor is ahead). On a map whose longest route is shorter,
:func:`fit_plan` keeps what fits and says what it left out, in this order:

1. frames: when the plan's frames are an upper bound (``frames_at_most``, the default
   ``--frames``), as many as the local scenario fits, at most the plan's;
2. distractors, farthest lead first (they need room ahead *and* behind);
3. coop scenarios (spline gaps, convoy), farthest lead first.

Only a map where the local scenario (no coop) does not fit is refused, naming its
longest route.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from cold_maps.evaluation.scenarios import MapPlan
from cold_maps.network.routing import LENGTH_TOLERANCE_M
from cold_maps.simulation.drive import (
    FRAME_RATE_HZ,
    ROUTE_MARGIN_M,
    DriveError,
    required_route_length,
)
from cold_maps.simulation.sensor import SENSOR_RANGE_M


@dataclass(frozen=True)
class FittedPlan:
    """What of a plan a map can drive.

    Fields:
        plan: the plan with the scenarios and frames that fit (``distractors`` False when
            none fit).
        distractor_leads_m: leads (m) of the distractors that fit, ascending.
        needed_m: route length (m) the fitted plan's drives need.
        notes: one line per thing left out (what, the length it needs, the longest route);
            empty when the whole plan fits.
    """

    plan: MapPlan
    distractor_leads_m: tuple[float, ...]
    needed_m: float
    notes: tuple[str, ...]


def _needed(plan: MapPlan, frames: int, leads: tuple[float, ...], distractors: tuple[float, ...]) -> float:
    return required_route_length(frames, (*leads, *distractors), behind_m=max(distractors, default=0.0),
                                 speed_mps=plan.speed_mps)


def _most_frames(plan: MapPlan, longest_m: float, leads: tuple[float, ...] = (),
                 distractors: tuple[float, ...] = ()) -> int:
    """Frames (>= 0) a route of ``longest_m`` holds with coops at ``leads`` and
    ``distractors`` (the plan's frames when it is endless)."""
    spare = longest_m - _needed(plan, 1, leads, distractors) + LENGTH_TOLERANCE_M
    if spare < 0:
        return 0
    return 1 + math.floor(spare * FRAME_RATE_HZ / plan.speed_mps) if math.isfinite(spare) else plan.frames


def fit_plan(plan: MapPlan, longest_m: float, *, where: str) -> FittedPlan:
    """The part of ``plan`` a route of at most ``longest_m`` (m, may be inf) can drive.

    ``where`` names the map (or the start lane) in the error; the notes name the map. Raises
    ``DriveError`` when not even the local scenario fits.
    """
    leads = tuple(sorted({*plan.coop_leads_m, *plan.chain_leads_m}))
    distractors = plan.coop_leads_m if plan.distractors else ()
    whole = _needed(plan, plan.frames, leads, distractors)
    if whole <= longest_m + LENGTH_TOLERANCE_M:
        return FittedPlan(plan, distractors, whole, ())
    most = _most_frames(plan, longest_m)
    frames = min(most, plan.frames) if plan.frames_at_most else plan.frames
    if not 1 <= frames <= most:
        if most:
            all_fit = _most_frames(plan, longest_m, leads, distractors)
            hint = f"at most {most} --frames fit" + (f" ({all_fit} with every scenario)" if all_fit else "")
        else:
            hint = (f"even one frame needs {_needed(plan, 1, (), ()):.0f} m ({SENSOR_RANGE_M:g} m sensor range, "
                    f"{ROUTE_MARGIN_M:g} m margin)")
        raise DriveError(f"{where}: no drivable route of {_needed(plan, max(frames, 1), (), ()):.0f} m for the "
                         f"local scenario (longest {longest_m:.0f} m); {hint}", longest_m=longest_m)
    notes = []
    if frames < plan.frames:
        notes.append(f"{plan.name}: {frames} frames per route instead of {plan.frames}: the longest route is "
                     f"{longest_m:.0f} m, {plan.frames} frames of the local scenario need "
                     f"{_needed(plan, plan.frames, (), ()):.0f} m")
    kept = distractors
    while kept and _needed(plan, frames, leads, kept) > longest_m + LENGTH_TOLERANCE_M:
        kept = kept[:-1]
    if kept != distractors:
        dropped = distractors[len(kept):]
        notes.append(f"{plan.name}: no distractors {', '.join(f'{d:g}' for d in dropped)} m ahead and behind: "
                     f"{frames} frames with them need {_needed(plan, frames, leads, kept + dropped[:1]):.0f} m "
                     f"of route, the longest is {longest_m:.0f} m")
    fitting = leads
    while fitting and _needed(plan, frames, fitting, ()) > longest_m + LENGTH_TOLERANCE_M:
        fitting = fitting[:-1]
    if fitting != leads:
        dropped = leads[len(fitting):]
        labels = [s.label for s in plan.scenarios if s.fusion != "local" and not set(s.chain_leads_m) <= set(fitting)]
        notes.append(f"{plan.name}: dropped {', '.join(labels)} (coops {', '.join(f'{d:g}' for d in dropped)} m "
                     f"ahead): {frames} frames need {_needed(plan, frames, fitting + dropped[:1], ()):.0f} m of "
                     f"route and more, the longest is {longest_m:.0f} m")
    scenarios = tuple(s for s in plan.scenarios if s.fusion == "local" or set(s.chain_leads_m) <= set(fitting))
    fitted = replace(plan, scenarios=scenarios, frames=frames, distractors=bool(kept))
    return FittedPlan(fitted, kept, _needed(plan, frames, fitting, kept), tuple(notes))
