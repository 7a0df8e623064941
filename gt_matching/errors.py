"""The error raised for input that ground-truth matching cannot use."""

from __future__ import annotations


class MatchingError(ValueError):
    """A detection, pose or map that cannot be matched; the message names the culprit."""
