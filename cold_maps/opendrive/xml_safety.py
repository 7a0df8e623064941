"""Hardened XML parsing for untrusted OpenDRIVE input.

No entity is ever resolved, no DTD or network resource is loaded, comments and
processing instructions are dropped, and libxml2's size limits stay on
(``huge_tree=False``). A DOCTYPE that declares entities (billion laughs, external
entities) or names an external DTD is rejected outright.
"""

from __future__ import annotations

from lxml import etree

from cold_maps.opendrive.errors import OpenDriveError


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


def parse_xml(data: bytes, *, path: str = "") -> etree._Element:
    """Parse ``data`` with the hardened parser and return the root element.

    Raises ``OpenDriveError`` naming ``path`` and the line for malformed XML and for a
    DOCTYPE that declares entities or references an external DTD.
    """
    if not isinstance(data, bytes):
        raise TypeError(f"OpenDRIVE data must be bytes, got {type(data).__name__}")
    try:
        root = etree.fromstring(data, _hardened_parser())
    except etree.XMLSyntaxError as exc:
        reason = f"malformed XML: {exc.msg}" if exc.msg else "malformed XML"
        raise OpenDriveError(reason, path=path, line=exc.lineno or None) from None
    docinfo = root.getroottree().docinfo
    if docinfo.system_url or docinfo.public_id:
        raise OpenDriveError(
            f"DOCTYPE references an external DTD ({docinfo.system_url or docinfo.public_id!r})",
            path=path,
        )
    dtd = docinfo.internalDTD
    if dtd is not None:
        names = [entity.name for entity in dtd.iterentities()]
        if names:
            raise OpenDriveError(
                f"DOCTYPE declares entities ({', '.join(names[:5])}); entities are not allowed",
                path=path,
            )
    return root
