"""What a run evaluates: the fusion set-ups (scenarios) and the plan per map.

A :class:`Scenario` is one fusion set-up evaluated on every frame (``local``, ``convoy``,
``spline`` per interpolation and gap d_s); a :class:`MapPlan` says which scenarios, drives,
error models and fusion parameters one map is evaluated with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Final, Literal, Sequence

import fusion
from cold_maps.evaluation.methods import MethodError, resolve_method
from cold_maps.evaluation.report import ScenarioKey, scenario_label
from cold_maps.evaluation.safety import StoppingRule
from cold_maps.network.lane_graph import LaneKey
from cold_maps.simulation.drive import CONVOY_HEADWAY_M, DEFAULT_SPEED_MPS
from cold_maps.simulation.messages import MessageModel
from cold_maps.simulation.odometry import OdometryModel
from cold_maps.simulation.sensor import SENSOR_RANGE_M
from cold_maps.simulation.sensor_errors import SensorErrorModel
from cold_maps.simulation.sensor_profile import IDEAL, SensorProfile

INTERPOLATIONS: Final[tuple[str, ...]] = ("paper", "hermite")

FusionName = Literal["local", "convoy", "spline"]

_REASONS: Final[tuple[tuple[str, str], ...]] = (
    ("not ahead", "coop_not_ahead"),
    ("no overlap on the same lane", "other_lane"),
    ("no overlap", "no_overlap"),
    ("no gap", "no_gap"),
    ("exceeds d_i", "gap_too_long"),
    ("not the same direction", "opposite_direction"),
    ("heads", "heading_mismatch"),
    ("matches none", "pose_case"),
    ("another lane", "other_lane"),
)


def reason_category(reason: str) -> str:
    """A short key for a fusion rejection reason (``other`` when unknown)."""
    for needle, category in _REASONS:
        if needle in reason:
            return category
    return "other"


@dataclass(frozen=True)
class Scenario:
    """One fusion set-up evaluated on every frame.

    Fields:
        fusion: ``local`` (ego only), ``convoy`` or ``spline``.
        interpolation: the fusion method for ``spline`` (``paper``, ``hermite`` or a name
            :func:`methods.resolve_method` resolves), "" otherwise.
        d_s: spline gap between the ego's detection end and the coop's start (m), 0 otherwise.
        lead_m: station distance of the scenario's coop ahead of the ego (m); 0 for local.
        vehicles: vehicles fused (1 local, 2 a pair, more a chain of coops every ``lead_m``
            ahead, :func:`fusion.fuse_chain`); 0 (default) when the run uses neither
            chains, history nor messages and the report leaves these fields out.
        history_m: lane history the coops send (m; 0 = none).
        exchange: how lanes travel (``sampled``/``bezier``; "" = detections directly).
    """

    fusion: FusionName
    interpolation: str = ""
    d_s: float = 0.0
    lead_m: float = 0.0
    vehicles: int = 0
    history_m: float = 0.0
    exchange: str = ""

    @property
    def label(self) -> str:
        """``local``, ``convoy`` or ``spline-<interpolation>-d<d_s>``, ``-v<vehicles>`` for a chain."""
        return scenario_label(self.fusion, self.interpolation, self.d_s, self.vehicles)

    @property
    def chain_leads_m(self) -> tuple[float, ...]:
        """Leads (m) of the coops of a chain, nearest first (the pair's one coop otherwise)."""
        return tuple(self.lead_m * i for i in range(1, max(2, self.vehicles)))

    def key(self, map_name: str, boundary: str) -> ScenarioKey:
        """The report key of one boundary."""
        return ScenarioKey(map_name, self.fusion, self.interpolation, float(self.d_s), boundary, self.vehicles,
                           float(self.history_m), self.exchange)


def scenarios_for(gaps_m: Sequence[float], interpolations: Sequence[str], *,
                  sensor_range_m: float = SENSOR_RANGE_M) -> tuple[Scenario, ...]:
    """local, convoy (headway d_v = 25 m) and spline for each distinct interpolation and gap.

    An interpolation is any fusion method name :func:`methods.resolve_method` resolves
    (``paper``, ``hermite``, a registered name or ``package.module:function``)."""
    for gap in gaps_m:
        if not (math.isfinite(gap) and gap > 0):
            raise ValueError(f"spline gap d_s: expected a finite distance > 0 m, got {gap!r}")
    for name in interpolations:
        try:
            resolve_method(name)
        except MethodError as exc:
            raise MethodError(f"interpolation: {exc}") from None
    splines = [Scenario("spline", name, float(gap), sensor_range_m + gap)
               for name in dict.fromkeys(interpolations) for gap in dict.fromkeys(gaps_m)]
    return (Scenario("local"), Scenario("convoy", lead_m=CONVOY_HEADWAY_M), *splines)


def extended_scenarios(scenarios: Sequence[Scenario], *, coops: int, history_m: float,
                       exchange: str) -> tuple[Scenario, ...]:
    """``scenarios`` with their vehicle count, history and exchange recorded, plus for each
    convoy and spline scenario the chains of 2 … ``coops`` coops (spaced by its lead)."""
    if coops < 1:
        raise ValueError(f"coops: expected at least 1, got {coops!r}")
    if not (math.isfinite(history_m) and history_m >= 0):
        raise ValueError(f"history: expected a finite length >= 0 m, got {history_m!r}")
    out = []
    for scenario in scenarios:
        base = replace(scenario, vehicles=1 if scenario.fusion == "local" else 2, history_m=history_m,
                       exchange=exchange)
        out.append(base)
        if scenario.fusion != "local":
            out += [replace(base, vehicles=k) for k in range(3, coops + 2)]
    return tuple(out)


def params_for_gaps(gaps_m: Sequence[float], convoy_weights: str = "paper",
                    association: str = "legacy") -> fusion.FusionParams:
    """Fusion parameters whose longest bridged gap d_i (default 50 m) admits every gap
    asked for, with 1 m to spare (a gap set along the lane is measured as a chord), and
    ``convoy_weights`` and ``association`` (:class:`fusion.FusionParams`)."""
    return fusion.FusionParams(d_i_m=max(fusion.DEFAULT_PARAMS.d_i_m, max(gaps_m, default=0.0) + 1.0),
                               convoy_weights=convoy_weights,  # type: ignore[arg-type]  # checked by FusionParams
                               association=association)  # type: ignore[arg-type]  # checked by FusionParams


@dataclass(frozen=True)
class MapPlan:
    """What to evaluate on one map.

    Fields:
        path: the OpenDRIVE file.
        scenarios: the fusion set-ups.
        frames: frames per drive.
        frames_at_most: ``frames`` is an upper bound: a map whose longest route is too
            short for them is driven for as many as fit (``evaluation.fit``).
        routes: drives (routes) on the map; None for as many as cover its lanes.
        seed: seed of the route choice and of the error models.
        speed_mps: ego speed (m/s); frames at ``FRAME_RATE_HZ``.
        start_lane: the lane every route starts on, or None for routes spread over the map.
        distractors: add turning coops, adjacent/opposite-lane and behind vehicles.
        errors: sensor error models (all off by default).
        params: fusion parameters.
        road_type: the paper's road type of this map (for the side-by-side), or None.
        history_m: lane history every vehicle keeps and sends (m; 0 = none, as the paper).
        odometry: dead-reckoning errors of the history (off by default).
        messages: how lanes are exchanged (default: detections fused directly).
        lanes: neighbour lanes the sensor detects on each side besides the vehicle's own
            (0: its lane only; with N >= 1 also the road edges and lanes leaving at forks).
        stopping: the stopping distance rule the lane is scored against at ``speed_mps``
            (``evaluation.safety``).
        sensor: the lane sensor's profile (``simulation.sensor_profile``; default the
            paper's ideal sensor), its lane-model error (``sensor.lane_error``) included.
        ground_truth: converter of the Lanelet2 ground truth: "engine" (the map engine's
            borders and lane graph, ``groundtruth.lanelet2_from_engine``) or "crdesigner".
    """

    path: Path
    scenarios: tuple[Scenario, ...]
    frames: int = 100
    frames_at_most: bool = False
    routes: int | None = 3
    seed: int = 0
    speed_mps: float = DEFAULT_SPEED_MPS
    start_lane: LaneKey | None = None
    distractors: bool = True
    errors: SensorErrorModel = SensorErrorModel()
    params: fusion.FusionParams = fusion.DEFAULT_PARAMS
    road_type: str | None = None
    history_m: float = 0.0
    odometry: OdometryModel = field(default_factory=OdometryModel)
    messages: MessageModel = field(default_factory=MessageModel)
    lanes: int = 0
    stopping: StoppingRule = StoppingRule()
    sensor: SensorProfile = IDEAL
    ground_truth: str = "engine"

    @property
    def name(self) -> str:
        """Map name (file stem)."""
        return self.path.stem

    @property
    def coop_leads_m(self) -> tuple[float, ...]:
        """Distinct coop leads of the scenarios (m)."""
        return tuple(sorted({s.lead_m for s in self.scenarios if s.fusion != "local"}))

    @property
    def chain_leads_m(self) -> tuple[float, ...]:
        """Leads (m) of the further coops of the chain scenarios, not in :attr:`coop_leads_m`."""
        pairs = set(self.coop_leads_m)
        return tuple(sorted({lead for s in self.scenarios if s.vehicles > 2 for lead in s.chain_leads_m} - pairs))
