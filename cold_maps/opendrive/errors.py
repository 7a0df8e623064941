"""Errors raised for unreadable or invalid OpenDRIVE input."""

from __future__ import annotations


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
