"""The built wheel is a complete tool: bundled maps as package data, LICENSE, ``py.typed``
markers, console scripts, and ``cold-eval --paper`` runs from an install outside the
repository."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

from conftest import BUNDLED_MAPS_DIR, PROJECT_ROOT

PACKAGES = ("cold_maps", "fusion", "converters", "gt_matching")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A wheel built from the working tree (no dependencies, no build isolation: the test
    environment carries setuptools and wheel)."""
    out = tmp_path_factory.mktemp("wheel")
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation", "-w", str(out),
         str(PROJECT_ROOT)], capture_output=True, text=True, timeout=300)
    if build.returncode != 0:
        pytest.fail(f"wheel build failed: {build.stderr[-2000:]}")
    (found,) = out.glob("cold_maps-*.whl")
    return found


def test_wheel_carries_maps_license_and_type_markers(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    bundled = sorted(p.name for p in BUNDLED_MAPS_DIR.glob("*.xodr"))
    assert bundled, "no bundled maps in the source tree"
    assert {f"cold_maps/maps/{name}" for name in bundled} <= names
    assert {f"{package}/py.typed" for package in PACKAGES} <= names
    assert any(name.endswith(".dist-info/licenses/LICENSE") for name in names)
    assert "cold_maps/__main__.py" in names


def test_wheel_metadata_names_license_classifiers_and_scripts(wheel: Path) -> None:
    archive = zipfile.ZipFile(wheel)
    dist_info = next(n.split("/")[0] for n in archive.namelist() if n.endswith(".dist-info/METADATA"))
    metadata = Parser().parsestr(archive.read(f"{dist_info}/METADATA").decode())
    assert metadata["License-Expression"] == "MIT"
    assert "Typing :: Typed" in metadata.get_all("Classifier")
    scripts = archive.read(f"{dist_info}/entry_points.txt").decode()
    for script in ("cold-maps", "cold-eval", "cold-fuse"):
        assert f"{script} = cold_maps.cli." in scripts


def test_installed_wheel_runs_the_paper_outside_the_repository(wheel: Path, tmp_path: Path) -> None:
    target = tmp_path / "site"
    install = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target),
                              str(wheel)], capture_output=True, text=True, timeout=300)
    assert install.returncode == 0, install.stderr[-2000:]
    out = tmp_path / "paper"
    code = ("import sys, cold_maps.evaluation.paper as p; print(p.BUNDLED_MAPS_DIR); "
            "from cold_maps.cli.evaluate import main; sys.exit(main(sys.argv[1:]))")
    run = subprocess.run([sys.executable, "-c", code, "--paper", "--speed", "250", "--no-mcap", "--no-plots",
                          "--out", str(out)], capture_output=True, text=True, timeout=600, cwd=tmp_path,
                         env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)})
    assert run.returncode == 0, run.stderr[-2000:]
    assert Path(run.stdout.splitlines()[0]).resolve().is_relative_to(target.resolve())
    records = json.loads((out / "metrics.json").read_text())["scenarios"]
    assert {r["map"] for r in records} == {"straight", "curve90", "rural"}


def test_python_dash_m_cold_maps_is_the_cold_maps_command() -> None:
    run = subprocess.run([sys.executable, "-m", "cold_maps", "info", str(BUNDLED_MAPS_DIR / "straight.xodr")],
                         capture_output=True, text=True, timeout=120, cwd=PROJECT_ROOT)
    assert run.returncode == 0, run.stderr
    assert "roads" in run.stdout
