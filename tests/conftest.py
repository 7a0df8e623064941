"""Shared fixtures: paths of the bundled maps and of the CARLA towns in ../shared; the
hypothesis profiles; a conversion cache of the suite's own."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import HealthCheck, settings

PROJECT_ROOT = Path(__file__).resolve().parents[1]
BUNDLED_MAPS_DIR = PROJECT_ROOT / "maps"
CARLA_MAPS_DIR = PROJECT_ROOT.parent / "shared" / "maps" / "carla"
TEST_CACHE_DIR = PROJECT_ROOT / ".pytest_cache" / "cold-maps"

# "ci" (chosen when $CI is set, as on the CI runner): the same examples on every run, no
# example database; "dev" (otherwise): random examples, failures replayed from .hypothesis/.
# Neither depends on the machine's speed (no deadline, no too-slow health check: a loaded
# machine made examples time out). Choose one with --hypothesis-profile.
_UNTIMED = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}
settings.register_profile("ci", derandomize=True, database=None, print_blob=True, **_UNTIMED)
settings.register_profile("dev", **_UNTIMED)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

# Conversions (and matplotlib's font cache) go to caches of the suite's own (removed by
# `make clean`), never the user's; tests that exercise the cache location set their own.
os.environ["COLD_MAPS_CACHE_DIR"] = str(TEST_CACHE_DIR)
os.environ["MPLCONFIGDIR"] = str(PROJECT_ROOT / ".pytest_cache" / "matplotlib")  # matplotlib's font cache too


def load_tool(name: str) -> ModuleType:
    """The script tools/<name>.py imported as module ``name``."""
    spec = importlib.util.spec_from_file_location(name, PROJECT_ROOT / "tools" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def carla_map(name: str) -> Path:
    """Path of a CARLA town in ../shared/maps/carla; skips the test when it is absent."""
    path = CARLA_MAPS_DIR / f"{name}.xodr"
    if not path.is_file():
        pytest.skip(f"CARLA map {path} not present (../shared/maps/carla is outside this clone)")
    return path


def bundled_map(name: str) -> Path:
    """Path of a bundled map in maps/; skips the test when it has not been generated."""
    path = BUNDLED_MAPS_DIR / f"{name}.xodr"
    if not path.is_file():
        pytest.skip(f"bundled map {path} not generated (run: make maps)")
    return path


def junction_fork_reach_m(graph, lane) -> float:
    """How far (m) past the fork of the bundled junction a detection going straight on still
    ends inside the turning lane ``lane`` (a connecting road ``*_left_*`` or ``*_right_*``):
    the turn's reference arc of radius R0 = ``JUNCTION_HALF_SIZE_M`` carries one lane of width
    w on its right, centre radius R = R0 + w/2 turning left, R0 − w/2 turning right; a point d
    along the straight lies √(R² + d²) − R off that arc, half a lane width at
    d = √((R + w/2)² − R²)."""
    maps = load_tool("make_maps")
    half = 0.5 * maps.LANE_WIDTH_M
    name = graph.odr_map.roads[lane.road_id].name
    radius = maps.JUNCTION_HALF_SIZE_M + (half if "_left_" in name else -half)
    return ((radius + half) ** 2 - radius**2) ** 0.5


@pytest.fixture(scope="session")
def town01_path() -> Path:
    return carla_map("Town01")


@pytest.fixture(scope="session")
def town04_path() -> Path:
    return carla_map("Town04")
