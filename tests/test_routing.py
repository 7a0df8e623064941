"""Routing (Dijkstra, longest routes, seeded random routes) and route geometry."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from graph_maps import JUNCTION_RADIUS_M, LANE_WIDTH_M, junction_map, odr_map, with_rule
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.network.lane_graph import LaneGraph, LaneKey, build_lane_graph
from cold_maps.network.route import Route, RoutePiece, route_from_lanes
from cold_maps.network.routing import (
    NoRouteError,
    longest_route_lengths,
    random_route,
    route_length,
    shortest_route,
)

HALF = LANE_WIDTH_M / 2
QUARTER_INNER = (JUNCTION_RADIUS_M - HALF) * math.pi / 2
QUARTER_OUTER = (JUNCTION_RADIUS_M + HALF) * math.pi / 2


def k(road_id: str, lane_id: int, section_index: int = 0) -> LaneKey:
    return LaneKey(road_id, section_index, lane_id)


@pytest.fixture(scope="module")
def graph() -> LaneGraph:
    return build_lane_graph(junction_map())


def synthetic_graph(lengths: list[float], edges: set[tuple[int, int]]) -> LaneGraph:
    """A lane graph with nodes 0..n-1 (road ids "0", "1", ...) and no geometry."""
    keys = [k(str(i), -1) for i in range(len(lengths))]
    succ = {key: tuple(sorted(keys[b] for a, b in edges if a == i)) for i, key in enumerate(keys)}
    pred = {key: tuple(sorted(keys[a] for a, b in edges if b == i)) for i, key in enumerate(keys)}
    return LaneGraph(odr_map([]), ("driving",), dict(zip(keys, lengths)), succ, pred, ())


graphs = st.integers(2, 6).flatmap(
    lambda n: st.tuples(
        st.lists(st.floats(0.5, 100.0), min_size=n, max_size=n),
        st.sets(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=2 * n),
    )
)


def _simple_paths(n: int, edges: set[tuple[int, int]]):
    for size in range(1, n + 1):
        for path in itertools.permutations(range(n), size):
            if all((a, b) in edges for a, b in zip(path, path[1:])):
                yield path


@settings(max_examples=60, deadline=None)
@given(graphs)
def test_shortest_route_is_the_cheapest_simple_path(case) -> None:
    lengths, edges = case
    graph = synthetic_graph(lengths, edges)
    n = len(lengths)
    best: dict[tuple[int, int], float] = {}
    for path in _simple_paths(n, edges):
        cost = sum(lengths[i] for i in path)
        best[path[0], path[-1]] = min(best.get((path[0], path[-1]), math.inf), cost)
    for a, b in itertools.product(range(n), repeat=2):
        if (a, b) in best:
            route = shortest_route(graph, graph.lanes[a], graph.lanes[b])
            assert route[0] == graph.lanes[a] and route[-1] == graph.lanes[b]
            assert all(y in graph.successors[x] for x, y in zip(route, route[1:]))
            assert route_length(graph, route) == pytest.approx(best[a, b])
        else:
            with pytest.raises(NoRouteError):
                shortest_route(graph, graph.lanes[a], graph.lanes[b])


@settings(max_examples=60, deadline=None)
@given(graphs)
def test_longest_route_lengths_brute_force(case) -> None:
    lengths, edges = case
    graph = synthetic_graph(lengths, edges)
    n = len(lengths)
    on_cycle = {p[0] for p in _simple_paths(n, edges) if (p[-1], p[0]) in edges}
    longest = longest_route_lengths(graph)
    for i in range(n):
        paths = [p for p in _simple_paths(n, edges) if p[0] == i]
        if any(set(p) & on_cycle for p in paths):
            assert longest[graph.lanes[i]] == math.inf
        else:
            expected = max(sum(lengths[j] for j in p) for p in paths)
            assert longest[graph.lanes[i]] == pytest.approx(expected)


def test_longest_route_lengths_deep_chain_has_no_recursion_limit() -> None:
    n = 5000
    graph = synthetic_graph([1.0] * n, {(i, i + 1) for i in range(n - 1)})
    assert longest_route_lengths(graph)[graph.lanes[0]] == pytest.approx(n)


def test_shortest_route_through_junction(graph: LaneGraph) -> None:
    assert shortest_route(graph, k("W", -1), k("S", -1)) == (k("W", -1), k("right", -1), k("S", -1))
    route = shortest_route(graph, k("W", -1), k("N", -1))
    assert route_length(graph, route) == pytest.approx(200 + QUARTER_OUTER, abs=0.01)
    assert shortest_route(graph, k("E", -1), k("E", -1)) == (k("E", -1),)


def test_shortest_route_errors(graph: LaneGraph) -> None:
    with pytest.raises(NoRouteError, match=r"no route from lane \('S', 0, -1\)"):
        shortest_route(graph, k("S", -1), k("W", -1))
    with pytest.raises(ValueError, match=r"goal lane \('X', 0, -1\) is not in the lane graph"):
        shortest_route(graph, k("W", -1), k("X", -1))


def test_random_route_is_seeded_valid_and_long_enough(graph: LaneGraph) -> None:
    routes = {random_route(graph, 150.0, np.random.default_rng(seed)) for seed in range(20)}
    assert None not in routes
    for route in routes:
        assert route_length(graph, route) >= 150.0
        assert all(b in graph.successors[a] for a, b in zip(route, route[1:]))
    # a 150 m route must start on W (every other lane run is at most 100 m + a turn)
    assert {route[0] for route in routes} == {k("W", -1)}
    assert len(routes) == 3  # right, left and straight are all drawn
    again = random_route(graph, 150.0, np.random.default_rng(7))
    assert again == random_route(graph, 150.0, np.random.default_rng(7))


def test_random_route_too_long_for_the_map(graph: LaneGraph) -> None:
    longest = 220.0  # W → straight → E
    assert random_route(graph, longest - 0.1, np.random.default_rng(1)) is not None
    assert random_route(graph, longest + 0.1, np.random.default_rng(1)) is None
    assert random_route(graph, 150.0, np.random.default_rng(1), start=k("E", -1)) is None
    with pytest.raises(ValueError, match="route length"):
        random_route(graph, float("nan"), np.random.default_rng(1))


def test_random_route_on_a_cycle_has_any_length() -> None:
    graph = synthetic_graph([10.0, 20.0], {(0, 1), (1, 0)})
    route = random_route(graph, 1000.0, np.random.default_rng(3))
    assert route is not None and 1000.0 <= route_length(graph, route) < 1020.0


def _cross(route: Route) -> np.ndarray:
    """z of tangent × (left − right) at every point; > 0 when left is on the left."""
    tangent = np.gradient(route.centre, axis=0)
    across = route.left - route.right
    return tangent[:, 0] * across[:, 1] - tangent[:, 1] * across[:, 0]


def _check_route_invariants(route: Route, step: float) -> None:
    assert route.centre.shape == route.left.shape == route.right.shape == (len(route.distance), 2)
    steps = np.diff(route.distance)
    assert (steps > 0).all() and steps.max() <= step * (1 + 1e-6) + 1e-9
    np.testing.assert_allclose(np.hypot(*(route.left - route.right).T), LANE_WIDTH_M, atol=1e-9)
    np.testing.assert_allclose(route.centre, 0.5 * (route.left + route.right), atol=1e-12)
    assert (_cross(route) > 0).all()


def test_route_geometry_right_turn(graph: LaneGraph) -> None:
    lanes = (k("W", -1), k("right", -1), k("S", -1))
    route = route_from_lanes(graph, lanes, step=0.1)
    _check_route_invariants(route, 0.1)
    np.testing.assert_allclose(route.centre[0], [-100.0, -HALF], atol=1e-9)
    np.testing.assert_allclose(route.centre[-1], [10.0 - HALF, -110.0], atol=1e-9)
    np.testing.assert_allclose(route.left[0], [-100.0, 0.0], atol=1e-9)
    assert route.length == pytest.approx(200 + QUARTER_INNER, abs=1e-3)
    # on the turn, every centre point is 8.25 m from the arc centre (0, -10)
    turn = (route.centre[:, 0] > 0) & (route.centre[:, 1] > -10)
    np.testing.assert_allclose(
        np.hypot(route.centre[turn, 0], route.centre[turn, 1] + 10.0), JUNCTION_RADIUS_M - HALF, atol=1e-9
    )
    assert route.pieces[1] == RoutePiece("right", 0, -1, 0.0, pytest.approx(JUNCTION_RADIUS_M * math.pi / 2))


def test_route_geometry_against_s_and_left_hand_traffic() -> None:
    rht = build_lane_graph(junction_map())
    straight = route_from_lanes(rht, (k("W", -1), k("straight", 1), k("E", -1)), step=0.5)
    _check_route_invariants(straight, 0.5)
    np.testing.assert_allclose(straight.centre[:, 1], -HALF, atol=1e-9)
    np.testing.assert_allclose(straight.left[:, 1], 0.0, atol=1e-9)
    assert straight.length == pytest.approx(220.0, abs=1e-9)
    assert straight.pieces[1] == RoutePiece("straight", 0, 1, 20.0, 0.0)
    # the same map driven on the left: E → straight → W along -x, left border at y = -3.5
    lht = build_lane_graph(with_rule(junction_map(), "LHT"))
    back = route_from_lanes(lht, (k("E", -1), k("straight", 1), k("W", -1)), step=0.5)
    _check_route_invariants(back, 0.5)
    np.testing.assert_allclose(back.centre[[0, -1]], [[120.0, -HALF], [-100.0, -HALF]], atol=1e-9)
    np.testing.assert_allclose(back.left[:, 1], -LANE_WIDTH_M, atol=1e-9)
    np.testing.assert_allclose(back.centre, straight.centre[::-1], atol=1e-9)


def test_route_from_lanes_errors(graph: LaneGraph) -> None:
    with pytest.raises(ValueError, match="at least one lane"):
        route_from_lanes(graph, ())
    with pytest.raises(ValueError, match=r"\('S', 0, -1\) does not follow lane \('W', 0, -1\)"):
        route_from_lanes(graph, (k("W", -1), k("S", -1)))
    with pytest.raises(ValueError, match=r"\('W', 0, 5\) is not in the lane graph"):
        route_from_lanes(graph, (k("W", 5),))


@pytest.mark.parametrize("town", ["Town01", "Town04"])
def test_carla_random_routes_of_300_m(town: str, town01_path, town04_path) -> None:
    from cold_maps.opendrive.parser import load_opendrive

    path = {"Town01": town01_path, "Town04": town04_path}[town]
    graph = build_lane_graph(load_opendrive(path))
    longest = longest_route_lengths(graph)
    rng = np.random.default_rng(2024)
    for _ in range(3):
        lanes = random_route(graph, 300.0, rng, longest=longest)
        assert lanes is not None
        route = route_from_lanes(graph, lanes, step=0.5)
        assert route.length >= 300.0 - 0.05
        assert np.isfinite(route.left).all() and np.isfinite(route.right).all()
        assert (_cross(route) > 0).mean() > 0.99


@pytest.fixture(scope="module")
def bundled_junction() -> LaneGraph:
    from conftest import bundled_map

    from cold_maps.opendrive.parser import load_opendrive

    return build_lane_graph(load_opendrive(bundled_map("junction")))


def test_bundled_junction_routes_have_closed_form_lengths(bundled_junction: LaneGraph) -> None:
    """150 m arm in, a right turn (lane radius 13 m), straight (30 m) or left turn (17 m),
    150 m arm out: every entry-to-exit route is one of the three, four times each."""
    graph = bundled_junction
    entries = [lane for lane in graph.lanes if not graph.predecessors[lane]]
    exits = [lane for lane in graph.lanes if not graph.successors[lane]]
    assert len(entries) == len(exits) == 4
    lengths = []
    for a in entries:
        for b in exits:
            if a.road_id == b.road_id:
                with pytest.raises(NoRouteError):
                    shortest_route(graph, a, b)
                continue
            lanes = shortest_route(graph, a, b)
            route = route_from_lanes(graph, lanes, step=0.1)
            assert route.length == pytest.approx(route_length(graph, lanes), abs=0.01)
            assert np.diff(route.distance).max() < 0.15
            assert (_cross(route) > 0).all()
            lengths.append(route.length)
    expected = [300 + 13 * math.pi / 2, 330.0, 300 + 17 * math.pi / 2]
    nearest = [min(range(3), key=lambda i: abs(length - expected[i])) for length in lengths]
    assert sorted(nearest) == [0] * 4 + [1] * 4 + [2] * 4
    np.testing.assert_allclose(lengths, [expected[i] for i in nearest], atol=0.01)


def test_bundled_highway_random_routes_are_continuous() -> None:
    from conftest import bundled_map

    from cold_maps.opendrive.parser import load_opendrive

    graph = build_lane_graph(load_opendrive(bundled_map("highway")))
    rng = np.random.default_rng(11)
    for _ in range(4):
        lanes = random_route(graph, 500.0, rng)
        assert lanes is not None
        route = route_from_lanes(graph, lanes, step=0.5)
        assert route.length >= 500.0 - 0.05
        assert np.diff(route.distance).max() < 0.6
        assert (_cross(route) > 0).all()
    assert random_route(graph, 2000.0, rng) is None
