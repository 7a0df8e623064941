"""GeoJSON per RFC 7946: WGS84 lon/lat from the geoReference and header offset, checked
with pyproj's inverse; ``--crs local`` says so in the file; no geoReference asks for it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cold_maps.cli.maps import main
from cold_maps.opendrive.georeference import Wgs84Transform
from cold_maps.opendrive.parser import load_opendrive

SMALL_MAP = Path(__file__).parent / "data" / "small_1_8.xodr"  # UTM 32, offset (100.5, -20, 3), hdg 0.25


def export(source: Path, out: Path, *crs: str) -> dict:
    assert main(["export", str(source), "--step", "1", "--format", "geojson", *crs, "-o", str(out)]) == 0
    return json.loads(out.read_text())


def coordinates(collection: dict) -> np.ndarray:
    return np.vstack([feature["geometry"]["coordinates"] for feature in collection["features"]])


def back_to_inertial(source: Path, lon_lat_h: np.ndarray) -> np.ndarray:
    """pyproj's inverse (EPSG:4326 → the map's CRS), then the inverse of <offset>."""
    import pyproj

    geo = load_opendrive(source).header.geo_reference
    inverse = pyproj.Transformer.from_crs("EPSG:4326", pyproj.CRS(geo.proj).to_2d(), always_xy=True)
    x, y = inverse.transform(lon_lat_h[:, 0], lon_lat_h[:, 1])
    dx, dy = x - geo.offset_x, y - geo.offset_y
    cos, sin = math.cos(geo.offset_hdg), math.sin(geo.offset_hdg)
    return np.column_stack((cos * dx + sin * dy, -sin * dx + cos * dy, lon_lat_h[:, 2] - geo.offset_z))


def test_wgs84_export_inverts_to_the_local_export(tmp_path: Path) -> None:
    wgs84 = export(SMALL_MAP, tmp_path / "w.geojson")
    local = export(SMALL_MAP, tmp_path / "l.geojson", "--crs", "local")
    assert wgs84["cold_maps:crs"]["frame"] == "wgs84" and local["cold_maps:crs"]["frame"] == "local"
    lon_lat = coordinates(wgs84)
    assert (np.abs(lon_lat[:, 0] - 9.0) < 6.0).all() and (np.abs(lon_lat[:, 1]) < 1.0).all()  # UTM zone 32
    np.testing.assert_allclose(back_to_inertial(SMALL_MAP, lon_lat), coordinates(local), atol=2e-4)


def test_town01_lands_at_its_georeference_origin(town01_path: Path, tmp_path: Path) -> None:
    geo = load_opendrive(town01_path).header.geo_reference
    params = dict(item.lstrip("+").split("=", 1) for item in geo.proj.split() if "=" in item)
    origin = Wgs84Transform(geo)(np.zeros((1, 3)))[0]  # tmerc, no false easting/northing, no offset
    np.testing.assert_allclose(origin[:2], (float(params["lon_0"]), float(params["lat_0"])), atol=1e-12)
    wgs84 = export(town01_path, tmp_path / "t.geojson")
    local = export(town01_path, tmp_path / "t_local.geojson", "--crs", "local")
    np.testing.assert_allclose(back_to_inertial(town01_path, coordinates(wgs84)), coordinates(local), atol=2e-4)


def test_map_without_georeference_asks_for_crs_local(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    source = tmp_path / "plain.xodr"
    text = SMALL_MAP.read_text()
    start, end = text.index("<geoReference>"), text.index("</geoReference>") + len("</geoReference>")
    source.write_text(text[:start] + text[end:])
    out = tmp_path / "plain.geojson"
    assert main(["export", str(source), "--format", "geojson", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no <geoReference>" in err and "--crs local" in err
    assert not out.exists()


def test_csv_refuses_wgs84_and_info_prints_the_offset_in_full(tmp_path: Path, capsys) -> None:
    """CSV rows are always in the inertial frame, so ``--crs wgs84`` with csv is a usage error
    (exit 2, one line, no file); ``info`` prints a UTM-sized offset to the millimetre (``:g``
    printed 5330987.654 as 5.33099e+06, 2.3 m off)."""
    out = tmp_path / "b.csv"
    assert main(["export", str(SMALL_MAP), "--format", "csv", "--crs", "wgs84", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--crs wgs84 needs --format geojson" in err[0] and not out.exists()
    far = tmp_path / "far.xodr"
    far.write_text(SMALL_MAP.read_text().replace('<offset x="100.5" y="-20"', '<offset x="690000.125" y="5330987.654"'))
    assert main(["info", str(far)]) == 0
    assert "offset: x=690000.125 y=5330987.654 z=3 hdg=0.25" in capsys.readouterr().out
