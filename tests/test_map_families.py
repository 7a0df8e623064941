"""tools/map_families.py: seeded maps, valid for the engine, within the family ranges, LHT on the left."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from functools import lru_cache

import numpy as np
import pytest

from cold_maps.evaluation.fit import fit_plan
from cold_maps.evaluation.scenarios import INTERPOLATIONS, MapPlan, params_for_gaps, scenarios_for
from cold_maps.network.continuity import link_gaps, record_length_mismatches, reference_line_defects
from cold_maps.network.lane_graph import build_lane_graph
from cold_maps.network.route import borders_in_driving_direction
from cold_maps.network.routing import longest_route_lengths
from cold_maps.opendrive import parse_opendrive
from cold_maps.opendrive.model import OpenDriveMap
from cold_maps.opendrive.reference_line import reference_pose
from cold_maps.opendrive.sampling import sample_lane_borders, sample_road
from cold_maps.simulation.drive import PAPER_GAPS_M
from tests.conftest import PROJECT_ROOT, load_tool

families = load_tool("map_families")
SEEDS = range(6)
CASES = [(family, seed) for family in families.FAMILIES for seed in SEEDS]


@lru_cache(maxsize=None)
def loaded(family: str, seed: int) -> OpenDriveMap:
    return parse_opendrive(families.generate(family, seed), path=f"{families.map_name(family, seed)}.xodr",
                           strict=True)


def test_same_bytes_in_another_process() -> None:
    code = ("import sys, hashlib; sys.path.insert(0, 'tools'); import map_families as m; "
            "print(';'.join(hashlib.sha256(m.generate(f, 3)).hexdigest() for f in m.FAMILIES))")
    env = dict(os.environ, PYTHONHASHSEED="12345", PYTHONPATH=str(PROJECT_ROOT))
    other = subprocess.run([sys.executable, "-c", code], cwd=PROJECT_ROOT, env=env, capture_output=True, text=True,
                           check=True).stdout.strip().split(";")
    import hashlib

    assert other == [hashlib.sha256(families.generate(f, 3)).hexdigest() for f in families.FAMILIES]


@pytest.mark.parametrize("family", families.FAMILIES)
def test_seeds_give_different_maps(family: str) -> None:
    assert len({families.generate(family, seed) for seed in SEEDS}) == len(SEEDS)


@pytest.mark.parametrize(("family", "seed"), CASES)
def test_valid_for_the_engine_and_long_enough_for_the_default_plan(family: str, seed: int) -> None:
    odr_map = loaded(family, seed)
    graph = build_lane_graph(odr_map)
    assert not graph.issues
    assert reference_line_defects(odr_map) == []
    assert record_length_mismatches(odr_map) == []
    assert link_gaps(graph) == []
    plan = MapPlan(PROJECT_ROOT / "map.xodr", scenarios_for(PAPER_GAPS_M, INTERPOLATIONS), frames=100,
                   params=params_for_gaps(PAPER_GAPS_M))
    fitted = fit_plan(plan, max(longest_route_lengths(graph).values()), where=family)
    assert fitted.notes == ()


@pytest.mark.parametrize(("family", "seed"), CASES)
def test_lane_widths_and_counts_within_the_family_ranges(family: str, seed: int) -> None:
    low, high = families.WIDTH_RANGE_M
    for road in loaded(family, seed).roads.values():
        for index, section in enumerate(road.lane_sections):
            for side in (section.left, section.right):
                assert len(side) == 0 or families.LANES_RANGE[0] <= len(side) <= families.LANES_RANGE[1]
            assert section.left or section.right
            if road.junction == "-1" and family in ("curves", "lanes", "junctions"):
                assert section.left and section.right  # two-way roads
            for lane in (*section.left, *section.right):
                samples = sample_lane_borders(road, index, lane.id, step=1.0)
                width = np.hypot(*(samples.outer[:, :2] - samples.inner[:, :2]).T)
                assert width.max() <= high + 1e-9, (road.id, lane.id)
                # a lane is 2.75-3.75 m wide, or opens from / closes to zero width
                assert width.min() >= low - 1e-9 or min(width[0], width[-1]) < 1e-9, (road.id, lane.id)


@pytest.mark.parametrize("seed", SEEDS)
def test_junction_arms_cross_at_30_to_150_degrees(seed: int) -> None:
    odr_map = loaded("junctions", seed)
    arms = [road for road in odr_map.roads.values() if road.junction == "-1"]
    assert len(arms) in (3, 4)
    headings = [road.plan_view[0].hdg for road in arms]  # every arm starts at the junction, heading out
    low, high = (math.radians(a) for a in families.CROSSING_ANGLE_RANGE_DEG)
    for i, heading in enumerate(headings):
        nearest = min(abs(math.remainder(other - heading, 2 * math.pi)) for j, other in enumerate(headings) if j != i)
        assert low - 1e-9 <= nearest <= high + 1e-9
    counts = {(len(road.lane_sections[0].left), len(road.lane_sections[0].right)) for road in arms}
    assert len(counts) == 1 and len(counts.pop()) == 2
    connecting = [road for road in odr_map.roads.values() if road.junction != "-1"]
    assert len(connecting) == len(arms) * (len(arms) - 1)  # every movement but U-turns


@pytest.mark.parametrize(("family", "seed"), CASES)
def test_odd_seeds_drive_on_the_left(family: str, seed: int) -> None:
    odr_map = loaded(family, seed)
    rule = "LHT" if seed % 2 else "RHT"
    assert {road.rule for road in odr_map.roads.values()} == {rule}
    for road in odr_map.roads.values():
        section = road.lane_sections[0]
        for lane in (*section.left, *section.right):
            s, left, right = borders_in_driving_direction(road, sample_lane_borders(road, 0, lane.id, step=1.0))
            middle = len(s) // 2
            ahead = 0.5 * (left[middle + 1, :2] + right[middle + 1, :2]) - 0.5 * (left[middle, :2] + right[middle, :2])
            x, y, _ = reference_pose(road, np.array([s[middle]]))
            beside = 0.5 * (left[middle, :2] + right[middle, :2]) - np.array([x[0], y[0]])
            # the reference line (the centre line of a two-way road) is on the driver's right in LHT
            on_left = ahead[0] * beside[1] - ahead[1] * beside[0] > 0.0
            assert on_left == (rule == "LHT"), (road.id, lane.id)


@pytest.mark.parametrize("seed", SEEDS)
def test_roundabouts_turn_counter_clockwise_in_rht_and_clockwise_in_lht(seed: int) -> None:
    odr_map = loaded("roundabouts", seed)
    ring = [road for road in odr_map.roads.values() if road.name.startswith("ring_")]
    assert len(ring) in (3, 4)
    for road in ring:
        _, left, right = borders_in_driving_direction(road, sample_road(road, 1.0)[0])
        centre = 0.5 * (left[:, :2] + right[:, :2])
        turning = np.sum(centre[:-1, 0] * centre[1:, 1] - centre[:-1, 1] * centre[1:, 0])  # about the ring centre
        assert (turning > 0) == (seed % 2 == 0)


def test_unknown_family_and_negative_seed_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown map family 'hills'"):
        families.build("hills", 0)
    with pytest.raises(ValueError, match="seed must be >= 0"):
        families.build("curves", -1)


def test_start_before_inverts_the_layout() -> None:
    segments = (families.line(20.0), families.spiral(30.0, 0.0, 0.02), families.arc(15.0, 0.02),
                families.spiral(25.0, 0.02, -0.01))
    start = families.Pose(3.0, -4.0, 0.7)
    end = families.chain_end(start, segments)
    again = families.start_before(end, segments)
    assert (again.x, again.y) == pytest.approx((start.x, start.y), abs=1e-9)
    assert math.remainder(again.hdg - start.hdg, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
