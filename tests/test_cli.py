"""``cold-maps`` CLI: info, export (CSV, GeoJSON), convert, check; one-line errors, atomic output."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import PROJECT_ROOT, bundled_map
from graph_maps import JUNCTION_RADIUS_M, LANE_WIDTH_M, junction_map

from cold_maps.cli import maps
from cold_maps.cli.maps import CSV_HEADER, main, map_info
from cold_maps.opendrive.parser import load_opendrive

ROAD_X0, ROAD_Y0, ROAD_LENGTH = 10.0, 20.0, 50.0
Z0, Z_SLOPE = 1.5, 0.01


def straight_xodr(rule: str) -> str:
    """A 50 m road from (10, 20) along +x, lanes 1 and -1 (3.5 m), sidewalk -2, z = 1.5 + 0.01 s."""
    lane = '<lane id="{id}" type="{type}" level="false"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>'
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="6" name="straight" vendor="test"/>
  <road name="r" length="{ROAD_LENGTH}" id="7" junction="-1" rule="{rule}">
    <planView><geometry s="0" x="{ROAD_X0}" y="{ROAD_Y0}" hdg="0" length="{ROAD_LENGTH}"><line/></geometry></planView>
    <elevationProfile><elevation s="0" a="{Z0}" b="{Z_SLOPE}" c="0" d="0"/></elevationProfile>
    <lanes><laneSection s="0">
      <left>{lane.format(id=1, type="driving")}</left>
      <center><lane id="0" type="none" level="false"/></center>
      <right>{lane.format(id=-1, type="driving")}{lane.format(id=-2, type="sidewalk")}</right>
    </laneSection></lanes>
  </road>
</OpenDRIVE>
"""


@pytest.fixture()
def straight_map(tmp_path: Path) -> Path:
    path = tmp_path / "straight.xodr"
    path.write_text(straight_xodr("RHT"))
    return path


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cold_maps.cli.maps", *args], capture_output=True, text=True, cwd=PROJECT_ROOT, timeout=60
    )


def read_csv(path: Path) -> tuple[list[str], dict[tuple[str, int, int, str], np.ndarray]]:
    """Header and, per border, its (N, 4) rows s, x, y, z in file order."""
    with path.open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        borders: dict[tuple[str, int, int, str], list[list[float]]] = {}
        last = None
        for road_id, section, lane_id, side, *values in reader:
            key = (road_id, int(section), int(lane_id), side)
            assert key == last or key not in borders, f"rows of border {key} are not consecutive"
            borders.setdefault(key, []).append([float(v) for v in values])
            last = key
    return header, {key: np.array(rows) for key, rows in borders.items()}


@pytest.mark.parametrize("rule", ["RHT", "LHT"])
def test_export_csv_columns_on_a_straight_road(tmp_path: Path, rule: str) -> None:
    source = tmp_path / "straight.xodr"
    source.write_text(straight_xodr(rule))
    out = tmp_path / "borders.csv"
    assert main(["export", str(source), "--step", "0.5", "--format", "csv", "-o", str(out)]) == 0
    header, borders = read_csv(out)
    assert tuple(header) == CSV_HEADER
    assert set(borders) == {("7", 0, lane, side) for lane in (1, -1) for side in ("left", "right")}
    forward_lane = -1 if rule == "RHT" else 1
    for (_, _, lane_id, side), rows in borders.items():
        s, x, y, z = rows.T
        forward = lane_id == forward_lane
        # ordered in driving direction, uniform 0.5 m grid, both ends
        assert np.all(np.diff(s) > 0) if forward else np.all(np.diff(s) < 0)
        assert sorted(s) == pytest.approx(np.linspace(0, ROAD_LENGTH, 101))
        np.testing.assert_allclose(x, ROAD_X0 + s, atol=1e-4)
        np.testing.assert_allclose(z, Z0 + Z_SLOPE * s, atol=1e-4)
        # the left border lies at +y of the lane centre when driving +x, at -y when driving -x
        centre_y = ROAD_Y0 + math.copysign(LANE_WIDTH_M / 2, lane_id)
        to_left = (1.0 if side == "left" else -1.0) * (1.0 if forward else -1.0)
        np.testing.assert_allclose(y, centre_y + to_left * LANE_WIDTH_M / 2, atol=1e-4)


def test_export_quotes_road_ids_with_commas_and_percent_signs(tmp_path: Path) -> None:
    source = tmp_path / "odd.xodr"
    source.write_text(straight_xodr("RHT").replace('id="7"', 'id="r%d,7"'))
    out = tmp_path / "borders.csv"
    assert main(["export", str(source), "--step", "5", "-o", str(out)]) == 0
    header, borders = read_csv(out)
    assert {key[0] for key in borders} == {"r%d,7"}
    assert all(len(rows) == 11 for rows in borders.values())


def _assert_left_is_left(borders: dict[tuple[str, int, int, str], np.ndarray]) -> int:
    """Cross-product check on every lane; returns the number of lanes checked."""
    lanes = {key[:3] for key in borders}
    for lane in lanes:
        left, right = borders[(*lane, "left")], borders[(*lane, "right")]
        assert left.shape == right.shape
        np.testing.assert_array_equal(left[:, 0], right[:, 0])
        xy_left, xy_right = left[:, 1:3], right[:, 1:3]
        centre = 0.5 * (xy_left + xy_right)
        tangent = np.gradient(centre, axis=0)
        across = xy_left - xy_right
        cross = tangent[:, 0] * across[:, 1] - tangent[:, 1] * across[:, 0]
        assert (cross > 0).all(), f"left border not left of right border in lane {lane}"
    return len(lanes)


def test_export_side_and_order_on_a_town(tmp_path: Path, town01_path: Path) -> None:
    out = tmp_path / "town01.csv"
    assert main(["export", str(town01_path), "--step", "1.0", "-o", str(out)]) == 0
    _, borders = read_csv(out)
    odr_map = load_opendrive(town01_path)
    driving = sum(
        lane.type == "driving" for road in odr_map.roads.values() for sec in road.lane_sections for lane in sec.lanes
    )
    assert _assert_left_is_left(borders) == driving
    assert np.isfinite(np.concatenate(list(borders.values()))).all()


def test_export_geojson_matches_csv(tmp_path: Path) -> None:
    source = bundled_map("junction")
    csv_out, geo_out = tmp_path / "b.csv", tmp_path / "b.geojson"
    assert main(["export", str(source), "--step", "0.2", "-o", str(csv_out)]) == 0
    assert main(["export", str(source), "--step", "0.2", "--format", "geojson", "--crs", "local", "-o", str(geo_out)]) == 0
    _, borders = read_csv(csv_out)
    assert _assert_left_is_left(borders) > 0
    collection = json.loads(geo_out.read_text())
    assert collection["type"] == "FeatureCollection"
    assert len(collection["features"]) == len(borders)
    for feature in collection["features"]:
        props = feature["properties"]
        rows = borders[(props["road_id"], props["section"], props["lane_id"], props["side"])]
        assert feature["geometry"]["type"] == "LineString"
        np.testing.assert_allclose(feature["geometry"]["coordinates"], rows[:, 1:], atol=1e-9)
        np.testing.assert_allclose(props["s"], rows[:, 0], atol=1e-9)


def test_map_info_counts_of_a_hand_built_map() -> None:
    lines = dict(line.split(": ", 1) for line in map_info(junction_map()))
    assert lines["roads"].startswith("7 (3 in junctions)")
    assert lines["lanes"] == "11 (driving 11)"
    assert lines["junctions"] == "1" and lines["connections"] == "3"
    assert lines["geometry"] == "arc 2, line 5"
    assert lines["revision"] == "1.6"
    quarters = JUNCTION_RADIUS_M * math.pi  # inner + outer quarter turns
    assert float(lines["driving lanes"].split()[0]) == pytest.approx((800 + 20 + quarters) / 1000, abs=1e-3)
    assert lines["lane graph"] == "11 driving lanes, 6 links, 0 issues"


def test_map_info_names_the_lane_graph_issues_under_their_count() -> None:
    from graph_maps import lane, odr_map, road, section, to_road

    ghost = road("A", 50.0, [section(0, 50, right=[lane(-1, succ=[-1])])], succ=to_road("ghost", "start"))
    lines = map_info(odr_map([ghost]))
    at = next(i for i, line in enumerate(lines) if line.startswith("lane graph: "))
    assert lines[at] == "lane graph: 1 driving lanes, 0 links, 1 issues"
    assert lines[at + 1] == "  road A successor: road ghost does not exist"
    assert not lines[at + 2].startswith("  ")


def test_info_is_fast_to_import_and_reports_the_georeference(town04_path: Path) -> None:
    code = (
        "import sys; from cold_maps.cli.maps import main; rc = main(['info', sys.argv[1]]); "
        "heavy = [m for m in ('crdesigner', 'lanelet2', 'matplotlib', 'mcap', 'converters', 'cold_maps.groundtruth.check') "
        "if m in sys.modules]; "
        "print('heavy:', heavy); sys.exit(rc)"
    )
    result = subprocess.run(
        [sys.executable, "-c", code, str(town04_path)], capture_output=True, text=True, cwd=PROJECT_ROOT, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert "heavy: []" in result.stdout
    assert "geoReference: +proj=tmerc" in result.stdout
    assert "revision: 1.4" in result.stdout


def test_export_of_a_broken_file_fails_cleanly(tmp_path: Path) -> None:
    broken = tmp_path / "broken.xodr"
    broken.write_text(straight_xodr("RHT")[:400])
    out = tmp_path / "out.csv"
    result = run_cli("export", str(broken), "-o", str(out))
    assert result.returncode != 0
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    assert "broken.xodr" in result.stderr
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.xodr"]


def test_failure_while_writing_leaves_the_old_file(
    tmp_path: Path, straight_map: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "borders.csv"
    out.write_text("old\n")
    real = maps.lane_border_polylines

    def failing(odr_map, step):
        yield next(real(odr_map, step))
        raise ValueError("road 7: sampling failed")

    monkeypatch.setattr(maps, "lane_border_polylines", failing)
    assert main(["export", str(straight_map), "-o", str(out)]) == 1
    assert capsys.readouterr().err == "cold-maps: error: road 7: sampling failed\n"
    assert out.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["borders.csv", "straight.xodr"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["export", "{map}", "--format", "xml", "-o", "x"], "invalid choice: 'xml'"),
        (["export", "{map}", "--step", "nan", "-o", "x"], "argument --step: expected a finite length > 0 m"),
        (["export", "{map}"], "required: -o/--output"),
        (["frobnicate"], "invalid choice: 'frobnicate'"),
        (["info", "{missing}"], "cannot read file"),
        (["export", "{map}", "-o", "{dir}"], "cold-maps: error:"),
    ],
)
def test_errors_are_one_line(tmp_path: Path, straight_map: Path, args: list[str], message: str) -> None:
    values = {"map": str(straight_map), "missing": str(tmp_path / "none.xodr"), "dir": str(tmp_path)}
    result = run_cli(*(arg.format(**values) for arg in args))
    assert result.returncode != 0
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert result.stdout == ""


def test_convert_writes_an_osm_that_plain_lanelet2_loads_in_the_opendrive_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import lanelet2
    from lanelet2.io import Origin
    from lanelet2.projection import MercatorProjector

    from cold_maps.opendrive.sampling import sample_road

    xodr = bundled_map("curve90")
    osm = tmp_path / "curve90.osm"
    assert main(["convert", str(xodr), "-o", str(osm), "--no-cache", "-v"]) == 0
    printed = capsys.readouterr().out
    assert "MercatorProjector" in printed and "Origin(0.0, 0.0)" in printed
    lanelet_map = lanelet2.io.load(str(osm), MercatorProjector(Origin(0.0, 0.0)))
    segments = np.array([
        ((a.x, a.y), (b.x, b.y))
        for ll in lanelet_map.laneletLayer
        for bound in (list(ll.leftBound), list(ll.rightBound))
        for a, b in zip(bound, bound[1:])
    ])
    road = load_opendrive(xodr).roads["1"]
    ours = np.concatenate([np.concatenate((b.inner[:, :2], b.outer[:, :2])) for b in sample_road(road, step=1.0)])
    start, direction = segments[:, 0], segments[:, 1] - segments[:, 0]
    along = np.einsum("psk,sk->ps", ours[:, None, :] - start[None], direction) / np.einsum("sk,sk->s", direction, direction)
    foot = start[None] + np.clip(along, 0.0, 1.0)[..., None] * direction[None]
    distance = np.min(np.linalg.norm(ours[:, None, :] - foot, axis=2), axis=1)
    # the frame is the OpenDRIVE frame: our border points lie on the lanelet borders, up to the
    # chord sag of the converter's 0.5 m vertex spacing on the curve's 16 m inner border
    assert np.median(distance) < 1e-6
    assert distance.max() <= 0.5**2 / (8 * 16.0) + 1e-4


def test_check_passes_a_bundled_map_and_fails_at_a_zero_threshold(capsys: pytest.CaptureFixture[str]) -> None:
    xodr = str(bundled_map("junction"))
    assert main(["check", xodr, "--converter", "crdesigner"]) == 0
    assert "ground truth: TRUSTWORTHY" in capsys.readouterr().out
    # crdesigner samples curves every 0.5 m, so some lane disagrees by more than 1 µm
    assert main(["check", xodr, "--threshold", "1e-6", "--converter", "crdesigner"]) == 3
    assert "NOT TRUSTWORTHY" in capsys.readouterr().out


def test_convert_and_check_of_a_broken_file_fail_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    broken = tmp_path / "broken.xodr"
    broken.write_text("<OpenDRIVE><header")
    out = tmp_path / "broken.osm"
    for args in (["convert", str(broken), "-o", str(out)], ["check", str(broken)]):
        assert main(args) == 1
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "broken.xodr" in err
    assert not out.exists()


def test_cache_lists_and_clears_conversions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "cache"))
    assert main(["cache"]) == 0
    assert "0 cached conversion(s)" in capsys.readouterr().out
    assert main(["convert", str(bundled_map("straight")), "-o", str(tmp_path / "straight.osm")]) == 0
    capsys.readouterr()
    assert main(["cache"]) == 0
    assert "1 cached conversion(s)" in capsys.readouterr().out
    assert main(["cache", "--clear"]) == 0
    assert "removed 1 file(s)" in capsys.readouterr().out
    assert not list((tmp_path / "cache").glob("*.osm"))


@pytest.mark.parametrize("command", [["cold_maps", "info"], ["cold_maps", "export"]])
def test_a_closed_pipe_ends_the_command_quietly(command: list[str], straight_map: Path, tmp_path: Path) -> None:
    """A reader that goes away before the command writes (``cold-maps info MAP | true``):
    no error, no traceback, the shell's SIGPIPE status 141."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)
    args = [sys.executable, "-m", *command, str(straight_map)]
    if command[-1] == "export":
        args += ["-o", "-"]
    try:
        run = subprocess.run(args, stdout=write_end, stderr=subprocess.PIPE, text=True, cwd=PROJECT_ROOT, timeout=60)
    finally:
        os.close(write_end)
    assert run.stderr == ""
    assert run.returncode == 141


def test_export_to_standard_output_writes_the_same_rows(straight_map: Path, tmp_path: Path) -> None:
    to_file = tmp_path / "borders.csv"
    assert main(["export", str(straight_map), "-o", str(to_file)]) == 0
    piped = subprocess.run([sys.executable, "-m", "cold_maps", "export", str(straight_map), "-o", "-"],
                           capture_output=True, text=True, cwd=PROJECT_ROOT, timeout=60)
    assert piped.returncode == 0 and piped.stderr == ""
    assert piped.stdout == to_file.read_text()
    assert not (PROJECT_ROOT / "-").exists()


def test_export_into_a_missing_folder_is_one_line_and_creates_nothing(straight_map: Path, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "missing" / "deeper" / "borders.csv"
    assert main(["export", str(straight_map), "-o", str(target)]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "missing" in err
    assert not (tmp_path / "missing").exists()


def test_export_writes_into_a_fifo_in_place(straight_map: Path, tmp_path: Path) -> None:
    """A target that is not a regular file (a FIFO here, /dev/stdout in a shell) is written
    through, never replaced by a renamed file."""
    import os
    import stat
    import threading

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received: list[str] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_text()))
    reader.start()
    assert main(["export", str(straight_map), "-o", str(fifo)]) == 0
    reader.join(timeout=60)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert received and received[0].startswith(CSV_HEADER)
