"""``gt_matching.relations.LaneletRelations`` gives, lanelet by lanelet, what lanelet2's
``RoutingGraph`` gives: the same ``following`` and ``previous`` lanelets in the same order,
and the same ``conflicting`` lanelets, for every lanelet in both orientations; on
synthetic maps (two-way lanelets among them), the engine's ground truth of the bundled
maps, of generated map families and of big-map junctions, and of the shared maps."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import BUNDLED_MAPS_DIR, PROJECT_ROOT, load_tool

SHARED_MAPS = PROJECT_ROOT.parent / "shared" / "maps"


def _as_keys(lanelets) -> list[tuple[int, bool]]:
    return [(int(lanelet.id), bool(lanelet.inverted())) for lanelet in lanelets]


def _assert_same_relations(lanelet_map, graph=None) -> int:
    """Every lanelet's relations agree; returns how many conflicting pairs there are."""
    from converters import routing_graph
    from gt_matching.relations import LaneletRelations

    graph = graph or routing_graph(lanelet_map)
    relations = LaneletRelations(lanelet_map)
    conflicts = 0
    for lanelet in lanelet_map.laneletLayer:
        for oriented in (lanelet, lanelet.invert()):
            for way in ("following", "previous"):
                assert _as_keys(getattr(relations, way)(oriented)) == _as_keys(getattr(graph, way)(oriented)), (
                    way, _as_keys([oriented]))
            expected = sorted(_as_keys(graph.conflicting(oriented)))
            assert sorted(_as_keys(relations.conflicting(oriented))) == expected, ("conflicting", _as_keys([oriented]))
            conflicts += len(expected)
    return conflicts


def _engine_map(path: Path):
    from cold_maps.groundtruth.lanelet2_from_engine import engine_converter
    from cold_maps.opendrive.parser import load_opendrive
    from converters import load_lanelet_map

    return load_lanelet_map(path, converter=engine_converter(load_opendrive(path)))


def test_grid_with_two_way_lanelets() -> None:
    import lanelet2

    from gt_matching.synthetic import grid_network

    lanelet_map, graph = grid_network(2, 2)
    assert _assert_same_relations(lanelet_map, graph) > 0  # the junctions' turns cross
    two_way = [lanelet for lanelet in lanelet_map.laneletLayer][::7]
    for lanelet in two_way:
        lanelet.attributes["one_way"] = "no"
    rules = lanelet2.traffic_rules.create(lanelet2.traffic_rules.Locations.Germany,
                                          lanelet2.traffic_rules.Participants.Vehicle)
    assert rules.canPass(two_way[0].invert())
    assert _assert_same_relations(lanelet_map, lanelet2.routing.RoutingGraph(lanelet_map, rules)) > 0


def test_unknown_and_impassable_lanelets_have_no_relations() -> None:
    from gt_matching.relations import LaneletRelations
    from gt_matching.synthetic import grid_network

    lanelet_map, _ = grid_network(1, 2)
    lanelet = next(iter(lanelet_map.laneletLayer))
    lanelet.attributes["subtype"] = "walkway"
    lanelet.attributes["one_way"] = "yes"
    relations = LaneletRelations(lanelet_map)
    assert relations.following(lanelet) == relations.previous(lanelet) == relations.conflicting(lanelet) == []


@pytest.mark.parametrize("name", sorted(path.stem for path in BUNDLED_MAPS_DIR.glob("*.xodr")))
def test_bundled_maps(name) -> None:
    _assert_same_relations(_engine_map(BUNDLED_MAPS_DIR / f"{name}.xodr"))


@pytest.mark.parametrize("family", ["junctions", "roundabouts", "ramps"])
def test_generated_maps(family, tmp_path) -> None:
    (path,) = load_tool("map_families").write_maps(tmp_path, [family], [2])
    _assert_same_relations(_engine_map(path))


@pytest.mark.parametrize("parallel", [False, True])
def test_big_map_junctions(parallel, tmp_path) -> None:
    big_maps = load_tool("big_maps")
    path = tmp_path / "junction.xodr"
    big_maps.write(big_maps.junction(4, 0, parallel), path)
    conflicts = _assert_same_relations(_engine_map(path))
    if not parallel:  # 16 connections, most of which cross one another
        assert conflicts >= 16 * 8


@pytest.mark.parametrize("name", ["carla/Town01", "esmini/multi_intersections", "esmini/fabriksgatan"])
def test_shared_maps(name) -> None:
    path = SHARED_MAPS / f"{name}.xodr"
    if not path.is_file():
        pytest.skip(f"shared map {path} not present (../shared/maps is outside this clone)")
    assert _assert_same_relations(_engine_map(path)) > 0
