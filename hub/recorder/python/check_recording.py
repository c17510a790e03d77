#!/usr/bin/env python3
"""Checks an iwsim recording with third-party readers only.

    check_recording.py FILE.mcap [--summary SUMMARY.json]

Opens FILE with the PyPI `mcap` reader, decodes every Foxglove channel (`/lab`, `/robots`,
`/tf`, `/proximity`) with `mcap-protobuf-support` (classes built from the schema stored in the
file), checks that each stored schema is exactly the FileDescriptorSet of the published
`foxglove-schemas-protobuf` package and that every message also parses with that package's
own classes, then prints:

    robots: N
    ticks: T
    last pose NAME: X Y HEADING_DEG

With --summary, each robot's `final_pose` in iwsim's summary.json must match its last pose in
the recording (summary.json rounds to 0.1 mm and 0.01 degree). Any decode error or mismatch
exits non-zero. Packages: requirements.txt beside this file.
"""

import argparse
import json
import math
import sys

from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from mcap_protobuf.schema import build_file_descriptor_set

PUBLISHED = {
    "foxglove.SceneUpdate": SceneUpdate,
    "foxglove.FrameTransforms": FrameTransforms,
}
EXPECTED = {
    "/lab": "foxglove.SceneUpdate",
    "/robots": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/proximity": "foxglove.SceneUpdate",
}


def fail(message: str) -> None:
    print(f"error: {message}", file=sys.stderr)
    sys.exit(1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("--summary", help="iwsim summary.json to compare final poses with")
    args = parser.parse_args()

    published_sets = {
        name: build_file_descriptor_set(cls).SerializeToString(deterministic=True) for name, cls in PUBLISHED.items()
    }

    with open(args.file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            fail("the file has no summary section (the recording was not finished)")
        topics = {c.topic: c for c in summary.channels.values()}
        for topic, schema_name in EXPECTED.items():
            channel = topics.get(topic)
            if channel is None:
                fail(f"no channel {topic}")
            schema = summary.schemas.get(channel.schema_id)
            if schema is None or schema.name != schema_name or schema.encoding != "protobuf":
                fail(f"{topic} does not carry the protobuf schema {schema_name}")
            if channel.message_encoding != "protobuf":
                fail(f"{topic} has message encoding {channel.message_encoding!r}")
            if schema.data != published_sets[schema_name]:
                fail(f"{topic}'s schema is not the published {schema_name} descriptor set")

        counts = {topic: 0 for topic in EXPECTED}
        last_poses: dict[str, tuple[float, float, float]] = {}
        names_seen: set[str] = set()
        ticks: set[int] = set()
        try:
            for schema, channel, message, decoded in reader.iter_decoded_messages(topics=list(EXPECTED)):
                counts[channel.topic] += 1
                # The same bytes must parse with the published package's own classes.
                own = PUBLISHED[schema.name].FromString(message.data)
                if own.SerializeToString(deterministic=True) != decoded.SerializeToString(deterministic=True):
                    fail(f"{channel.topic} at {message.log_time} decodes differently with the published classes")
                if channel.topic == "/tf":
                    ticks.add(message.log_time)
                    for t in decoded.transforms:
                        if t.parent_frame_id != "world":
                            fail(f"/tf parent frame {t.parent_frame_id!r}, expected 'world'")
                        q = t.rotation
                        heading = math.degrees(2.0 * math.atan2(q.z, q.w))
                        heading = (heading + 180.0) % 360.0 - 180.0
                        last_poses[t.child_frame_id] = (t.translation.x, t.translation.y, heading)
                        names_seen.add(t.child_frame_id)
                elif channel.topic == "/robots":
                    for e in decoded.entities:
                        if len(e.cubes) != 1 or len(e.texts) != 1:
                            fail(f"/robots entity {e.id} should be one box and one label")
        except Exception as e:  # noqa: BLE001 - any decoder failure is a failed check
            fail(f"decoding failed: {type(e).__name__}: {e}")

        for topic, n in counts.items():
            if n == 0 and topic != "/proximity":
                fail(f"no messages on {topic}")

    print(f"robots: {len(names_seen)}")
    print(f"ticks: {len(ticks)}")
    for name in sorted(last_poses):
        x, y, h = last_poses[name]
        print(f"last pose {name}: {x:.6f} {y:.6f} {h:.4f}")

    if args.summary:
        with open(args.summary, encoding="utf-8") as f:
            run = json.load(f)
        for robot in run.get("robots", []):
            name = robot["name"]
            if name not in last_poses:
                fail(f"summary robot {name} is not in the recording")
            x, y, h = last_poses[name]
            sx, sy, sh = robot["final_pose"]
            dh = (h - sh + 180.0) % 360.0 - 180.0
            if abs(x - sx) > 1e-3 or abs(y - sy) > 1e-3 or abs(dh) > 0.02:
                fail(f"{name}: recording ends at ({x}, {y}, {h}), summary says ({sx}, {sy}, {sh})")
        print(f"summary: {len(run.get('robots', []))} final poses match")


if __name__ == "__main__":
    main()
