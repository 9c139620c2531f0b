#!/usr/bin/env bash
# Installs what voxpan's ROS tests need, idempotently (CI runs it as root on Debian bookworm):
#   - Debian's ROS 1 (Noetic-era ros_comm 1.15.15): rosmaster, rostopic, rosbag (record/play/
#     info), rospy, the message packages (Python classes and .msg files under /usr/share/*_msgs)
#   - Debian's RViz and Xvfb: the viewer test draws the map node's topics off-screen
#   - target/ros-venv: PyPI rosbags (bag writer), mcap + mcap-ros2-support (independent
#     readers), eclipse-zenoh (rmw_zenoh-format peer), numpy/pillow/tifffile
#
#   tools/ros/setup.sh            # install (a second run with nothing missing takes < 1 s)
#   tools/ros/setup.sh --check    # install, then smoke-test ROS 1 on 127.0.0.1 (smoke_ros1.sh)
#   tools/ros/setup.sh --venv-only  # only target/ros-venv (what the bag tests need; no root)
#
# Env: VOXPAN_ROS_VENV (default <repo>/target/ros-venv).
# Traps: Debian's ROS tools run under /usr/bin/python3 (their shebang); a venv's or pyenv's
# python3 cannot import rospy/rosbag. python3-rosgraph does not depend on python3-netifaces,
# which it imports when neither ROS_IP nor ROS_HOSTNAME is set: installed here too.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
venv="${VOXPAN_ROS_VENV:-$repo/target/ros-venv}"

apt_pkgs=(
    python3-rosmaster python3-rostopic python3-rosbag python3-rospy python3-roslz4
    python3-netifaces
    python3-std-msgs python3-sensor-msgs python3-geometry-msgs python3-tf2-msgs
    python3-visualization-msgs python3-rosservice python3-std-srvs python3-nav-msgs
    python3-rosnode
    ros-std-msgs ros-sensor-msgs ros-geometry-msgs ros-tf2-msgs ros-visualization-msgs ros-nav-msgs
    iproute2 rviz xvfb
)

missing=()
[[ "${1:-}" == "--venv-only" ]] && apt_pkgs=()
for p in "${apt_pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
    if [[ $(id -u) != 0 ]]; then
        echo "setup.sh: needs root to apt-get install: ${missing[*]}" >&2
        exit 1
    fi
    echo "apt-get install ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >/dev/null
fi

py="$venv/bin/python"
if [[ ! -x "$py" ]]; then
    python3 -m venv "$venv"
fi
stamp="$venv/.voxpan-requirements"
if [[ ! -f "$stamp" ]] || ! cmp -s "$stamp" "$here/requirements.txt"; then
    "$py" -m pip install --quiet --disable-pip-version-check -r "$here/requirements.txt"
    cp "$here/requirements.txt" "$stamp"
fi

if [[ "${1:-}" == "--check" ]]; then
    "$here/smoke_ros1.sh"
fi
