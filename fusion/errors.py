"""Errors raised by the fusion library.

Every failure on bad data is a :class:`FusionError`; a pair of valid detections that simply
cannot be fused is *not* an error (``fuse`` returns ``kind="none"`` with the reason).

- :class:`FusionError` — base class.
- :class:`InvalidDetectionError` — malformed lane detection or pose (shape, size, NaN/inf).
- :class:`InvalidParameterError` — a ``FusionParams`` field or a keyword out of range.
- :class:`BezierDecodeError` — a Bézier exchange message that is truncated, of an unknown
  version or otherwise malformed.
"""

from __future__ import annotations


class FusionError(ValueError):
    """Base class of all errors raised by :mod:`fusion` for bad input."""


class InvalidDetectionError(FusionError):
    """A lane detection or pose is malformed; the message names the field."""


class InvalidParameterError(FusionError):
    """A fusion parameter or keyword argument is out of its documented range."""


class BezierDecodeError(FusionError):
    """A Bézier exchange message cannot be decoded."""
