#!/usr/bin/env bash
# ROS 1 across two hosts (netns.sh): rosmaster and `rosbag play BAG` on host a, rostopic echo
# on host b. What voxpan's two-computer test does with voxpan's nodes in between
# (perceive on a, map on b).
#
#   tools/ros/smoke_ros1_netns.sh BAG
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
bag="$(realpath "${1:?bag}")"
tmp="$(mktemp -d)"
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
    "$here/netns.sh" down
    rm -rf "$tmp"
}
trap cleanup EXIT
export ROS_HOME="$tmp/ros_home" ROS_LOG_DIR="$tmp/log"
"$here/netns.sh" up
on() { "$here/netns.sh" exec "$@"; }

on a rosmaster --core -p 11311 >"$tmp/master.log" 2>&1 &
pids+=($!)
for _ in $(seq 50); do on b rostopic list >/dev/null 2>&1 && break; sleep 0.1; done
on b timeout 30 rostopic echo -n 1 --noarr /camera/color/image_raw >"$tmp/echo.txt" 2>&1 &
echo_pid=$!
sleep 1
on a rosbag play -q -d 1 "$bag" >"$tmp/play.log" 2>&1
wait "$echo_pid" || { cat "$tmp/echo.txt" "$tmp/play.log"; exit 1; }
grep -q 'height:' "$tmp/echo.txt" || { cat "$tmp/echo.txt"; exit 1; }
on b rostopic info /camera/color/image_raw >/dev/null 2>&1 || true
echo "ros1 two hosts: rosbag play on a ($(on a sh -c 'echo $ROS_IP')) -> rostopic echo on b ($(on b sh -c 'echo $ROS_IP')): ok"
