"""Routing on the lane graph: shortest routes (Dijkstra) and seeded random routes.

A route here is a sequence of lanes (``LaneKey``) in driving direction, each followed
whole; ``cold_maps.network.route.Route`` turns it into world-frame polylines. Lane lengths are the
graph's centreline lengths (m). Routes may pass a lane more than once (a loop round a
block), so on a map with a reachable cycle any length can be driven.
"""

from __future__ import annotations

import heapq
import math
from typing import Final, Mapping, Sequence

import numpy as np

from cold_maps.network.lane_graph import LaneGraph, LaneKey

LENGTH_TOLERANCE_M: Final[float] = 1e-6
"""Slack (m) on comparing a route length with a needed one: lane lengths summed in a
different order, or the same road's lanes sampled in opposite directions, differ by
round-off (99.99999999999999 against 100.0 m)."""


class NoRouteError(ValueError):
    """No route joins the two lanes asked for."""


def _require_lane(graph: LaneGraph, lane: LaneKey, what: str) -> None:
    if lane not in graph.lengths:
        raise ValueError(f"{what} lane {tuple(lane)} is not in the lane graph (lane types {graph.lane_types})")


def route_length(graph: LaneGraph, lanes: Sequence[LaneKey]) -> float:
    """Summed centreline length (m) of the lanes."""
    return float(sum(graph.lengths[lane] for lane in lanes))


def shortest_route(graph: LaneGraph, start: LaneKey, goal: LaneKey) -> tuple[LaneKey, ...]:
    """Lanes from ``start`` to ``goal`` (both included) of least summed length.

    Raises ValueError when a lane is not in the graph, NoRouteError when ``goal`` cannot
    be reached from ``start``.
    """
    _require_lane(graph, start, "start")
    _require_lane(graph, goal, "goal")
    best: dict[LaneKey, float] = {start: graph.lengths[start]}
    came_from: dict[LaneKey, LaneKey] = {}
    queue: list[tuple[float, LaneKey]] = [(best[start], start)]
    done: set[LaneKey] = set()
    while queue:
        cost, lane = heapq.heappop(queue)
        if lane in done:
            continue
        if lane == goal:
            path = [goal]
            while path[-1] != start:
                path.append(came_from[path[-1]])
            return tuple(reversed(path))
        done.add(lane)
        for nxt in graph.successors[lane]:
            new_cost = cost + graph.lengths[nxt]
            if new_cost < best.get(nxt, math.inf):
                best[nxt] = new_cost
                came_from[nxt] = lane
                heapq.heappush(queue, (new_cost, nxt))
    raise NoRouteError(f"no route from lane {tuple(start)} to lane {tuple(goal)}")


def longest_route_lengths(graph: LaneGraph) -> dict[LaneKey, float]:
    """Per lane, the longest route (m) that starts with it: inf when it reaches a cycle.

    Strongly connected components (iterative Tarjan) are emitted successors first, so
    each acyclic lane's value is its length plus the best of its successors' values.
    """
    longest: dict[LaneKey, float] = {}
    for component in _components_successors_first(graph):
        cyclic = len(component) > 1 or component[0] in graph.successors[component[0]]
        for lane in component:
            if cyclic:
                longest[lane] = math.inf
            else:
                after = (longest[nxt] for nxt in graph.successors[lane])
                longest[lane] = graph.lengths[lane] + max(after, default=0.0)
    return longest


def _components_successors_first(graph: LaneGraph) -> list[list[LaneKey]]:
    """Strongly connected components, every component after those it can reach."""
    index: dict[LaneKey, int] = {}
    low: dict[LaneKey, int] = {}
    stack: list[LaneKey] = []
    on_stack: set[LaneKey] = set()
    components: list[list[LaneKey]] = []
    for root in graph.lanes:
        if root in index:
            continue
        work: list[tuple[LaneKey, int]] = [(root, 0)]
        while work:
            lane, child = work.pop()
            if child == 0:
                index[lane] = low[lane] = len(index)
                stack.append(lane)
                on_stack.add(lane)
            nexts = graph.successors[lane]
            if child > 0:
                low[lane] = min(low[lane], low[nexts[child - 1]])
            while child < len(nexts) and nexts[child] in index:
                if nexts[child] in on_stack:
                    low[lane] = min(low[lane], index[nexts[child]])
                child += 1
            if child < len(nexts):
                work.append((lane, child + 1))
                work.append((nexts[child], 0))
                continue
            if low[lane] == index[lane]:
                component: list[LaneKey] = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == lane:
                        break
                components.append(component)
    return components


def random_route(
    graph: LaneGraph,
    length_m: float,
    rng: np.random.Generator,
    *,
    start: LaneKey | None = None,
    longest: Mapping[LaneKey, float] | None = None,
) -> tuple[LaneKey, ...] | None:
    """A random route of whole lanes whose summed length is at least ``length_m``.

    The start lane (unless given) and each next lane are drawn uniformly among those from
    which the remaining length can still be driven, so the walk never dead-ends. Returns
    None when the map (or ``start``) has no route that long. ``longest`` may pass a
    precomputed ``longest_route_lengths(graph)`` when drawing many routes.
    """
    if not (math.isfinite(length_m) and length_m > 0):
        raise ValueError(f"route length must be a finite number > 0 m, got {length_m!r}")
    if start is not None:
        _require_lane(graph, start, "start")
    reach = longest_route_lengths(graph) if longest is None else longest

    def drivable(lanes: Sequence[LaneKey], needed: float) -> list[LaneKey]:
        return [lane for lane in lanes if reach[lane] >= needed - LENGTH_TOLERANCE_M]

    firsts = drivable(graph.lanes if start is None else (start,), length_m)
    if not firsts:
        return None
    route = [firsts[rng.integers(len(firsts))]]
    remaining = length_m - graph.lengths[route[0]]
    while remaining > LENGTH_TOLERANCE_M:
        nexts = drivable(graph.successors[route[-1]], remaining)
        route.append(nexts[rng.integers(len(nexts))])
        remaining -= graph.lengths[route[-1]]
    return tuple(route)
