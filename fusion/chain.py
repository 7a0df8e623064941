"""Chains of vehicles: an ego and K cooperative vehicles ahead of it, fused link by link.

Link k fuses coop k into the lane built so far (the ego's detection extended by coops
1 … k−1) with :func:`fusion.fuse_history` (convoy or spline, with the coop's history when
it carries one). The lane built so far always ends with the last points of one detection,
unchanged (a spline or history link keeps the whole coop detection, a convoy link its part
past the overlap, or the lane so far when the coop ends inside it): those points, in their
sender's frame, are the link's ego, so every coop is checked against the far end of the
lane built so far ("ahead" means ahead of its sender, whatever the road did since the
ego), and the link's result replaces them. A link whose check
fails ends the chain there: the lane built so far is the result and the link's reason is
the chain's reason. Per-point sources follow the points through every link. A chain
costs its links' fusions and one concatenation per link after the first (whose result is
the lane so far as it is). Uncertainty (σ, :mod:`fusion.uncertainty`) follows the points
the same way, link by link: points a link leaves unchanged (the lane so far before its ego
prefix, and the prefix's ``EGO`` runs) keep their σ, the points it creates get the link's
σ (computed in the link's ego frame from the two detections it fuses); the chain has σ when
every link had.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Final, Sequence

import numpy as np

from fusion.api import DEFAULT_PARAMS
from fusion.errors import InvalidDetectionError
from fusion.geometry import to_world
from fusion.history import fuse_history
from fusion.types import FusionKind, FusionParams, LaneDetection, NDArrayFloat, NDArrayInt8, Source
from fusion.uncertainty import own_variances

_EGO: Final[int] = int(Source.EGO)
_EGO_BYTE: Final[bytes] = bytes([_EGO])


@dataclass(frozen=True)
class ChainLink:
    """One link of a chain.

    Fields: ``sender`` the coop's id; ``kind`` as :attr:`FusionResult.kind` (``"none"``
    when the link failed); ``gap_m`` its signed gap to the lane built so far [m];
    ``reason`` why it failed ("" when fused).
    """

    sender: str
    kind: FusionKind
    gap_m: float
    reason: str = ""


@dataclass(frozen=True)
class ChainResult:
    """The lane of a chain of vehicles.

    Fields:
        left, right: fused borders, ``(N, 2)`` float64, world frame [m], driving direction.
        left_source, right_source: ``(N,)`` int8 :class:`Source` labels per point.
        links: the links tried, in order (the failing one last, if any).
        vehicles: vehicles whose lanes the result holds (1 + fused links).
        reason: why the chain ended before its last coop ("" when every link fused).
        left_sigma, right_sigma: lateral 1σ [m] per point of ``left`` / ``right`` (world
            frame, see the module docstring), or None when a detection fused states no σ.
    """

    left: NDArrayFloat
    right: NDArrayFloat
    left_source: NDArrayInt8
    right_source: NDArrayInt8
    links: tuple[ChainLink, ...]
    vehicles: int
    reason: str = ""
    left_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)
    right_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        for array in (self.left, self.right, self.left_source, self.right_source, self.left_sigma, self.right_sigma):
            if array is not None:
                array.setflags(write=False)


def _carried(previous: NDArrayFloat | NDArrayInt8, new: NDArrayFloat | NDArrayInt8,
             labels: NDArrayInt8) -> NDArrayFloat | NDArrayInt8:
    """Labels (or σ) of a link's result: where its ``labels`` lead (and, for a coop ending
    inside the lane, trail) with an ``EGO`` run, that is the lane built so far, unchanged, so
    it keeps that lane's ``previous`` values; ``new`` elsewhere."""
    raw = labels.tobytes()  # int8 labels as bytes: the runs are what strip() removes
    lead = len(raw) - len(raw.lstrip(_EGO_BYTE))
    if lead == len(raw):
        return previous.copy()
    trail = len(raw) - len(raw.rstrip(_EGO_BYTE))
    out = new.copy()
    out[:lead] = previous[:lead]
    if trail:
        out[-trail:] = previous[-trail:]
    return out


def _joined(lane: NDArrayFloat | NDArrayInt8, n: int, link: NDArrayFloat | NDArrayInt8,
            labels: NDArrayInt8) -> NDArrayFloat | NDArrayInt8:
    """The lane so far without its last ``n`` values, then the ``link``'s values carried
    (:func:`_carried`)."""
    return np.concatenate((lane[:-n], _carried(lane[-n:], link, labels)))


def fuse_chain(ego: LaneDetection, coops: Sequence[LaneDetection], *, mode: str = "auto",
               interpolation: str = "paper", params: FusionParams = DEFAULT_PARAMS) -> ChainResult:
    """Lane of ``ego`` extended by ``coops`` (nearest first), link by link (module docstring).

    ``mode``, ``interpolation`` and ``params`` as in :func:`fusion.fuse`, for every link.
    Output in the world frame.
    """
    if not isinstance(ego, LaneDetection):
        raise InvalidDetectionError(f"ego must be a LaneDetection, got {type(ego).__name__}")
    for i, coop in enumerate(coops):
        if not isinstance(coop, LaneDetection):
            raise InvalidDetectionError(f"coops[{i}] must be a LaneDetection, got {type(coop).__name__}")
    end = ego  # the detection whose last points end the lane built so far
    parts: list[tuple[NDArrayFloat, NDArrayInt8]] = []  # the lane built so far per border; none yet: the ego's
    sigmas: list[NDArrayFloat] | None = []  # its σ per border; None once a link has none
    links: list[ChainLink] = []
    for coop in coops:
        step = fuse_history(end, coop, mode=mode, interpolation=interpolation, params=params)
        links.append(ChainLink(coop.sender, step.kind, step.gap_m, step.reason))
        if step.kind == "none":
            if not parts:
                sigmas = None if step.left_sigma is None else [step.left_sigma, step.right_sigma]
            break
        borders = ((step.left, step.left_source), (step.right, step.right_source))
        step_sigmas = None if step.left_sigma is None or step.right_sigma is None else (step.left_sigma,
                                                                                      step.right_sigma)
        counts = (end.left.shape[0], end.right.shape[0])
        if parts:  # the lane so far ends with the n points of ``end``: the link's ego prefix copies them
            if sigmas is not None and step_sigmas is not None:
                sigmas = [_joined(sigma, n, new, source) for sigma, n, new, (_, source)
                          in zip(sigmas, counts, step_sigmas, borders)]
            else:
                sigmas = None
            parts = [(np.concatenate((points[:-n], border)), _joined(labels, n, source, source))
                     for (points, labels), n, (border, source) in zip(parts, counts, borders)]
        else:  # the first link's ego is the lane so far
            parts = list(borders)
            sigmas = None if step_sigmas is None else list(step_sigmas)
        (label, n_left), (_, n_right) = _trailing(step.left_source), _trailing(step.right_source)
        end = _last_points(coop if label != _EGO else end, n_left, n_right)
    if not parts:
        parts = [(to_world(b, ego.pose), np.full(b.shape[0], _EGO, np.int8)) for b in (ego.left, ego.right)]
        if not links:
            own = own_variances(ego)
            sigmas = None if own is None else [np.sqrt(v.world) for v in own]
    failed = bool(links) and links[-1].kind == "none"
    reason = links[-1].reason if failed else ""
    (left, left_source), (right, right_source) = parts
    fused = len(links) - failed
    left_sigma, right_sigma = (None, None) if not sigmas else sigmas
    return ChainResult(left, right, left_source, right_source, tuple(links), 1 + fused, reason, left_sigma,
                       right_sigma)


def _trailing(source: NDArrayInt8) -> tuple[int, int]:
    """``(label, length)`` of the last run of equal labels."""
    raw = source.tobytes()
    return int(source[-1]), len(raw) - len(raw.rstrip(raw[-1:]))


def _last_points(detection: LaneDetection, n_left: int, n_right: int) -> LaneDetection:
    """``detection`` restricted to its last ``n_left``/``n_right`` border points (at least 2),
    with its neighbour lanes, road edges and branches (the end they describe is unchanged)."""
    n_left, n_right = max(n_left, 2), max(n_right, 2)
    if n_left >= detection.left.shape[0] and n_right >= detection.right.shape[0]:
        return detection
    return replace(detection, left=detection.left[-n_left:], right=detection.right[-n_right:],
                   left_sigma=None if detection.left_sigma is None else detection.left_sigma[-n_left:],
                   right_sigma=None if detection.right_sigma is None else detection.right_sigma[-n_right:])
