#!/usr/bin/env bash
# Regenerates the protobuf descriptor sets that smocap embeds as MCAP schema data
# (proto/descriptors/*.fds, serialized google.protobuf.FileDescriptorSet with imports) from the
# .proto files in proto/. Needs protoc: `pip install grpcio-tools` (in a venv outside the
# repository) provides it as `python -m grpc_tools.protoc`, with google/protobuf/*.proto.
# Usage: scripts/gen_descriptors.sh [python]   (default: python3)
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${1:-python3}"
INC="$("$PY" -c 'import grpc_tools, os; print(os.path.join(os.path.dirname(grpc_tools.__file__), "_proto"))')"
mkdir -p proto/descriptors
for f in foxglove/schemas smocap/smocap smocap/unfittable; do
    name="$(basename "$f")"
    "$PY" -m grpc_tools.protoc -Iproto -I"$INC" --include_imports \
        --descriptor_set_out="proto/descriptors/$name.fds" "proto/$f.proto"
done
ls -l proto/descriptors
