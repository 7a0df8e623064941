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
from cold_maps.network.continuity import link_gaps
from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.opendrive import xml_safety
from cold_maps.opendrive.parser import parse_opendrive
from cold_maps.opendrive.xml_safety import iter_xml
from tests.conftest import load_tool

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


class _LostError:
    """Raises ``MemoryError`` when collected, as lxml's error log does when it cannot record
    a libxml2 error: Python reports it through ``sys.unraisablehook``."""

    def __del__(self) -> None:
        raise MemoryError


@pytest.mark.parametrize("then", ["vague syntax error", "no error"])
def test_an_error_lost_for_memory_is_a_memory_error(then: str, monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A libxml2 error lxml could not record for want of memory: the parse ends with
    ``MemoryError`` (not "malformed XML", nor a map missing what failed), and nothing
    is printed ("Exception ignored" and a traceback); the hook is restored."""
    real_iterparse = etree.iterparse
    hook = sys.unraisablehook

    def lossy(*args, **kwargs):
        _LostError()
        if then == "vague syntax error":
            raise etree.XMLSyntaxError(None, 1, 0, 0)  # XML_ERR_INTERNAL_ERROR, no message: all lxml knows
        yield from real_iterparse(*args, **kwargs)

    monkeypatch.setattr(etree, "iterparse", lossy)
    with pytest.raises(MemoryError):
        parse_opendrive(many_roads(2))
    assert capsys.readouterr().err == "" and sys.unraisablehook is hook


def test_other_unraisable_exceptions_while_parsing_reach_the_hook_after(monkeypatch: pytest.MonkeyPatch) -> None:
    """Only ``MemoryError``s are kept back: another exception Python cannot raise during the
    parse goes to the hook in place once the parse ends, and the map is read."""
    real_iterparse = etree.iterparse
    seen = []

    class Broken:
        def __del__(self) -> None:
            raise ValueError("from __del__")

    def with_broken(*args, **kwargs):
        Broken()
        yield from real_iterparse(*args, **kwargs)

    monkeypatch.setattr(etree, "iterparse", with_broken)
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: seen.append(unraisable.exc_value))
    assert len(parse_opendrive(many_roads(2)).roads) == 2
    assert [str(error) for error in seen] == ["from __del__"]


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


def test_out_of_memory_while_reporting_it_still_writes_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> None:
    """At the very edge of a limit even formatting the error line can run out of memory: the
    line prepared in advance is written to file descriptor 2, no exception escapes."""
    from cold_maps.cli import common

    path = tmp_path / "m.xodr"
    path.write_bytes(many_roads(1))

    def exhausted(*args):
        raise MemoryError

    monkeypatch.setattr(maps, "map_info", exhausted)
    monkeypatch.setattr(common, "memory_limit", exhausted)
    assert maps.main(["info", str(path)]) == 1
    assert capfd.readouterr().err == "cold-maps: error: out of memory\n"


def _info_under_address_space_limit(path: Path, extra_mib: int) -> subprocess.CompletedProcess[str]:
    """``cold-maps info PATH`` in a process whose address space may grow ``extra_mib`` MiB
    past what it holds once the commands' modules are imported (a real ``ulimit -v``)."""
    script = (
        "import resource, sys\n"
        "from cold_maps.cli.maps import main\n"
        "import cold_maps.opendrive.parser, cold_maps.network.lane_graph, cold_maps.network.continuity\n"
        "pages = int(open('/proc/self/statm').read().split()[0]) * resource.getpagesize()\n"
        "limit = pages + int(sys.argv[2]) * 2**20\n"
        "resource.setrlimit(resource.RLIMIT_AS, (limit, limit))\n"
        "sys.exit(main(['info', sys.argv[1]]))\n"
    )
    return subprocess.run([sys.executable, "-c", script, str(path), str(extra_mib)], capture_output=True, text=True,
                          timeout=120)


def test_an_address_space_limit_is_named(tmp_path: Path) -> None:
    """A map (11 MB) whose parse cannot live within 16 MiB more: one line, exit 1, the limit
    named, whichever allocation fails (the read, libxml2, the model)."""
    path = tmp_path / "m.xodr"
    path.write_bytes(many_roads(20_000))
    done = _info_under_address_space_limit(path, 16)
    assert done.returncode == 1, done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith("cold-maps: error: out of memory (limit ") and "ulimit -v" in done.stderr


def test_a_small_map_reads_under_a_tight_address_space_limit(tmp_path: Path) -> None:
    """Reading a file reserves its size, not the size limit of ``load_opendrive`` (256 MiB)."""
    path = tmp_path / "m.xodr"
    path.write_bytes(many_roads(1))
    done = _info_under_address_space_limit(path, 32)
    assert done.returncode == 0, done.stderr
    assert "roads: 1 " in done.stdout


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


@pytest.mark.parametrize("lanes", [1, 3])
def test_the_big_chain_has_lanes_per_side_linked_road_to_road(lanes: int) -> None:
    """tools/big_maps.py chain --lanes: every road has ``lanes`` lanes each way, each lane
    the successor of the same lane on the road before, borders meeting (0 gaps over 1 cm),
    the road marks solid outside, broken between lanes of one direction."""
    big_maps = load_tool("big_maps")
    roads = 5
    odr_map = parse_opendrive("".join(big_maps.chain(roads, seed=1, lanes_per_side=lanes)).encode(), strict=True)
    graph = build_lane_graph(odr_map)
    assert len(graph.lanes) == 2 * lanes * roads
    assert sum(1 for _ in graph.edges()) == 2 * lanes * (roads - 1)
    assert graph.successors[LaneKey("2", 0, -lanes)] == (LaneKey("3", 0, -lanes),)
    assert graph.successors[LaneKey("3", 0, lanes)] == (LaneKey("2", 0, lanes),)
    assert link_gaps(graph) == [] and not graph.issues
    section = odr_map.roads["1"].lane_sections[0]
    assert [lane.id for lane in section.right] == list(range(-1, -lanes - 1, -1))
    assert [lane.road_marks[0].type for lane in section.right] == ["broken"] * (lanes - 1) + ["solid"]
    assert section.center.road_marks[0].type == ("broken" if lanes == 1 else "solid")
