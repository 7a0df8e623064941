"""The error raised when an OpenDRIVE map cannot be converted to Lanelet2."""

from __future__ import annotations


class ConversionError(ValueError):
    """An OpenDRIVE or OSM file that cannot be converted or loaded.

    The message names the file: ``Town01.xodr: converter crashed: KeyError: '7'``.
    A ValueError, like ``OpenDriveError``: the input cannot be turned into a map.

    Fields:
        path: the file at fault.
        reason: what is wrong, without the file name.
    """

    def __init__(self, path: str, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")
