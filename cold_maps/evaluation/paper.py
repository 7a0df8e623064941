"""The paper's experiments (sec. IV) on the bundled maps: plans and the extra tables.

Each map is driven end to end on lane -1 of road 1 (the lane along +s, maps/README.md)
by an ego and one cooperative vehicle, with no distractors, as in the paper's two-vehicle
scenarios, at the default 10 m/s with frames at 10 Hz (1 m per frame): the ego drives from
the route start until the farthest coop's detection (r_lane + d_s + r_lane ahead) reaches
the route end, so every stretch of the road is seen at the same 1 m frame spacing.
Gaps d_s: straight 30 and 50 m, 90° curve 20 m, rural 20 m plus a sweep to 50 m for the
longest gap that keeps the maximum error bounded.
"""

from __future__ import annotations

import math
from importlib.resources import files
from pathlib import Path
from typing import Final, Mapping, Sequence

from cold_maps.evaluation.report import ScenarioResult, paper_comparison_markdown
from cold_maps.evaluation.scenarios import MapPlan, params_for_gaps, scenarios_for
from cold_maps.network.lane_graph import LaneKey, load_graph
from cold_maps.network.routing import longest_route_lengths
from cold_maps.simulation.drive import DEFAULT_SPEED_MPS, FRAME_RATE_HZ, ROUTE_MARGIN_M
from cold_maps.simulation.sensor import SENSOR_RANGE_M

BUNDLED_MAPS_DIR: Final[Path] = Path(str(files("cold_maps.maps")))
"""The bundled maps, package data ``cold_maps.maps`` (``maps/`` in a source checkout)."""
PAPER_START_LANE: Final[LaneKey] = LaneKey("1", 0, -1)
PAPER_GAPS_M: Final[Mapping[str, tuple[float, ...]]] = {
    "straight": (30.0, 50.0),
    "curve90": (20.0,),
    "rural": (20.0, 25.0, 30.0, 35.0, 40.0, 45.0, 50.0),
}
ROAD_TYPES: Final[Mapping[str, str]] = {"straight": "straight", "curve90": "right_curve_90", "rural": "rural"}
"""Bundled map → the paper's road type (``report.PAPER_TABLE_II`` keys)."""
RUNTIME_MAP: Final[str] = "rural"
"""The paper's Table I runs on the rural road."""
MAX_ERROR_LIMIT_M: Final[float] = 0.75
"""Error bound of the longest-gap table (m)."""


def paper_frame_count(route_length_m: float, gaps_m: Sequence[float], speed_mps: float = DEFAULT_SPEED_MPS,
                      limit: int | None = None) -> int:
    """Frames (at ``FRAME_RATE_HZ``) an ego at ``speed_mps`` drives on a route while the
    farthest coop (r_lane + d_s ahead) and its detection stay on it; at most ``limit``."""
    usable = route_length_m - (SENSOR_RANGE_M + max(gaps_m)) - SENSOR_RANGE_M - ROUTE_MARGIN_M
    if usable <= 0:
        raise ValueError(f"route of {route_length_m:.0f} m is too short for d_s = {max(gaps_m)} m")
    fitting = int(math.floor(usable * FRAME_RATE_HZ / speed_mps + 1e-9)) + 1
    return fitting if limit is None else min(fitting, limit)


def paper_plans(maps_dir: Path = BUNDLED_MAPS_DIR, *, frames: int | None = None, seed: int = 0,
                speed_mps: float = DEFAULT_SPEED_MPS,
                interpolations: Sequence[str] = ("paper", "hermite")) -> list[MapPlan]:
    """One plan per paper map (straight, curve90, rural) in ``maps_dir``: the whole route
    at ``speed_mps`` (default 10 m/s) and 10 Hz, or its first ``frames`` frames."""
    plans = []
    for name, gaps in PAPER_GAPS_M.items():
        path = maps_dir / f"{name}.xodr"
        graph = load_graph(path)
        if PAPER_START_LANE not in graph.lengths:
            raise ValueError(f"{path}: no driving lane {tuple(PAPER_START_LANE)} to start the paper's drive on")
        length = longest_route_lengths(graph)[PAPER_START_LANE]
        if not math.isfinite(length):
            raise ValueError(f"{path}: the paper's drive needs a route with an end, found a loop")
        plans.append(MapPlan(path, scenarios_for(gaps, interpolations),
                             frames=paper_frame_count(length, gaps, speed_mps, limit=frames), routes=1,
                             seed=seed, speed_mps=speed_mps, start_lane=PAPER_START_LANE,
                             distractors=False, params=params_for_gaps(gaps), road_type=ROAD_TYPES[name]))
    return plans


def table_ii_markdown(results: Sequence[ScenarioResult], interpolation: str) -> str:
    """Table II side by side with the paper for one spline interpolation (local and convoy
    rows included), on the maps of :data:`ROAD_TYPES`."""
    chosen = [r for r in results if r.key.map in ROAD_TYPES
              and (r.key.fusion != "spline" or r.key.interpolation == interpolation)]
    return paper_comparison_markdown(chosen, {name: ROAD_TYPES[name] for name in {r.key.map for r in chosen}})


def gap_limit_markdown(results: Sequence[ScenarioResult], limit_m: float = MAX_ERROR_LIMIT_M) -> str:
    """Per map and interpolation, the longest spline gap d_s whose maximum error (both
    boundaries) stays ≤ ``limit_m``, with every shorter evaluated gap also within it."""
    worst: dict[tuple[str, str], dict[float, float]] = {}
    for r in results:
        if r.key.fusion == "spline":
            gaps = worst.setdefault((r.key.map, r.key.interpolation), {})
            gaps[r.key.d_s] = max(gaps.get(r.key.d_s, 0.0), r.max_error_m)
    rows = []
    for (map_name, interpolation), gaps in sorted(worst.items()):
        longest = None
        for gap in sorted(gaps):
            if not gaps[gap] <= limit_m:
                break
            longest = gap
        errors = ", ".join(f"{gap:g}: {gaps[gap]:.3f}" for gap in sorted(gaps))
        rows.append(f"| {map_name} | {interpolation} | {'none' if longest is None else f'{longest:g}'} | {errors} |")
    return (f"Longest gap d_s with max error ≤ {limit_m:g} m (paper: 20 m on the rural road).\n\n"
            "| map | interpolation | longest d_s [m] | max error per d_s [m] |\n|---|---|---|---|\n"
            + "\n".join(rows) + "\n")
