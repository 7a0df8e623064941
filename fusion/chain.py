"""Chains of vehicles: an ego and K cooperative vehicles ahead of it, fused link by link.

Link k fuses coop k into the lane built so far (the ego's detection extended by coops
1 … k−1), which stands in for the ego detection: :func:`fusion.fuse_history` (convoy or
spline, with the coop's history when it carries one) in the frame of coop k−1 (the
vehicle at the far end of the lane built so far: "ahead" means ahead of it, whatever the
road did since the ego), so every coop is checked against the lane built so far, its far
end included. A link whose check
fails ends the chain there: the lane built so far is the result and the link's reason is
the chain's reason. Per-point sources follow the points through every link. Only the last
:data:`TAIL_M` of the lane built so far enter a link (the fusion keeps the ego lane it is
given as a prefix of its result, so the rest is joined back unchanged): a chain's cost grows
linearly with its length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np

from fusion.api import DEFAULT_PARAMS
from fusion.errors import InvalidDetectionError
from fusion.geometry import cumulative_length, to_world, transform
from fusion.history import fuse_history
from fusion.types import FusionKind, FusionParams, LaneDetection, NDArrayFloat, NDArrayInt8, Source

TAIL_M: Final[float] = 60.0
"""Length [m] of the end of the lane built so far that enters the next link (what a link
reads of it: the end fits, at most 6 m, the gap, and a convoy overlap of at most one
detection); the rest is kept as it is."""
_EGO: Final[int] = int(Source.EGO)


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
    not_ego = np.flatnonzero(new != _EGO)
    if not not_ego.size:
        return previous.copy()
    lead, trail = int(not_ego[0]), new.shape[0] - 1 - int(not_ego[-1])
    out[:lead] = previous[:lead]
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
    built = anchor = ego
    tail: list[tuple[NDArrayFloat, NDArrayInt8]] | None = None  # the last link's result, world frame
    done: list[tuple[NDArrayFloat, NDArrayInt8]] = [(np.empty((0, 2)), np.empty(0, np.int8))] * 2
    links: list[ChainLink] = []
    for coop in coops:
        if tail is not None:
            for i, (border, source) in enumerate(tail):
                cut = _tail_start(border)
                done[i] = (np.concatenate((done[i][0], border[:cut])), np.concatenate((done[i][1], source[:cut])))
                tail[i] = (border[cut:], source[cut:])
            n_left = tail[0][0].shape[0]
            lane = _to_vehicle(np.concatenate((tail[0][0], tail[1][0])), anchor)
            built = LaneDetection(anchor.pose, lane[:n_left], lane[n_left:], ego.stamp, ego.sender)
        step = fuse_history(built, coop, mode=mode, interpolation=interpolation, params=params)
        links.append(ChainLink(coop.sender, step.kind, step.gap_m, step.reason))
        if step.kind == "none":
            break
        labels = ((np.full(ego.left.shape[0], _EGO, np.int8), np.full(ego.right.shape[0], _EGO, np.int8))
                  if tail is None else (tail[0][1], tail[1][1]))
        tail = [(step.left, _carried(labels[0], step.left_source)), (step.right, _carried(labels[1], step.right_source))]
        anchor = coop
    reason = links[-1].reason if links and links[-1].kind == "none" else ""
    fused = sum(link.kind != "none" for link in links)
    if tail is None:
        tail = [(to_world(b, ego.pose), np.full(b.shape[0], _EGO, np.int8)) for b in (ego.left, ego.right)]
    (left, left_source), (right, right_source) = [
        (np.concatenate((d[0], t[0])), np.concatenate((d[1], t[1]))) for d, t in zip(done, tail)]
    return ChainResult(left, right, left_source, right_source, tuple(links), 1 + fused, reason)


def _tail_start(border: NDArrayFloat) -> int:
    """Index where the last :data:`TAIL_M` of a border begin."""
    s = cumulative_length(border)
    return int(np.searchsorted(s, s[-1] - TAIL_M, side="right")) - 1 if s[-1] > TAIL_M else 0


def _to_vehicle(points: NDArrayFloat, vehicle: LaneDetection) -> NDArrayFloat:
    """World points [m] in the vehicle frame of a detection's sender."""
    p = vehicle.pose
    c, s = math.cos(p.yaw), math.sin(p.yaw)
    return transform(points, -c * p.x - s * p.y, s * p.x - c * p.y, -p.yaw)
