"""Big and odd files (issue 28): the map is parsed one top-level element at a time, and
running out of memory ends a command with one line naming the limit, never a traceback
or "malformed XML"."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from lxml import etree
from small_maps import straight_road

from cold_maps.cli import maps
from cold_maps.opendrive import xml_safety
from cold_maps.opendrive.parser import parse_opendrive
from cold_maps.opendrive.xml_safety import iter_xml

ROADS = 400
"""Roads of :func:`many_roads`' default map (about 300 KB, ten libxml2 reads)."""


def many_roads(count: int = ROADS) -> bytes:
    """``count`` copies of a 20 m straight road (ids 1..count) in one map."""
    text = straight_road(20.0)
    start, end = text.index("<road "), text.index("</road>") + len("</road>")
    road = text[start:end]
    copies = "\n".join(road.replace('id="1"', f'id="{i}"', 1) for i in range(1, count + 1))
    return (text[:start] + copies + text[end:]).encode()


def test_the_tree_holds_one_read_ahead_chunk_at_most() -> None:
    """Each top-level element is dropped once the next is asked for; the tree holds at most
    what libxml2 parsed ahead (one 32 KiB read), never the whole map."""
    data = many_roads()
    elements = iter_xml(data, ("header", "road"))
    root = next(elements)
    seen, held = [], []
    for child in elements:
        assert root[0] is child and child.attrib
        if seen:
            assert seen[-1].getparent() is None and len(seen[-1]) == 0 and seen[-1].attrib == {}
        seen.append(child)
        held.append(len(root))
    assert [element.tag for element in seen] == ["header"] + ["road"] * ROADS
    road_bytes = len(data) // ROADS
    assert max(held) <= 2 + 32768 // road_bytes < ROADS
    assert len(parse_opendrive(data).roads) == ROADS


def test_libxml2_out_of_memory_is_a_memory_error_not_malformed_xml(monkeypatch: pytest.MonkeyPatch) -> None:
    def exhausted(*args, **kwargs):
        raise etree.XMLSyntaxError("Memory allocation failed", xml_safety._XML_ERR_NO_MEMORY, 1, 1)
        yield  # a generator, as lxml's iterparse: the error comes while parsing

    monkeypatch.setattr(etree, "iterparse", exhausted)
    with pytest.raises(MemoryError):
        parse_opendrive(many_roads(1))


def test_out_of_memory_is_one_line_naming_the_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "m.xodr"
    path.write_bytes(many_roads(1))

    def exhausted(odr_map):
        raise MemoryError

    monkeypatch.setattr(maps, "map_info", exhausted)
    assert maps.main(["info", str(path)]) == 1
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("cold-maps: error: out of memory (")
    assert "GiB" in error


def test_an_address_space_limit_is_named(tmp_path: Path) -> None:
    """A real ``ulimit -v`` the parse cannot live within: one line, exit 1, the limit named."""
    path = tmp_path / "m.xodr"
    path.write_bytes(many_roads(2000))
    script = (
        "import resource, sys\n"
        "from cold_maps.cli.maps import main\n"
        "import cold_maps.opendrive.parser, cold_maps.network.lane_graph, cold_maps.network.continuity\n"
        "pages = int(open('/proc/self/statm').read().split()[0]) * resource.getpagesize()\n"
        "limit = pages + 8 * 2**20\n"
        "resource.setrlimit(resource.RLIMIT_AS, (limit, limit))\n"
        "sys.exit(main(['info', sys.argv[1]]))\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1, done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith("cold-maps: error: out of memory (limit ") and "ulimit -v" in done.stderr


def test_only_top_level_roads_are_read_and_other_elements_dropped() -> None:
    """A ``<road>`` nested in ``<userData>`` is no road of the map; top-level elements the
    reader skips (``<controller>``, ``<userData>``) are dropped with the next road."""
    data = many_roads(3).replace(b'<road id="2"', b'<userData><road id="99"/></userData><controller id="5"/>'
                                 b'<road id="2"', 1)
    assert list(parse_opendrive(data).roads) == ["1", "2", "3"]
    elements = iter_xml(data, ("header", "road"))
    root = next(elements)
    for child in elements:
        assert root[0] is child
