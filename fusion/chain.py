"""Chains of vehicles: an ego and K cooperative vehicles ahead of it, fused link by link.

Link k fuses coop k into the lane built so far (the ego's detection extended by coops
1 … k−1), which stands in for the ego detection: :func:`fusion.fuse_history` (convoy or
spline, with the coop's history when it carries one) in the ego's vehicle frame, so every
coop is checked against the lane built so far, its far end included. A link whose check
fails ends the chain there: the lane built so far is the result and the link's reason is
the chain's reason. Per-point sources follow the points through every link.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from fusion.api import DEFAULT_PARAMS
from fusion.errors import InvalidDetectionError
from fusion.geometry import to_world, transform
from fusion.history import fuse_history
from fusion.types import FusionKind, FusionParams, FusionResult, LaneDetection, NDArrayFloat, NDArrayInt8, Source


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
    """

    left: NDArrayFloat
    right: NDArrayFloat
    left_source: NDArrayInt8
    right_source: NDArrayInt8
    links: tuple[ChainLink, ...]
    vehicles: int
    reason: str = ""

    def __post_init__(self) -> None:
        for array in (self.left, self.right, self.left_source, self.right_source):
            array.setflags(write=False)


def _carried(previous: NDArrayInt8, new: NDArrayInt8) -> NDArrayInt8:
    """Labels of a link's result: its leading (and, for a coop ending inside the lane, trailing)
    ``EGO`` run is the lane built so far, unchanged, so it keeps that lane's labels."""
    out = new.copy()
    not_ego = np.flatnonzero(new != Source.EGO)
    lead = int(not_ego[0]) if not_ego.size else new.shape[0]
    out[:lead] = previous[:lead]
    trail = new.shape[0] - 1 - int(not_ego[-1]) if not_ego.size else 0
    if trail:
        out[-trail:] = previous[-trail:]
    return out


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
    built = ego
    sources = (np.full(ego.left.shape[0], Source.EGO, dtype=np.int8),
               np.full(ego.right.shape[0], Source.EGO, dtype=np.int8))
    result: FusionResult | None = None
    links: list[ChainLink] = []
    for coop in coops:
        step = fuse_history(built, coop, mode=mode, interpolation=interpolation, params=params)
        links.append(ChainLink(coop.sender, step.kind, step.gap_m, step.reason))
        if step.kind == "none":
            break
        result = step
        sources = (_carried(sources[0], step.left_source), _carried(sources[1], step.right_source))
        built = LaneDetection(ego.pose, _to_vehicle(step.left, ego), _to_vehicle(step.right, ego), ego.stamp,
                              ego.sender)
    reason = links[-1].reason if links and links[-1].kind == "none" else ""
    fused = sum(link.kind != "none" for link in links)
    if result is None:
        return ChainResult(to_world(ego.left, ego.pose), to_world(ego.right, ego.pose), sources[0], sources[1],
                           tuple(links), 1, reason)
    return ChainResult(result.left, result.right, sources[0], sources[1], tuple(links), 1 + fused, reason)


def _to_vehicle(points: NDArrayFloat, ego: LaneDetection) -> NDArrayFloat:
    """World points [m] in the ego's vehicle frame."""
    p = ego.pose
    return transform(points - (p.x, p.y), 0.0, 0.0, -p.yaw)
