"""Our lane borders against commonroad-scenario-designer's independent OpenDRIVE code."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import PROJECT_ROOT

TOOL = PROJECT_ROOT / "tools" / "crosscheck_opendrive.py"
STEP_M = 1.0


@pytest.fixture(scope="module")
def tool():
    """tools/crosscheck_opendrive.py as a module (tools/ is not a package)."""
    spec = importlib.util.spec_from_file_location("crosscheck_opendrive", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    del sys.modules[spec.name]


@pytest.mark.parametrize("town", ["town01_path", "town04_path"])
def test_driving_lane_borders_agree_with_crdesigner(town, request, tool):
    path: Path = request.getfixturevalue(town)
    result = tool.crosscheck(path, step=STEP_M)
    assert result.missing_in_theirs == () and result.missing_in_ours == ()
    assert result.lanes_compared > 100
    assert result.distances.size > 10_000
    # the residual is the maps' own reference-line gaps between <geometry> records (up to
    # ~1.4 mm in Town04), which the two implementations resolve on different sides
    assert np.percentile(result.distances, 99) <= 1e-3
    assert result.distances.max() <= 5e-3


def test_point_to_polyline_distances(tool):
    polyline = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    points = np.array([[0.5, 0.3], [2.0, 1.0], [-1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(tool.point_to_polyline(points, polyline), [0.3, 1.0, 1.0, 0.0])


def test_cli_prints_one_line_per_map_and_fails_cleanly(tmp_path):
    missing = tmp_path / "absent.xodr"
    run = subprocess.run([sys.executable, str(TOOL), str(missing)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1
    assert run.stdout == ""
    assert "absent.xodr" in run.stderr and "Traceback" not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
