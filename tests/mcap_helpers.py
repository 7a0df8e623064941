"""Test helpers for MCAP recordings: every message decoded (JSON or the Foxglove protobuf
schemas, from the schema records the file carries), and a recording in the version-1
format (JSON only, float ``stamp_s``, log times from 0) written with the ``mcap`` library as
cold-eval wrote it before foxglove-sdk."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

_PROTO_CLASSES: dict[tuple[str, bytes], Any] = {}


def proto_class(name: str, data: bytes) -> Any:
    """The protobuf message class ``name`` from a serialised ``FileDescriptorSet``."""
    key = (name, data)
    if key not in _PROTO_CLASSES:
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        pool = descriptor_pool.DescriptorPool()
        for file in descriptor_pb2.FileDescriptorSet.FromString(data).file:
            pool.Add(file)
        descriptor = pool.FindMessageTypeByName(name)
        factory = message_factory.MessageFactory(pool)
        get_class = getattr(message_factory, "GetMessageClass", None)
        _PROTO_CLASSES[key] = get_class(descriptor) if get_class else factory.GetPrototype(descriptor)
    return _PROTO_CLASSES[key]


def read_all(path: Path) -> tuple[Any, list[tuple[str, str, Any, int]], dict[str, dict[str, str]]]:
    """Summary, messages as (topic, schema name, decoded message, log time ns), metadata.

    JSON messages decode to dicts, protobuf ones to protobuf message objects."""
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        messages = []
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding == "json":
                decoded = json.loads(message.data)
            else:
                assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
                decoded = proto_class(schema.name, schema.data).FromString(message.data)
            messages.append((channel.topic, schema.name, decoded, message.log_time))
        metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
    return summary, messages, metadata


V1_LANE_DETECTION_SCHEMA: dict[str, Any] = {
    "title": "cold.LaneDetection",
    "type": "object",
    "properties": {"stamp_s": {"type": "number"}, "frame": {"type": "integer"}, "sender": {"type": "string"},
                   "pose": {"type": "object"}, "left": {"type": "array"}, "right": {"type": "array"}},
    "required": ["stamp_s", "frame", "sender", "pose", "left", "right"],
}


def write_v1_recording(path: Path, detections: Sequence[tuple[float, int, str, tuple[float, float, float],
                                                               np.ndarray, np.ndarray]],
                       map_path: str = "") -> None:
    """A version-1 recording of ``(stamp_s, frame, sender, (x, y, yaw), left, right)``
    detections on ``/cold/detections`` (log time = stamp in ns from 0), with the
    ``cold.run`` (no ``recording_version``) and ``cold.status`` metadata."""
    with open(path, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="", library="cold-maps")
        writer.add_metadata("cold.run", {"map": map_path, "params": "{}"})
        schema = writer.register_schema(name="cold.LaneDetection", encoding="jsonschema",
                                        data=json.dumps(V1_LANE_DETECTION_SCHEMA).encode())
        channel = writer.register_channel(topic="/cold/detections", message_encoding="json", schema_id=schema)
        for sequence, (stamp_s, frame, sender, (x, y, yaw), left, right) in enumerate(detections):
            message = {"stamp_s": stamp_s, "frame": frame, "sender": sender, "pose": {"x": x, "y": y, "yaw": yaw},
                       "left": np.asarray(left).tolist(), "right": np.asarray(right).tolist()}
            ns = round(stamp_s * 1e9)
            writer.add_message(channel_id=channel, log_time=ns, publish_time=ns, sequence=sequence,
                               data=json.dumps(message, separators=(",", ":")).encode())
        writer.add_metadata("cold.status", {"status": "complete"})
        writer.finish()
