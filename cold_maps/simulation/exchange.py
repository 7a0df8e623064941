"""What the ego receives from the other vehicles: their lane history and their messages.

:class:`LaneExchange` turns one frame's sensed detections (:func:`detection.sense`) into what
the ego fuses: each other vehicle's detection with its lane history attached
(:func:`odometry.lane_history`, when ``history_m`` > 0) and, when messages are on, the last
message the ego received from it (:class:`messages.LaneChannel`). It draws from its own
generators, one pair per drive (seeded from the run's seed and the drive's index), so
switching it on leaves the detections themselves unchanged and a drive gives the same
draws in whatever process or order it runs.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Final

import numpy as np

from cold_maps.simulation.detection import Sensed
from cold_maps.simulation.messages import LaneChannel, MessageModel
from cold_maps.simulation.odometry import OdometryModel, lane_history
from cold_maps.simulation.sensor_errors import SensorErrorModel

HISTORY_STREAM: Final[int] = 11
"""Sub-stream of the run's seed that the histories draw from."""
MESSAGE_STREAM: Final[int] = 12
"""Sub-stream of the run's seed that the message losses draw from."""


class LaneExchange:
    """History and messages of the vehicles of a run (module docstring).

    ``history_m`` (m; 0 = none), ``odometry`` the dead-reckoning errors, ``messages`` the
    exchange, ``errors`` the sensor errors (their offset and noise apply to the history),
    ``seed`` the run's seed.
    """

    def __init__(self, history_m: float, odometry: OdometryModel, messages: MessageModel,
                 errors: SensorErrorModel, seed: int) -> None:
        self.history_m, self.odometry, self.messages, self.errors = history_m, odometry, messages, errors
        self.seed = seed
        self.channels: dict[tuple[int, str], LaneChannel] = {}
        self._rngs: dict[int, tuple[np.random.Generator, np.random.Generator]] = {}

    def apply(self, drive: int, sensed: dict[str, Sensed], stamp: float) -> tuple[dict[str, Sensed],
                                                                                dict[str, int]]:
        """What the ego fuses in this frame of drive number ``drive`` (by vehicle name, the
        ego's own detection unchanged), and the bytes each vehicle sent in it (0 when none)."""
        if drive not in self._rngs:
            self._rngs[drive] = (np.random.default_rng([self.seed, HISTORY_STREAM, drive]),
                                 np.random.default_rng([self.seed, MESSAGE_STREAM, drive]))
        history_rng, message_rng = self._rngs[drive]
        out: dict[str, Sensed] = {}
        sent: dict[str, int] = {}
        for name, item in sensed.items():
            detection = item.detection
            if name == "ego":
                out[name] = item
                continue
            if detection is not None and self.history_m > 0:
                state = item.state
                history = lane_history(state.track, state.station, self.history_m, self.errors, self.odometry,
                                       history_rng)
                detection = replace(detection, history=history)
            if self.messages.enabled:
                channel = self.channels.setdefault((drive, name), LaneChannel(self.messages))
                sent[name] = channel.step(detection, stamp, message_rng)
                detection = channel.received
            out[name] = replace(item, detection=detection)
        return out, sent
