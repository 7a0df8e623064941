"""MapLocator: round trips road → world → road on hand-built maps and on CARLA Town04."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cold_maps.opendrive.lanes import section_borders
from cold_maps.opendrive.model import CubicPoly, Geometry, Header, Lane, LaneSection, OpenDriveMap, Road
from cold_maps.opendrive.projection import MapLocator
from cold_maps.opendrive.sampling import road_to_world

ORIGIN = (7e5, -3e5)


def lanes(left: tuple[float, ...], right: tuple[float, ...]) -> tuple[tuple[Lane, ...], tuple[Lane, ...]]:
    return (
        tuple(Lane(i + 1, "driving", widths=(CubicPoly(0.0, w, 0.0, 0.0, 0.0),)) for i, w in enumerate(left)),
        tuple(Lane(-(i + 1), "driving", widths=(CubicPoly(0.0, w, 0.0, 0.0, 0.0),)) for i, w in enumerate(right)),
    )


def road(road_id: str, plan_view: tuple[Geometry, ...], left=(3.5,), right=(3.5, 3.0), offset=0.0) -> Road:
    length = plan_view[-1].s + plan_view[-1].length
    lft, rgt = lanes(left, right)
    section = LaneSection(0.0, length, False, lft, Lane(0, "none"), rgt)
    offsets = (CubicPoly(0.0, offset, 0.0, 0.0, 0.0),)
    return Road(road_id, "", length, "-1", "RHT", None, None, plan_view, (), offsets, (section,))


def hand_map() -> OpenDriveMap:
    x0, y0 = ORIGIN
    roads = [
        road("arc", (Geometry("arc", 0.0, x0, y0, 0.0, 80.0, curvature=0.02),), offset=0.4),
        road(
            "spiral",
            (Geometry("spiral", 0.0, x0, y0 + 200.0, 1.0, 120.0, curv_start=-0.01, curv_end=0.03),),
            left=(),
            right=(3.0, 0.0, 2.5),
        ),
        road(
            "param",
            (
                Geometry("line", 0.0, x0 - 300.0, y0, 0.5, 20.0),
                Geometry(
                    "paramPoly3", 20.0, x0 - 300.0 + 20 * math.cos(0.5), y0 + 20 * math.sin(0.5), 0.5, 60.0,
                    bu=58.0, cv=6.0, dv=-2.0, p_range="normalized",
                ),
            ),
        ),
    ]
    return OpenDriveMap("", Header(1, 8), {r.id: r for r in roads}, {})


@pytest.fixture(scope="module")
def locator() -> MapLocator:
    return MapLocator(hand_map())


def random_lane_points(odr_map: OpenDriveMap, rng: np.random.Generator, count: int, roads: list[Road]):
    """(road, s, t, lane id) of random points strictly inside random lanes, away from road ends."""
    for _ in range(count):
        r = roads[rng.integers(len(roads))]
        s = float(rng.uniform(1.0, r.length - 1.0))
        index = max(i for i, sec in enumerate(r.lane_sections) if sec.s <= s)
        borders = {k: v for k, v in section_borders(r, index, np.array([s])).items() if k != 0}
        wide = [k for k, (a, b) in borders.items() if abs(a[0] - b[0]) > 0.2]
        if not wide:
            continue
        lane_id = wide[rng.integers(len(wide))]
        inner, outer = borders[lane_id][0][0], borders[lane_id][1][0]
        t = inner + rng.uniform(0.05, 0.95) * (outer - inner)
        yield r, s, float(t), lane_id


def test_round_trip_on_every_geometry_kind(locator):
    odr_map = hand_map()
    rng = np.random.default_rng(7)
    checked = 0
    for r, s, t, lane_id in random_lane_points(odr_map, rng, 150, list(odr_map.roads.values())):
        x, y = road_to_world(r, np.array([s]), np.array([t]))
        found = locator.locate(float(x[0]), float(y[0]))
        assert found is not None
        assert (found.road_id, found.lane_id, found.section) == (r.id, lane_id, 0)
        assert abs(found.s - s) < 1e-3 and abs(found.t - t) < 1e-3
        assert found.distance == 0.0
        checked += 1
    assert checked > 100


def test_point_outside_the_road_reports_distance_or_none(locator):
    arc = hand_map().roads["arc"]
    # outer border of lane 1 is at t = 0.4 + 3.5: a point 0.6 m further out
    x, y = road_to_world(arc, np.array([30.0]), np.array([3.9 + 0.6]))
    found = locator.locate(float(x[0]), float(y[0]))
    assert found is not None and found.lane_id == 1
    assert found.distance == pytest.approx(0.6, abs=1e-6)
    assert found.t == pytest.approx(4.5, abs=1e-6)
    x, y = road_to_world(arc, np.array([30.0]), np.array([3.9 + 1.5]))
    assert locator.locate(float(x[0]), float(y[0])) is None
    assert locator.locate(0.0, 0.0) is None


def test_point_beyond_the_road_end_counts_the_overshoot(locator):
    x0, y0 = ORIGIN
    # the arc road starts at ORIGIN heading +x: 0.5 m behind its start, inside lane -1
    found = locator.locate(x0 - 0.5, y0 - 1.0)
    assert found is not None and found.road_id == "arc" and found.s == 0.0
    assert found.distance == pytest.approx(0.5, abs=1e-9)


def test_locator_rejects_bad_input():
    with pytest.raises(ValueError, match="not finite"):
        MapLocator(hand_map()).locate(float("nan"), 0.0)
    with pytest.raises(ValueError, match="max_distance"):
        MapLocator(hand_map(), max_distance=-1.0)
    with pytest.raises(ValueError, match="has no road"):
        MapLocator(OpenDriveMap("empty.xodr", Header(1, 8), {}, {}))


@pytest.fixture(scope="module")
def town04(town04_path):
    from cold_maps.opendrive.parser import load_opendrive

    odr_map = load_opendrive(town04_path)
    return odr_map, MapLocator(odr_map)


def test_round_trip_on_town04_roads_outside_junctions(town04):
    odr_map, town_locator = town04
    roads = [r for r in odr_map.roads.values() if r.junction == "-1" and r.length > 5.0]
    rng = np.random.default_rng(2024)
    checked = 0
    for r, s, t, lane_id in random_lane_points(odr_map, rng, 120, roads):
        x, y = road_to_world(r, np.array([s]), np.array([t]))
        found = town_locator.locate(float(x[0]), float(y[0]))
        assert found is not None
        assert (found.road_id, found.lane_id) == (r.id, lane_id)
        assert abs(found.s - s) < 1e-3 and abs(found.t - t) < 1e-3
        checked += 1
    assert checked > 100


def test_points_on_town04_junction_roads_map_back_to_themselves(town04):
    # connecting roads overlap, so the road found may be another one; its (s, t) must
    # still map back onto the point, inside a lane
    odr_map, town_locator = town04
    roads = [r for r in odr_map.roads.values() if r.junction != "-1"]
    rng = np.random.default_rng(11)
    checked = 0
    for r, s, t, _ in random_lane_points(odr_map, rng, 80, roads):
        x, y = road_to_world(r, np.array([s]), np.array([t]))
        found = town_locator.locate(float(x[0]), float(y[0]))
        assert found is not None and found.distance == 0.0
        fx, fy = road_to_world(odr_map.roads[found.road_id], np.array([found.s]), np.array([found.t]))
        assert math.hypot(fx[0] - x[0], fy[0] - y[0]) < 1e-3
        checked += 1
    assert checked > 50
