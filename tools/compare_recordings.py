"""Compare the messages of two ``run.mcap`` recordings, decoded: same channels and schemas,
and message by message in file order the same topic, log time and content, times taken
relative to each recording's stamp base (``cold.run`` ``stamp_base_ns``), so two runs
started at different wall-clock times compare equal when they recorded the same frames.

Protobuf messages (the Foxglove schemas the file carries) are compared field by field
(their ``google.protobuf.Timestamp`` fields made relative, then serialised
deterministically), JSON ones as decoded objects (``stamp`` made relative). The metadata
records are printed where they differ (the run parameters name the output folder) but not
counted. Exit status 0 when no message differs, 1 otherwise.

Usage: ``python tools/compare_recordings.py BASE.mcap NEW.mcap [--show 5]``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path
from typing import Any, Iterator

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from mcap_helpers import read_all  # noqa: E402

TIMESTAMP = "google.protobuf.Timestamp"
NS_PER_S = 1_000_000_000


def _relative_proto(message: Any, base_ns: int) -> None:
    """Every Timestamp field inside ``message`` shifted by ``-base_ns``, in place."""
    for field, value in message.ListFields():
        if field.message_type is None:
            continue
        values = value if field.label == field.LABEL_REPEATED else [value]
        for item in values:
            if field.message_type.full_name == TIMESTAMP:
                ns = item.seconds * NS_PER_S + item.nanos - base_ns
                item.seconds, item.nanos = divmod(ns, NS_PER_S)
            else:
                _relative_proto(item, base_ns)


def canonical(decoded: Any, base_ns: int) -> Any:
    """A comparable form of a decoded message with its times relative to ``base_ns``."""
    if isinstance(decoded, dict):
        stamp = decoded.get("stamp")
        if isinstance(stamp, dict):
            decoded = {**decoded, "stamp": stamp["sec"] * NS_PER_S + stamp["nsec"] - base_ns}
        return decoded
    _relative_proto(decoded, base_ns)
    return decoded.SerializeToString(deterministic=True)


def messages(path: Path) -> tuple[list[tuple[str, str, str]], Iterator[tuple[str, str, int, Any]], dict[str, Any]]:
    """Channels (topic, schema, encoding), messages (topic, schema, relative log time ns,
    canonical content) and metadata of a recording."""
    summary, decoded, metadata = read_all(path)
    base = int(metadata.get("cold.run", {}).get("stamp_base_ns", "0"))
    channels = sorted((c.topic, summary.schemas[c.schema_id].name if c.schema_id else "", c.message_encoding)
                      for c in summary.channels.values())
    return channels, ((topic, schema, log_time - base, canonical(message, base))
                      for topic, schema, message, log_time in decoded), metadata


def compare(base: Path, new: Path, show: int = 5) -> int:
    """Prints the differences of two recordings; returns the number of differing messages
    (a missing or extra message counts as one)."""
    base_channels, base_messages, base_metadata = messages(base)
    new_channels, new_messages, new_metadata = messages(new)
    differing = 0
    if base_channels != new_channels:
        differing += 1
        print(f"channels differ: {sorted(set(base_channels) ^ set(new_channels))}")
    for name in sorted(set(base_metadata) | set(new_metadata)):
        old, now = base_metadata.get(name, {}), new_metadata.get(name, {})
        if "params" in old and "params" in now:  # a JSON object: its differing keys only
            old, now = ({**m, **{f"params.{k}": v for k, v in json.loads(m["params"]).items()}, "params": ""}
                        for m in (old, now))
        changed = {key: (old.get(key), now.get(key)) for key in sorted(set(old) | set(now))
                   if key != "stamp_base_ns" and old.get(key) != now.get(key)}
        if changed:
            print(f"metadata {name} differs (not counted): {changed}")
    count = 0
    for index, pair in enumerate(_paired(base_messages, new_messages)):
        count += 1
        old, now = pair
        if old != now:
            differing += 1
            if differing <= show:
                print(f"message {index} differs: {_brief(old)} | {_brief(now)}")
    print(f"{base.name} vs {new.name}: {count} messages, {differing} differing")
    return differing


def _paired(first: Iterator[Any], second: Iterator[Any]) -> Iterator[tuple[Any, Any]]:
    """Pairs of both sequences, None for the shorter one's missing items."""
    missing = object()
    for old, now in itertools.zip_longest(first, second, fillvalue=missing):
        yield (None if old is missing else old), (None if now is missing else now)


def _brief(message: tuple[str, str, int, Any] | None) -> str:
    if message is None:
        return "missing"
    topic, schema, log_time, _ = message
    return f"{topic} {schema} at {log_time} ns"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("base", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--show", type=int, default=5, help="differing messages to print")
    args = parser.parse_args(argv)
    for path in (args.base, args.new):
        if not path.is_file():
            raise SystemExit(f"compare_recordings: {path}: no such file")
    return 1 if compare(args.base, args.new, args.show) else 0


if __name__ == "__main__":
    sys.exit(main())
