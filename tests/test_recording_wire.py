"""cold_maps.recording.wire: the scene updates and frame transforms it encodes as bytes are
byte for byte what foxglove-sdk encodes from its message objects (the reference,
``recorder.scene_update`` and ``recorder.frame_transform``), zero and negative-zero
coordinates, empty updates and several updates in one batch included."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.recording import wire
from cold_maps.recording.recorder import (
    COLOR_COOP,
    COLOR_EGO,
    COLOR_FUSED,
    COLOR_GT,
    FRAME_ID,
    LINE_THICKNESS_M,
    frame_transform,
    scene_update,
)

STAMPS_NS = st.integers(0, 2**32 * 10**9 - 1)  # the SDK's Timestamp holds seconds as u32
# coordinates as drawn (rounded to 0.1 mm), often exactly 0.0 or -0.0 (left out of the wire)
coordinates = st.one_of(st.sampled_from([0.0, -0.0, 1e-4, -1e-4]),
                        st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False).map(lambda v: round(v, 4)))
lines = st.integers(2, 12).flatmap(lambda n: st.lists(st.tuples(coordinates, coordinates), min_size=n, max_size=n))
updates = st.lists(st.tuples(STAMPS_NS, st.lists(lines, max_size=4),
                             st.sampled_from([COLOR_GT, COLOR_FUSED, COLOR_EGO, COLOR_COOP])), min_size=1, max_size=4)


@settings(max_examples=60, deadline=None)
@given(batch=updates)
def test_scene_updates_equal_the_sdk_encoding(batch) -> None:
    names = [[f"line-{k}" for k in range(len(drawn))] for _, drawn, _ in batch]
    arrays = [[np.array(line, dtype=float) for line in drawn] for _, drawn, _ in batch]
    flat = [line for group in arrays for line in group]
    coordinates_m = np.concatenate(flat) if flat else np.empty((0, 2))
    encoded = wire.scene_updates([(ns, ids, color) for (ns, _, color), ids in zip(batch, names)], coordinates_m,
                                 [len(line) for line in flat], LINE_THICKNESS_M, FRAME_ID)
    expected = [scene_update(ns, ids, group, color).encode() for (ns, _, color), ids, group in
                zip(batch, names, arrays)]
    assert encoded == expected


@settings(max_examples=60, deadline=None)
@given(ns=STAMPS_NS, sender=st.sampled_from(["ego", "coop1", "coop_2-b"]), x=coordinates, y=coordinates,
       yaw=st.one_of(st.sampled_from([0.0, -0.0, np.pi, -np.pi]), st.floats(-4.0, 4.0)))
def test_frame_transforms_equal_the_sdk_encoding(ns, sender, x, y, yaw) -> None:
    assert wire.frame_transform(ns, FRAME_ID, sender, x, y, yaw) == frame_transform(ns, sender, x, y, yaw).encode()


def test_points_leave_out_zero_coordinates_and_give_each_point_s_offset() -> None:
    data, offsets = wire.points(np.array([[1.0, 2.0], [0.0, 2.0], [-0.0, 0.0]]))
    assert offsets.tolist() == [0, 20, 31, 33]
    assert data[20:22] == bytes((0x2A, 9)) and data[22] == 0x11 and data[31:] == bytes((0x2A, 0))
