"""Bad OpenDRIVE input gets an ``OpenDriveError`` that names file, element and line."""

from __future__ import annotations

import os
import string
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.model import OpenDriveMap
from cold_maps.opendrive.parser import load_opendrive, parse_opendrive

SMALL_MAP = Path(__file__).parent / "data" / "small_1_8.xodr"
SMALL_TEXT = SMALL_MAP.read_text(encoding="utf-8")
NAME = "bad.xodr"


def line_of(text: str, after: str = "") -> int:
    """1-based line of the small map where the first ``text`` after ``after`` starts."""
    return SMALL_TEXT.count("\n", 0, SMALL_TEXT.index(text, SMALL_TEXT.index(after) if after else 0)) + 1


def mutate(old: str, new: str, after: str = "") -> tuple[bytes, int]:
    """The small map with the first ``old`` after ``after`` replaced by ``new``, and the
    line where the replacement starts."""
    at = SMALL_TEXT.index(old, SMALL_TEXT.index(after) if after else 0)
    text = SMALL_TEXT[:at] + new + SMALL_TEXT[at + len(old) :]
    return text.encode(), line_of(old, after)


def parse_error(data: bytes) -> OpenDriveError:
    """The error of strict parsing (lenient parsing accepts omitted coefficients: see
    tests/test_opendrive_lenient.py)."""
    with pytest.raises(OpenDriveError) as info:
        parse_opendrive(data, path=NAME, strict=True)
    return info.value


def test_small_map_is_valid() -> None:
    assert isinstance(parse_opendrive(SMALL_TEXT.encode(), path=NAME), OpenDriveMap)


ROAD2 = '<road id="2"'
ROAD3 = '<road id="3"'
LINE_GEOMETRY = '<geometry s="0" x="1" y="2" hdg="0.5" length="5"><line/>'

SECTION = '<laneSection s="0">'

# (old, new, after, element, reason fragment[, the error's line: first such text from after])
BAD_CASES: dict[str, tuple[str, ...]] = {
    "missing geometry hdg": (LINE_GEOMETRY, LINE_GEOMETRY.replace(' hdg="0.5"', ""), "", "geometry", "missing required attribute 'hdg'"),
    "non-numeric length": ('length="5"><line/>', 'length="abc"><line/>', "", "geometry", "'length' is not a finite number: 'abc'"),
    "NaN x": ('x="1" y="2"', 'x="NaN" y="2"', "", "geometry", "'x' is not a finite number: 'NaN'"),
    "digit underscore hdg": ('hdg="0.4"', 'hdg="1_0"', "", "geometry", "'hdg' is not a number in the XML Schema form: '1_0'"),
    "full-width width": ('sOffset="9" a="3.5"', 'sOffset="9" a="\uff13.\uff15"', "", "width", "'a' is not a number in the XML Schema form: '３.５'"),
    "Arabic-Indic spiral curvEnd": ('curvEnd="0.04"', 'curvEnd="\u0660.\u0660\u0664"', "", "spiral", "'curvEnd' is not a number in the XML Schema form"),
    "digit underscore laneLink": ('<laneLink from="1" to="2"/>', '<laneLink from="1" to="2_0"/>', "", "laneLink", "'to' is not an integer in the XML Schema form: '2_0'"),
    "inf curvature": ('curvature="-0.02"', 'curvature="inf"', "", "arc", "'curvature' is not a finite number: 'inf'"),
    "-INF elevation": ('a="1.5"', 'a="-INF"', "", "elevation", "'a' is not a finite number"),
    "overflow width": ('sOffset="9" a="3.5"', 'sOffset="9" a="1e999"', "", "width", "'a' is not a finite number"),
    "empty hdg": ('hdg="0.4"', 'hdg=""', "", "geometry", "'hdg' is not a finite number: ''"),
    "negative geometry length": ('length="5"><line/>', 'length="-5"><line/>', "", "geometry", "geometry length must be >= 0, got -5.0"),
    "negative road length": ('length="10" junction="-1">', 'length="-10" junction="-1">', "", "road", "road '2' has negative length -10.0"),
    "missing road length": ('<road id="3" length="8"', '<road id="3"', "", "road", "missing required attribute 'length'"),
    "missing road id": ('<road id="3" length="8"', '<road length="8"', "", "road", "missing required attribute 'id'"),
    "unknown geometry kind": ("<line/>", "<clothoid k='1'/>", "", "geometry", "geometry has no known kind"),
    "empty geometry": ('length="8"><arc curvature="0.1"/></geometry>', 'length="8"/>', "", "geometry", "geometry has no known kind"),
    "two geometry kinds": ("<line/>", '<line/><arc curvature="1"/>', "", "geometry", "geometry has 2 shapes (line, arc)"),
    "two shapes of one kind": ("<line/>", "<line/><line/>", "", "geometry", "geometry has 2 shapes (line, line)"),
    "missing arc curvature": ('<arc curvature="-0.02"/>', "<arc/>", "", "arc", "missing required attribute 'curvature'"),
    "missing paramPoly3 dV": (' dV="8"', "", "", "paramPoly3", "missing required attribute 'dV'"),
    "bad pRange": ('pRange="arcLength"', 'pRange="metres"', "", "paramPoly3", "'pRange' is 'metres', expected one of arcLength, normalized"),
    "bad rule": ('rule="LHT"', 'rule="left"', "", "road", "'rule' is 'left', expected one of RHT, LHT"),
    "no planView": ('<planView><geometry s="0" x="-9" y="2" hdg="0" length="10"><line/></geometry></planView>', "", "", "road", "road '2' has no <planView> geometry", ROAD2),
    "two planViews": ("</planView>", "</planView><planView/>", ROAD2, "planView", "more than one <planView> in road '2'"),
    "dangling road link": ('elementId="2" contactPoint="end"', 'elementId="99" contactPoint="end"', "", "predecessor", "links to road '99', which does not exist"),
    "dangling junction link": ('elementId="7"', 'elementId="70"', "", "successor", "links to junction '70', which does not exist"),
    "dangling road junction": ('junction="7"', 'junction="8"', "", "road", "links to junction '8', which does not exist"),
    "dangling connecting road": ('connectingRoad="3" contactPoint="start"', 'connectingRoad="33" contactPoint="start"', "", "connection", "links to road '33'"),
    "dangling incoming road": ('incomingRoad="2"', 'incomingRoad="22"', "", "connection", "links to road '22'"),
    "missing connecting road": ('connectingRoad="3" contactPoint="end"', 'contactPoint="end"', "", "connection", "missing required attribute 'connectingRoad'"),
    "missing connection contactPoint": ('connectingRoad="3" contactPoint="end"', 'connectingRoad="3"', "", "connection", "missing required attribute 'contactPoint'"),
    "bad laneLink": ('<laneLink from="1" to="2"/>', '<laneLink from="one" to="2"/>', "", "laneLink", "'from' is not an integer: 'one'"),
    "duplicate road id": (ROAD3, ROAD2, "", "road", "duplicate road id '2'"),
    "duplicate junction id": ('<controller id="5" name="ctrl">', '<junction id="7"/><controller id="5" name="ctrl">', "", "junction", "duplicate junction id '7'"),
    "missing road link contactPoint": ('elementId="1" contactPoint="start"/></link>', 'elementId="1"/></link>', "", "successor", "missing required attribute 'contactPoint'"),
    "bad contactPoint": ('contactPoint="end"/>', 'contactPoint="middle"/>', "", "predecessor", "'contactPoint' is 'middle'"),
    "bad elementType": ('elementType="road" elementId="2"', 'elementType="street" elementId="2"', "", "predecessor", "'elementType' is 'street'"),
    "two predecessors": ('<successor elementType="junction"', '<predecessor elementType="road" elementId="3" contactPoint="start"/><successor elementType="junction"', "", "predecessor", "more than one road predecessor"),
    "non-consecutive left lanes": ('<lane id="2" type="sidewalk"', '<lane id="3" type="sidewalk"', "", "laneSection", "left lane ids must be 1, 2 (consecutive from the reference line), found 1, 3", SECTION),
    "duplicate right lane": ('<lane id="-2" type="shoulder"', '<lane id="-1" type="shoulder"', "", "laneSection", "right lane ids must be -1, -2", SECTION),
    "left lane with negative id": ('<lane id="2" type="sidewalk"', '<lane id="-2" type="sidewalk"', "", "laneSection", "left lane ids must be 1, 2", SECTION),
    "non-integer lane id": ('<lane id="1" type="driving" level="false"', '<lane id="1.5" type="driving" level="false"', "", "lane", "'id' is not an integer: '1.5'"),
    "missing lane type": ('<lane id="2" type="sidewalk"', '<lane id="2"', "", "lane", "missing required attribute 'type'"),
    "no center lane": ('<center><lane id="0" type="none"/></center>', "", ROAD3, "laneSection", "exactly one <center> lane with id 0, found: none", SECTION),
    "center lane not 0": ('<center><lane id="0" type="none"/></center>', '<center><lane id="1" type="none"/></center>', ROAD3, "laneSection", "found: 1", SECTION),
    "section after road end": ('<laneSection s="18"', '<laneSection s="30.5"', "", "laneSection", "lane section starts at s=30.5, after the end of road '1' (30.0)"),
    "negative section start": ('<laneSection s="0">', '<laneSection s="-1">', ROAD2, "laneSection", "negative s=-1.0"),
    "bad singleSide": ('singleSide="true"', 'singleSide="maybe"', "", "laneSection", "'singleSide' is not a boolean: 'maybe'"),
    "bad junction type": ('name="crossing"', 'name="crossing" type="roundabout"', "", "junction", "'type' is 'roundabout', expected one of default, direct, virtual, crossing"),
    "bad lane direction": ('direction="reversed"', 'direction="up"', "", "lane", "'direction' is 'up'"),
    "missing width sOffset": ('<width sOffset="9"', "<width", "", "width", "missing required attribute 'sOffset'"),
    "missing revMajor": ('revMajor="1" ', "", "", "header", "missing required attribute 'revMajor'"),
    "unsupported revision": ('revMajor="1"', 'revMajor="2"', "", "header", "unsupported OpenDRIVE revision 2.8"),
    "non-numeric north": ('north="10.5"', 'north="up"', "", "header", "'north' is not a finite number: 'up'"),
    "missing offset hdg": (' hdg="0.25"', "", "", "offset", "missing required attribute 'hdg'"),
}


@pytest.mark.parametrize("case", list(BAD_CASES), ids=list(BAD_CASES))
def test_bad_input_names_file_element_and_line(case: str) -> None:
    old, new, after, element, reason, *at = BAD_CASES[case]
    data, line = mutate(old, new, after)
    if at:
        line = line_of(at[0], after)
    error = parse_error(data)
    assert (error.path, error.element, error.line) == (NAME, element, line)
    assert str(error).startswith(f"{NAME}:{line}: <{element}>: ")
    assert reason in error.reason


def test_duplicate_road_points_at_the_second_one() -> None:
    data, line = mutate(ROAD3, ROAD2)
    assert line > line_of(ROAD2)
    assert parse_error(data).line == line


def test_road_without_lane_section() -> None:
    start = SMALL_TEXT.index(ROAD3)
    road3 = SMALL_TEXT[start : SMALL_TEXT.index("</road>", start)]
    text = SMALL_TEXT.replace(road3, road3.replace("laneSection", "userData"))
    assert str(parse_error(text.encode())) == f"{NAME}:{line_of(ROAD3)}: <road>: road '3' has no <laneSection>"


def test_wrong_root() -> None:
    error = parse_error(b"<?xml version='1.0'?>\n<OpenSCENARIO><road/></OpenSCENARIO>")
    assert str(error) == f"{NAME}:2: <OpenSCENARIO>: root element is not <OpenDRIVE>"


def test_no_roads() -> None:
    error = parse_error(b'<OpenDRIVE>\n<header revMajor="1" revMinor="4"/>\n<junction id="1"/></OpenDRIVE>')
    assert str(error) == f"{NAME}:1: <OpenDRIVE>: the map has no <road>"


def test_no_header() -> None:
    text = SMALL_TEXT[: SMALL_TEXT.index("  <header")] + SMALL_TEXT[SMALL_TEXT.index("  <road"):]
    assert str(parse_error(text.encode())) == f"{NAME}:2: <OpenDRIVE>: no <header>"


@pytest.mark.parametrize(
    "data, line",
    [
        (SMALL_TEXT.replace("</road>", "", 1).encode(), None),
        (SMALL_TEXT.encode()[:2000], None),
        (b"", 1),
        (b"\xff\xfe\x00garbage", 1),
        (b"<OpenDRIVE><header revMajor='1' revMinor='4'/><road", 1),
        (b"<OpenDRIVE>\n<header revMajor='1' revMajor='4'/></OpenDRIVE>", 2),
    ],
    ids=["missing end tag", "truncated", "empty", "binary", "unterminated tag", "duplicate attribute"],
)
def test_malformed_xml_names_file_and_line(data: bytes, line: int | None) -> None:
    error = parse_error(data)
    assert error.reason.startswith("malformed XML")
    assert error.line is not None and error.line >= 1
    if line is not None:
        assert error.line == line
    assert str(error).startswith(f"{NAME}:{error.line}: malformed XML")


def test_malformed_xml_line_is_where_the_problem_is() -> None:
    data, line = mutate('<junction id="7" name="crossing">', '<junction id="7" name="crossing" id="8">')
    error = parse_error(data)
    assert error.line == line and "id" in error.reason


def billion_laughs(levels: int) -> bytes:
    """The classic entity bomb: &lol{levels}; expands to 10**levels "lol"s."""
    declarations = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{n} "{f"&lol{n - 1};" * 10}">' for n in range(1, levels + 1)
    ]
    doctype = "\n".join(declarations)
    return f"""<?xml version="1.0"?>\n<!DOCTYPE lolz [\n{doctype}\n]>
<OpenDRIVE><header revMajor="1" revMinor="4" name="&lol{levels};"/></OpenDRIVE>""".encode()


XXE_TEXT = b"""<?xml version="1.0"?>
<!DOCTYPE OpenDRIVE [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>
<OpenDRIVE><header revMajor="1" revMinor="4"><geoReference>&xxe;</geoReference></header></OpenDRIVE>"""

XXE_ATTRIBUTE = XXE_TEXT.replace(b"<geoReference>&xxe;</geoReference>", b"").replace(b'revMinor="4"', b'revMinor="4" name="&xxe;"')

PARAMETER_ENTITY = b"""<?xml version="1.0"?>
<!DOCTYPE OpenDRIVE [<!ENTITY % remote SYSTEM "http://127.0.0.1:9/evil.dtd"> %remote;]>
<OpenDRIVE/>"""

HIDDEN_AFTER_BRACKET = b"""<?xml version="1.0"?>
<!DOCTYPE OpenDRIVE [<!ATTLIST header name CDATA "]>">
<!ENTITY late "x">]>
<OpenDRIVE/>"""

EXTERNAL_DTD = b'<?xml version="1.0"?>\n<!DOCTYPE OpenDRIVE SYSTEM "file:///etc/passwd">\n<OpenDRIVE/>'


@pytest.mark.parametrize(
    "data, reason, line",
    [
        (billion_laughs(9), "DOCTYPE declares entities (lol0, lol1, lol2, lol3, lol4); entities are not allowed", 3),
        (XXE_TEXT, "DOCTYPE declares entities (xxe); entities are not allowed", 2),
        (XXE_ATTRIBUTE, "DOCTYPE declares entities (xxe); entities are not allowed", 2),
        (PARAMETER_ENTITY, "DOCTYPE declares entities (remote); entities are not allowed", 2),
        (HIDDEN_AFTER_BRACKET, "DOCTYPE declares entities (late); entities are not allowed", 3),
        (EXTERNAL_DTD, "DOCTYPE references an external DTD ('file:///etc/passwd')", 2),
    ],
    ids=[
        "billion laughs",
        "external entity in text",
        "external entity in attribute",
        "parameter entity",
        "declaration after ]> in a quoted value",
        "external DTD",
    ],
)
def test_entity_payloads_are_rejected(data: bytes, reason: str, line: int) -> None:
    error = parse_error(data)
    assert error.reason == reason
    assert (error.path, error.line) == (NAME, line)
    assert "root:" not in str(error)


def test_lxml_alone_expands_attribute_entities_hence_the_declaration_check() -> None:
    """Why entity declarations are rejected before parsing: libxml2 expands internal
    entities in attribute values despite resolve_entities=False, bounded only by its
    amplification limit. External entities in text stay unresolved."""
    from cold_maps.opendrive.xml_safety import _HARDENED

    root = etree.fromstring(billion_laughs(3), etree.XMLParser(**_HARDENED))
    assert root[0].get("name") == "lol" * 1000
    with pytest.raises(etree.XMLSyntaxError, match="amplification"):
        etree.fromstring(billion_laughs(9), etree.XMLParser(**_HARDENED))
    root = etree.fromstring(XXE_TEXT, etree.XMLParser(**_HARDENED))
    assert "root:" not in etree.tostring(root, encoding="unicode")


def test_entities_in_utf16_input_are_rejected_after_parsing() -> None:
    data = billion_laughs(2).decode().replace('encoding="utf-8"', "").encode("utf-16")
    assert str(parse_error(data)) == f"{NAME}: DOCTYPE declares entities (lol0, lol1, lol2); entities are not allowed"


def test_plain_doctype_and_entity_text_without_doctype_are_tolerated() -> None:
    data = SMALL_TEXT.replace("<OpenDRIVE>", "<!DOCTYPE OpenDRIVE>\n<OpenDRIVE>", 1).encode()
    assert len(parse_opendrive(data).roads) == 3
    data = SMALL_TEXT.replace("+units=m", '+units=m <!ENTITY x "y">').encode()
    assert parse_opendrive(data).header.geo_reference.proj.endswith('+units=m <!ENTITY x "y">')


def test_size_limit_is_checked_before_reading(tmp_path: Path) -> None:
    size = SMALL_MAP.stat().st_size
    assert len(load_opendrive(SMALL_MAP, max_bytes=size).roads) == 3
    with pytest.raises(OpenDriveError) as info:
        load_opendrive(SMALL_MAP, max_bytes=size - 1)
    assert str(info.value) == f"{SMALL_MAP}: file is {size} bytes, more than the limit of {size - 1} bytes"


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero (a file whose stat size is 0)")
def test_size_limit_also_caps_the_read() -> None:
    with pytest.raises(OpenDriveError, match="more than the limit of 1000 bytes"):
        load_opendrive("/dev/zero", max_bytes=1000)


def test_unreadable_paths(tmp_path: Path) -> None:
    missing = tmp_path / "missing.xodr"
    with pytest.raises(OpenDriveError) as info:
        load_opendrive(missing)
    assert str(info.value) == f"{missing}: cannot read file: No such file or directory"
    with pytest.raises(OpenDriveError, match="cannot read file"):
        load_opendrive(tmp_path)


def test_load_reports_the_file_path(tmp_path: Path) -> None:
    path = tmp_path / "broken.xodr"
    data, line = mutate('length="5"><line/>', 'length="abc"><line/>')
    path.write_bytes(data)
    with pytest.raises(OpenDriveError) as info:
        load_opendrive(path)
    assert str(info.value).startswith(f"{path}:{line}: <geometry>: ")


# -- random mutations never raise anything but OpenDriveError --------------------------------

SMALL_BYTES = SMALL_TEXT.encode()
XML_TEXT = st.text(alphabet=string.ascii_letters + string.digits + " .-+_eE<>&\"'/=", max_size=12)
ATTRIBUTE_VALUES = st.one_of(
    st.sampled_from(["", "-1", "0", "1e400", "nan", "-inf", "1_0", "7", "3", "start", "junction", "true", "x"]),
    XML_TEXT,
)


def parses_or_opendrive_error(data: bytes) -> None:
    try:
        result = parse_opendrive(data, path=NAME)
    except OpenDriveError as error:
        assert str(error).startswith(NAME)
    else:
        assert isinstance(result, OpenDriveMap)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(edits=st.lists(st.tuples(st.integers(0, len(SMALL_BYTES)), st.integers(0, 8), st.binary(max_size=8)), max_size=4))
def test_byte_mutations_raise_only_opendrive_error(edits: list[tuple[int, int, bytes]]) -> None:
    data = SMALL_BYTES
    for at, cut, insert in edits:
        data = data[:at] + insert + data[at + cut :]
    parses_or_opendrive_error(data)


ELEMENT_COUNT = sum(1 for _ in etree.fromstring(SMALL_BYTES).iter())


@settings(max_examples=150, deadline=None)
@given(
    edits=st.lists(
        st.tuples(st.sampled_from(["set", "drop_attribute", "remove", "duplicate", "rename"]), st.integers(0, ELEMENT_COUNT - 1), ATTRIBUTE_VALUES),
        min_size=1,
        max_size=4,
    )
)
def test_tree_mutations_raise_only_opendrive_error(edits: list[tuple[str, int, str]]) -> None:
    root = etree.fromstring(SMALL_BYTES)
    for operation, index, value in edits:
        elements = [e for e in root.iter() if isinstance(e.tag, str)]
        element = elements[index % len(elements)]
        names = sorted(element.attrib)
        if operation == "set" and names:
            element.set(names[len(value) % len(names)], value)
        elif operation == "drop_attribute" and names:
            del element.attrib[names[len(value) % len(names)]]
        elif operation == "remove" and element.getparent() is not None:
            element.getparent().remove(element)
        elif operation == "duplicate" and element.getparent() is not None:
            element.addnext(etree.fromstring(etree.tostring(element)))
        elif operation == "rename":
            element.tag = ["line", "arc", "lane", "road", "left", "right", "center", "width", "geometry"][len(value) % 9]
    parses_or_opendrive_error(etree.tostring(root))


@pytest.mark.parametrize(("text", "value"), [("10", 10.0), ("+1.", 1.0), (".5", 0.5), ("-1.5E-3", -1.5e-3),
                                             (" 2 ", 2.0), ("1e2", 100.0)])
def test_numbers_in_the_xml_schema_double_form_are_read(text: str, value: float) -> None:
    data, _ = mutate('hdg="0.4"', f'hdg="{text}"')
    road = parse_opendrive(data, path=NAME).roads["1"]
    assert [g.hdg for g in road.plan_view if g.s == 10.0] == [value]


@pytest.mark.parametrize("text", ["1_0", "\uff11\uff10", "1\u00a0"])
def test_python_only_number_forms_are_refused_without_strict(text: str) -> None:
    data, line = mutate('hdg="0.4"', f'hdg="{text}"')
    with pytest.raises(OpenDriveError) as info:
        parse_opendrive(data, path=NAME)
    assert str(info.value) == f"{NAME}:{line}: <geometry>: attribute 'hdg' is not a number in the XML Schema form: {text!r}"


def past_line_cap(text: str) -> str:
    """``text`` with blank lines after the header, so that every road starts past line 70000."""
    end = text.index("</header>") + len("</header>")
    return text[:end] + "\n" * 70000 + text[end:]


def test_element_lines_past_lxmls_cap_are_omitted_and_the_road_named() -> None:
    """lxml keeps element lines in 16 bits: from 65535 on its sourceline is capped or an
    estimate, so the error names no line (and the road the element is in) rather than a wrong one."""
    data, line = mutate('hdg="0.4"', 'hdg="abc"')
    assert parse_error(data).line == line < 65535
    error = parse_error(past_line_cap(data.decode()).encode())
    assert error.line is None
    assert str(error) == f"{NAME}: <geometry>: attribute 'hdg' is not a finite number: 'abc' (in road '1')"


def test_malformed_xml_lines_past_65535_are_right() -> None:
    text = past_line_cap(SMALL_TEXT)
    at = text.index('<junction id="7" name="crossing">')
    bad = text[:at] + '<junction id="7" name="crossing" id="8">' + text[at + len('<junction id="7" name="crossing">'):]
    assert parse_error(bad.encode()).line == bad.count("\n", 0, at) + 1 > 70000
