"""Errors raised for unreadable or invalid OpenDRIVE input."""

from __future__ import annotations

from typing import Any, Final

LXML_LINE_CAP: Final[int] = 65535
"""libxml2 keeps an element's source line in 16 bits: from this line on, lxml's
``sourceline`` is this value or an estimate from a nearby text node."""


def source_line(element: Any) -> int | None:
    """The 1-based source line of an lxml element, None when unknown or past
    ``LXML_LINE_CAP`` (where it cannot be trusted)."""
    line = element.sourceline
    return line if line is not None and 0 < line < LXML_LINE_CAP else None


class OpenDriveError(ValueError):
    """An OpenDRIVE file that cannot be read or is invalid.

    The message names the file, the element and its source line, e.g.
    ``town.xodr:123: <geometry>: attribute 'length' is not a number: 'abc'``.

    Fields:
        path: the file ("" for in-memory input).
        element: the offending element's tag ("" when the file as a whole is at fault).
        line: 1-based source line, or None when unknown.
        reason: what is wrong, without location.
    """

    def __init__(self, reason: str, *, path: str = "", element: str = "", line: int | None = None):
        self.path = path
        self.element = element
        self.line = line
        self.reason = reason
        where = path or "<input>"
        if line is not None:
            where += f":{line}"
        what = f" <{element}>:" if element else ""
        super().__init__(f"{where}:{what} {reason}")
