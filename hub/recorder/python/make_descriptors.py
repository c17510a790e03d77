#!/usr/bin/env python3
"""Writes the Foxglove schemas the recorder embeds: one serialized protobuf FileDescriptorSet per
message type, taken from the published `foxglove-schemas-protobuf` package (pinned in
requirements.txt), with every file it imports, dependencies first.

The recorder includes these bytes verbatim as each Foxglove channel's MCAP schema, so a reader
sees exactly Foxglove's published definitions. Re-run after bumping the package:

    python hub/recorder/python/make_descriptors.py hub/recorder/schemas
"""

import pathlib
import sys

from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap_protobuf.schema import build_file_descriptor_set

MESSAGES = [SceneUpdate, FrameTransforms]


def main() -> int:
    if len(sys.argv) != 2:
        print(f"usage: {sys.argv[0]} OUT_DIR", file=sys.stderr)
        return 2
    out = pathlib.Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    for message in MESSAGES:
        name = message.DESCRIPTOR.full_name
        data = build_file_descriptor_set(message).SerializeToString(deterministic=True)
        (out / f"{name}.bin").write_bytes(data)
        print(f"{name}: {len(data)} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
