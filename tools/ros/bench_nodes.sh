#!/usr/bin/env bash
# Latency and throughput of the ROS nodes on the flat sample (640x480): rosbag play of the
# flat frames as a RealSense-style bag -> `voxpan node perceive` -> `voxpan node map`, on this
# machine's loopback or on two hosts made of network namespaces (tools/ros/netns.sh, root).
# ROS 1: Debian's rosmaster and rosbag play. ROS 2 (`ros2`): tools/ros/ros2_peer.py is the
# router (rmw_zenohd's role) and plays an MCAP bag of the same frames; the nodes run --ros2.
# Prints the input rate and the frames integrated per second of playing (the throughput when
# frames are dropped), then each node's summary: frames in/done, drops (busy + lagged), and
# latency from the perception node receiving a depth image to its publication (perceive) and
# to its integration in the map node (map). The flat sample's stamps are about 1 s apart, so
# RATE 1 measures latency unloaded and a high RATE (50) the throughput.
#
#   tools/ros/bench_nodes.sh [loopback|two-hosts] [RATE] [ros1|ros2]   # RATE: play -r (1)
#
# Env: VOXPAN (binary, default target/release/voxpan; build it with --features ros1, or
# ros2 for ROS 2), PERCEIVE_ARGS (more options for `node perceive`, split at spaces: a
# network and keyframes, e.g. "--model yolov5s-seg.onnx --segment-every 5"),
# FLAT (default ../shared/data/flat), VOXPAN_ROS_VENV (the rosbags venv of setup.sh).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
layout="${1:-loopback}"
rate="${2:-1}"
ros="${3:-ros1}"
[[ "$ros" == ros1 || "$ros" == ros2 ]] || { echo "middleware: ros1 or ros2" >&2; exit 2; }
voxpan="${VOXPAN:-$repo/target/release/voxpan}"
flat="${FLAT:-$repo/../shared/data/flat}"
py="${VOXPAN_ROS_VENV:-$repo/target/ros-venv}/bin/python"
[[ -x "$voxpan" ]] || { echo "no $voxpan: cargo build --release --features $ros" >&2; exit 1; }
"$voxpan" node map --help >/dev/null
tmp="$(mktemp -d)"
pids=()
export VOXPAN_NETNS_A=vxbench-a VOXPAN_NETNS_B=vxbench-b VOXPAN_NETNS_NET=10.214.0 ROS_PORT=11411
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    wait 2>/dev/null || true
    [[ "$layout" == two-hosts ]] && "$here/netns.sh" down
    rm -rf "$tmp"
}
trap cleanup EXIT
export ROS_HOME="$tmp/ros_home" ROS_LOG_DIR="$tmp/log"
unset ROS_HOSTNAME
# Command prefixes that run a program on host a or b. Arrays, not functions: a background
# `prefix cmd &` then has the program's own pid in $! (netns.sh execs), so SIGINT reaches it.
case "$layout" in
loopback)
    export ROS_MASTER_URI="http://127.0.0.1:$ROS_PORT" ROS_IP=127.0.0.1
    on_a=() on_b=()
    ;;
two-hosts)
    "$here/netns.sh" up
    on_a=("$here/netns.sh" exec a) on_b=("$here/netns.sh" exec b)
    ;;
*) echo "layout: loopback or two-hosts" >&2; exit 2 ;;
esac

if [[ "$ros" == ros1 ]]; then
    "$py" "$here/make_test_bags.py" "$flat" "$tmp/bags" --name flat --formats ros1 --no-verify >/dev/null
    "${on_a[@]}" rosmaster --core -p "$ROS_PORT" >"$tmp/master.log" 2>&1 &
    pids+=($!)
    for _ in $(seq 100); do "${on_a[@]}" rostopic list >/dev/null 2>&1 && break; sleep 0.2; done
    middleware_a=() middleware_b=()
else
    "$py" "$here/make_test_bags.py" "$flat" "$tmp/bags" --name flat --formats mcap --no-verify >/dev/null
    addr_a=127.0.0.1 addr_b=127.0.0.1
    [[ "$layout" == two-hosts ]] && addr_a="$VOXPAN_NETNS_NET.1" addr_b="$VOXPAN_NETNS_NET.2"
    # The router runs with the player on host b (below), as rosbag play does for ROS 1.
    router="tcp/$addr_b:$ROS_PORT"
    middleware_a=(--ros2 --zenoh-connect "$router" --zenoh-listen "tcp/$addr_a:0")
    middleware_b=(--ros2 --zenoh-connect "$router" --zenoh-listen "tcp/$addr_b:0")
fi
"${on_a[@]}" "$voxpan" node map "${middleware_a[@]}" --save "$tmp/map.voxpan" >"$tmp/map.log" 2>&1 &
map=$!
pids+=($map)
read -r -a perceive_args <<<"${PERCEIVE_ARGS:-}"
"${on_b[@]}" "$voxpan" node perceive "${middleware_b[@]}" --labels-topic /camera/segments/image \
    "${perceive_args[@]}" >"$tmp/perceive.log" 2>&1 &
perceive=$!
pids+=($perceive)
for _ in $(seq 100); do
    grep -q listening "$tmp/map.log" && grep -q listening "$tmp/perceive.log" && break
    sleep 0.2
done
kill -0 "$map" "$perceive" 2>/dev/null || {
    cat "$tmp/map.log" "$tmp/perceive.log" >&2
    echo "a node did not start (a voxpan built with --features $ros?)" >&2
    exit 1
}
if [[ "$ros" == ros1 ]]; then
    t0=$(date +%s.%N)
    "${on_b[@]}" rosbag play -q -d 3 -r "$rate" "$tmp/bags/flat.bag" >"$tmp/play.log" 2>&1
    t1=$(date +%s.%N)
    # Throughput while the bag plays (play's 3 s start delay left out).
    play_s=$(echo "$t1 - $t0 - 3" | bc -l)
else
    # The router and the player on host b with the camera's node (as rosbag play for ROS 1);
    # it plays once the nodes' subscriptions are in the graph, and says how long it took.
    "${on_b[@]}" "$py" "$here/ros2_peer.py" --listen "tcp/$addr_b:$ROS_PORT" \
        --bag "$tmp/bags/flat-mcap" --rate "$rate" --report "$tmp/peer.json" \
        --wait-for /camera/color/image_raw,/camera/aligned_depth_to_color/image_raw,/voxpan/depth \
        >"$tmp/play.log" 2>&1 &
    peer=$!
    pids+=($peer)
    while kill -0 "$peer" 2>/dev/null && ! grep -q '^played' "$tmp/play.log"; do sleep 0.2; done
    play_s=$(sed -n 's/^played .* in \([0-9.]*\) s$/\1/p' "$tmp/play.log")
    [[ -n "$play_s" ]] || { cat "$tmp/play.log" >&2; echo "the ROS 2 bag was not played" >&2; exit 1; }
fi
sleep 3
kill -INT "$perceive"; wait "$perceive" || true
kill -INT "$map"; wait "$map" || true
done_frames=$(grep -c 'integrated frame' "$tmp/map.log" || true)
# When the nodes drop frames, integrated frames per second of playing is what the pair sustains.
echo "$ros, layout $layout, play -r $rate: 100 frames published in $(printf %.2f "$play_s") s" \
    "($(echo "100 / $play_s" | bc -l | xargs printf %.1f) frames/s), $done_frames integrated" \
    "($(echo "$done_frames / $play_s" | bc -l | xargs printf %.1f) per second of playing)"
echo "perceive: $(tail -n 1 "$tmp/perceive.log")"
echo "map:      $(grep 'frames in' "$tmp/map.log" | tail -n 1)"
