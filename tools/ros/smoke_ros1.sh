#!/usr/bin/env bash
# ROS 1 smoke test on loopback with Debian's packages: a real rosmaster, a rospy publisher of
# sensor_msgs/Image, rostopic echo as subscriber; optionally `rosbag play BAG` with an echo of
# its colour topic.
#
#   tools/ros/smoke_ros1.sh [BAG]
#
# Env: ROS_SMOKE_PORT (default 11311). Everything listens on 127.0.0.1 only.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
port="${ROS_SMOKE_PORT:-11311}"
export ROS_MASTER_URI="http://127.0.0.1:$port" ROS_IP=127.0.0.1
unset ROS_HOSTNAME
tmp="$(mktemp -d)"
export ROS_HOME="$tmp/ros_home" ROS_LOG_DIR="$tmp/log"
master=""
cleanup() {
    [[ -n "$master" ]] && kill "$master" 2>/dev/null && wait "$master" 2>/dev/null
    rm -rf "$tmp"
}
trap cleanup EXIT

rosmaster --core -p "$port" >"$tmp/master.log" 2>&1 &
master=$!
for _ in $(seq 50); do
    rostopic list >/dev/null 2>&1 && break
    sleep 0.1
done
rostopic list >/dev/null || { cat "$tmp/master.log"; echo "rosmaster did not come up" >&2; exit 1; }

topic=/voxpan_smoke/image
timeout 20 rostopic echo -n 1 --noarr "$topic" >"$tmp/echo.txt" 2>&1 &
echo_pid=$!
/usr/bin/python3 "$here/ros1_image_pub.py" "$topic" 30 10 >"$tmp/pub.log" 2>&1 &
pub_pid=$!
wait "$echo_pid" || { cat "$tmp/echo.txt" "$tmp/pub.log"; echo "rostopic echo got nothing" >&2; exit 1; }
kill "$pub_pid" 2>/dev/null || true
wait "$pub_pid" 2>/dev/null || true
grep -q 'encoding: "rgb8"' "$tmp/echo.txt" || { cat "$tmp/echo.txt"; exit 1; }
echo "ros1 smoke: rospy -> rostopic echo of sensor_msgs/Image on $ROS_MASTER_URI: ok"

if [[ -n "${1:-}" ]]; then
    # rosbag play waits only 0.2 s after advertising (-d sets it): subscribe first.
    timeout 30 rostopic echo -n 1 --noarr /camera/color/image_raw >"$tmp/bag_echo.txt" 2>&1 &
    echo_pid=$!
    sleep 1
    rosbag play -q -d 1 "$1" >"$tmp/play.log" 2>&1
    wait "$echo_pid" || { cat "$tmp/bag_echo.txt" "$tmp/play.log"; exit 1; }
    grep -q 'height:' "$tmp/bag_echo.txt" || { cat "$tmp/bag_echo.txt"; exit 1; }
    echo "ros1 smoke: rosbag play $1 -> rostopic echo /camera/color/image_raw: ok"
fi
