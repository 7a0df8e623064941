"""What a run measured: one accumulator per scenario key, check runtimes and overlays.

The :class:`Collector` is filled frame by frame by the evaluator and read by the reports,
the plots and the paper tables, also after an interrupt.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass, field

from cold_maps.evaluation.records import Spool
from cold_maps.evaluation.report import FrameRecord, ScenarioAccumulator, ScenarioKey
from cold_maps.network.lane_strip import NDArrayFloat


@dataclass(frozen=True)
class Overlay:
    """What one frame of a scenario looked like, for the overlay plot (world frame, m).

    Fields:
        frame: frame index; max_error_m: its largest error; gt: GT borders by name;
        detections: sender → (left, right); fused: fused borders by name.
    """

    frame: int
    max_error_m: float
    gt: dict[str, NDArrayFloat]
    detections: dict[str, tuple[NDArrayFloat, NDArrayFloat]]
    fused: dict[str, NDArrayFloat]


@dataclass
class Collector:
    """Everything a run measured so far (filled frame by frame, readable after an interrupt).

    Fields:
        accumulators: one per scenario key, in insertion order.
        check_ms: (map, scenario label) → runtimes of the fusibility check alone, the
            overlap check for convoy (ms; 8 bytes each).
        overlays: (map, scenario label) → the frame with the largest error of any of its
            pairs (distractors included: the summary's max error).
        notes: lines for the summary (routes, lane coverage, what did not fit a map).
        reduced_maps: names of the maps evaluated with fewer frames, distractors or
            scenarios than asked, because their longest route is too short.
        gt_warnings: per map, why its ground truth is not trustworthy on the driven lanes.
        frames_done: frames evaluated.
        drives: (map, drive index) → (global index of the drive's frame 0, its frames):
            where each route starts on the frame axis of the plots.
        spool: where the accumulators stream their records (a temporary folder by default;
            a worker's collector spools into its parent's).
    """

    accumulators: dict[ScenarioKey, ScenarioAccumulator] = field(default_factory=dict)
    check_ms: dict[tuple[str, str], array[float]] = field(default_factory=dict)
    overlays: dict[tuple[str, str], Overlay] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    reduced_maps: list[str] = field(default_factory=list)
    gt_warnings: list[str] = field(default_factory=list)
    frames_done: int = 0
    drives: dict[tuple[str, int], tuple[int, int]] = field(default_factory=dict)
    spool: Spool = field(default_factory=Spool)

    def add(self, key: ScenarioKey, record: FrameRecord) -> None:
        """Adds one evaluation to the scenario ``key``."""
        self._accumulator(key).add(record)

    def add_traffic(self, key: ScenarioKey, sent_bytes: int, seconds: float) -> None:
        """Counts one frame of ``seconds`` (s) of one of the scenario's senders, which sent
        ``sent_bytes`` in it (0: no message)."""
        self._accumulator(key).add_traffic(sent_bytes, seconds)

    def add_check_ms(self, label: tuple[str, str], runtime_ms: float) -> None:
        """Counts one runtime (ms) of the fusibility check alone of the scenario ``label``."""
        self.check_ms.setdefault(label, array("d")).append(runtime_ms)

    def _accumulator(self, key: ScenarioKey) -> ScenarioAccumulator:
        accumulator = self.accumulators.get(key)
        if accumulator is None:
            accumulator = self.accumulators[key] = ScenarioAccumulator(key, spool=self.spool)
        return accumulator

    def merge(self, later: Collector) -> None:
        """Appends what ``later`` measured after everything in this collector (a work unit
        run elsewhere): the same state as if its frames had been evaluated into this one. Its
        records' segment files are adopted, not copied: they must stay where they are."""
        for key, accumulator in later.accumulators.items():
            self._accumulator(key).merge(accumulator)
        for label, runtimes in later.check_ms.items():
            self.check_ms.setdefault(label, array("d")).extend(runtimes)
        for label, overlay in later.overlays.items():
            kept = self.overlays.get(label)
            if kept is None or overlay.max_error_m > kept.max_error_m:
                self.overlays[label] = overlay
        self.notes.extend(later.notes)
        self.reduced_maps.extend(name for name in later.reduced_maps if name not in self.reduced_maps)
        self.gt_warnings.extend(later.gt_warnings)
        self.frames_done += later.frames_done
        self.drives.update(later.drives)

    def route_starts(self, map_name: str) -> list[int]:
        """The global frame index at which each drive of ``map_name`` starts, in order."""
        return sorted(first for (name, _), (first, _) in self.drives.items() if name == map_name)
