"""Hardened XML parsing for untrusted OpenDRIVE input.

No external entity, DTD or network resource is loaded, entity references in text stay
unresolved, comments and processing instructions are dropped, and libxml2's size limits
stay on (``huge_tree=False``). A DOCTYPE that declares entities (billion laughs,
external entities) or names an external DTD is rejected outright: before parsing when
the bytes show it, else from the parsed DTD. The tree is streamed (``iter_xml``): one
child of the root at a time.
"""

from __future__ import annotations

import io
import re
import sys
from collections import deque
from typing import Final, Iterable, Iterator

from lxml import etree

from cold_maps.opendrive.errors import OpenDriveError

_ENTITY_DECLARATION: Final[re.Pattern[bytes]] = re.compile(rb"<!ENTITY\s+(?:%\s+)?([^\s\"'>]+)")


_HARDENED: Final[dict[str, bool]] = {
    "resolve_entities": False,
    "no_network": True,
    "load_dtd": False,
    "dtd_validation": False,
    "huge_tree": False,
    "remove_comments": True,
    "remove_pis": True,
}
"""Options of every parse: no entity, DTD or network, libxml2's size limits on."""
_XML_ERR_NO_MEMORY: Final[int] = 2
"""libxml2's error code for a failed allocation (reported as a syntax error)."""
_UNRAISABLE_KEPT: Final[int] = 32
"""Unraisable exceptions a parse keeps, the last ones (CPython's deque fills its first block
with the first 32 appends: they allocate nothing)."""


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


def _doctype_line(data: bytes, path: str) -> int | None:
    """The line of ``data``'s DOCTYPE (None without one), after refusing entity
    declarations in it; TypeError unless ``data`` is bytes."""
    if not isinstance(data, bytes):
        raise TypeError(f"OpenDRIVE data must be bytes, got {type(data).__name__}")
    doctype = data.find(b"<!DOCTYPE")
    if doctype < 0:
        return None
    _reject_entity_declarations(data, doctype, path)
    return data.count(b"\n", 0, doctype) + 1


def iter_xml(data: bytes, tags: Iterable[str], *, path: str = "") -> Iterator[etree._Element]:
    """Parse ``data`` with the hardened parser, streaming: first the root element, then
    each child of the root named one of ``tags`` (local names, any namespace) once it is
    complete. A child is cleared and dropped from the tree when the next one is asked for,
    with the other children before it, so the tree holds at most what libxml2 parsed ahead
    (one read of 32 KiB) instead of the whole map (lxml's tree takes about 16 times the
    file's size); keep no reference to the children's elements.

    Raises ``OpenDriveError`` naming ``path`` and the line for malformed XML and for a
    DOCTYPE that declares entities or references an external DTD; ``MemoryError`` when
    libxml2 runs out of memory (see ``_ParserMemory``, in effect until the stream ends or
    is closed: close it when you stop early).
    """
    line = _doctype_line(data, path)
    events = etree.iterparse(io.BytesIO(data), events=("end",), tag=[f"{{*}}{tag}" for tag in tags], **_HARDENED)
    root: etree._Element | None = None
    with _ParserMemory() as memory:
        try:
            for _, element in events:
                if root is None:
                    root = element.getroottree().getroot()
                    _check_doctype(root, path, line)
                    yield root
                if element.getparent() is not root:
                    continue  # the root itself, or nested in another child: dropped with that
                while element.getprevious() is not None:
                    del root[0]
                yield element
                element.clear()
                root.remove(element)
            if root is None:
                _check_doctype(events.root, path, line)
                yield events.root
        except etree.XMLSyntaxError as exc:
            raise memory.error(exc, path) from None
        memory.check()


def parse_xml(data: bytes, *, path: str = "") -> etree._Element:
    """The whole tree of ``data``, parsed with the checks of :func:`iter_xml`, for readers
    that need every element at once (the ground truth's road rules); the map reader
    streams instead."""
    line = _doctype_line(data, path)
    with _ParserMemory() as memory:
        try:
            root = etree.fromstring(data, etree.XMLParser(**_HARDENED))
        except etree.XMLSyntaxError as exc:
            raise memory.error(exc, path) from None
        memory.check()
    _check_doctype(root, path, line)
    return root


class _ParserMemory:
    """Context of a parse that tells libxml2 running out of memory from malformed XML.

    Besides the error code libxml2 gives for a failed allocation, lxml's error log can
    itself fail to record a libxml2 error; Python then prints "Exception ignored" and a
    traceback, and the parse fails with a vague syntax error (or none, the error lost).
    Inside the context such ``MemoryError``s are kept silently (``sys.unraisablehook`` is
    a deque's ``append``: no Python frame, nothing allocated, so it works where memory ran
    out) and the parse ends with ``MemoryError``; other unraisable
    exceptions go to the previous hook at the end."""

    def __init__(self) -> None:
        self._caught: deque[sys.UnraisableHookArgs] = deque(maxlen=_UNRAISABLE_KEPT)
        self._previous = sys.unraisablehook

    def __enter__(self) -> _ParserMemory:
        self._previous = sys.unraisablehook
        sys.unraisablehook = self._caught.append
        return self

    def __exit__(self, *exc_info: object) -> None:
        sys.unraisablehook = self._previous
        for unraisable in self._caught:
            if not isinstance(unraisable.exc_value, MemoryError):
                self._previous(unraisable)

    @property
    def _seen(self) -> bool:
        return any(isinstance(unraisable.exc_value, MemoryError) for unraisable in self._caught)

    def check(self) -> None:
        """Raise ``MemoryError`` if memory ran out while parsing, though the parse ended."""
        if self._seen:
            raise _out_of_memory()

    def error(self, exc: etree.XMLSyntaxError, path: str) -> Exception:
        """What a libxml2 syntax error means: ``MemoryError`` when it ran out of memory,
        else ``OpenDriveError`` naming the line (1 for an error before the first line
        ended)."""
        if self._seen or exc.code == _XML_ERR_NO_MEMORY:
            return _out_of_memory()
        reason = f"malformed XML: {exc.msg}" if exc.msg else "malformed XML"
        return OpenDriveError(reason, path=path, line=exc.lineno or 1)


def _out_of_memory() -> MemoryError:
    return MemoryError("libxml2 ran out of memory parsing the XML")


def _check_doctype(root: etree._Element, path: str, line: int | None) -> None:
    """Refuse an external DTD and entity declarations the byte check missed (UTF-16)."""
    docinfo = root.getroottree().docinfo
    if docinfo.system_url or docinfo.public_id:
        external = docinfo.system_url or docinfo.public_id
        raise OpenDriveError(f"DOCTYPE references an external DTD ({external!r})", path=path, line=line)
    dtd = docinfo.internalDTD
    if dtd is not None:
        names = [entity.name for entity in dtd.iterentities()]
        if names:
            raise OpenDriveError(_entities_reason(names), path=path, line=line)
