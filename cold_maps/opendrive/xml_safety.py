"""Hardened XML parsing for untrusted OpenDRIVE input.

No external entity, DTD or network resource is loaded, entity references in text stay
unresolved, comments and processing instructions are dropped, and libxml2's size limits
stay on (``huge_tree=False``). A DOCTYPE that declares entities (billion laughs,
external entities) or names an external DTD is rejected outright: before parsing when
the bytes show it, else from the parsed DTD.
"""

from __future__ import annotations

import re
from typing import Final

from lxml import etree

from cold_maps.opendrive.errors import OpenDriveError

_ENTITY_DECLARATION: Final[re.Pattern[bytes]] = re.compile(rb"<!ENTITY\s+(?:%\s+)?([^\s\"'>]+)")


def _hardened_parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=True,
        remove_pis=True,
    )


def _reject_entity_declarations(data: bytes, doctype: int, path: str) -> None:
    """Reject entity declarations after the DOCTYPE at byte ``doctype`` before libxml2
    sees them.

    Needed: libxml2 expands internal entities in attribute values even with
    ``resolve_entities=False`` (bounded only by its amplification limit). Input in other
    encodings (UTF-16) is caught after parsing, from the parsed DTD.
    """
    declarations = list(_ENTITY_DECLARATION.finditer(data, doctype))
    if declarations:
        names = [match.group(1).decode("utf-8", "replace") for match in declarations]
        line = data.count(b"\n", 0, declarations[0].start()) + 1
        raise OpenDriveError(_entities_reason(names), path=path, line=line)


def _entities_reason(names: list[str]) -> str:
    return f"DOCTYPE declares entities ({', '.join(names[:5])}); entities are not allowed"


def parse_xml(data: bytes, *, path: str = "") -> etree._Element:
    """Parse ``data`` with the hardened parser and return the root element.

    Raises ``OpenDriveError`` naming ``path`` and the line for malformed XML and for a
    DOCTYPE that declares entities or references an external DTD.
    """
    if not isinstance(data, bytes):
        raise TypeError(f"OpenDRIVE data must be bytes, got {type(data).__name__}")
    doctype = data.find(b"<!DOCTYPE")
    line = data.count(b"\n", 0, doctype) + 1 if doctype >= 0 else None
    if doctype >= 0:
        _reject_entity_declarations(data, doctype, path)
    try:
        root = etree.fromstring(data, _hardened_parser())
    except etree.XMLSyntaxError as exc:
        reason = f"malformed XML: {exc.msg}" if exc.msg else "malformed XML"
        raise OpenDriveError(reason, path=path, line=exc.lineno or None) from None
    docinfo = root.getroottree().docinfo
    if docinfo.system_url or docinfo.public_id:
        external = docinfo.system_url or docinfo.public_id
        raise OpenDriveError(f"DOCTYPE references an external DTD ({external!r})", path=path, line=line)
    dtd = docinfo.internalDTD
    if dtd is not None:
        names = [entity.name for entity in dtd.iterentities()]
        if names:
            raise OpenDriveError(_entities_reason(names), path=path, line=line)
    return root
