#!/usr/bin/env bash
# Regenerate softplc/protocols/sparkplug/sparkplug_b_pb2.py (and its .pyi) from sparkplug_b.proto.
# The generated module is committed, so installing softplc needs no protobuf compiler; run this
# after changing the .proto. protoc comes from grpcio-tools, in a throw-away virtualenv; its
# version decides the protobuf runtime the module needs (pyproject.toml pins protobuf to match).
set -euo pipefail
cd "$(dirname "$0")/.."
GRPCIO_TOOLS=grpcio-tools==1.85.1  # protoc 35.1: gencode for protobuf 7.35 and later 7.x
tools=$(mktemp -d)
trap 'rm -rf "$tools"' EXIT
python3 -m venv "$tools"
"$tools/bin/pip" install --quiet --disable-pip-version-check "$GRPCIO_TOOLS"
folder=softplc/protocols/sparkplug
"$tools/bin/python" -m grpc_tools.protoc --proto_path="$folder" --python_out="$folder" --pyi_out="$folder" "$folder/sparkplug_b.proto"
echo "generated $folder/sparkplug_b_pb2.py and sparkplug_b_pb2.pyi with $("$tools/bin/python" -m grpc_tools.protoc --version)"
