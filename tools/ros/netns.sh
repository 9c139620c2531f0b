#!/usr/bin/env bash
# Two test "hosts" on one machine: network namespaces joined by a veth pair (root needed).
#
#   tools/ros/netns.sh up        # voxpan-a 10.213.0.1/24 <-veth-> voxpan-b 10.213.0.2/24
#   tools/ros/netns.sh down
#   tools/ros/netns.sh exec a|b CMD...   # run CMD in host a or b, ROS_IP/ROS_MASTER_URI set
#
# Env: VOXPAN_NETNS_A/B (names), VOXPAN_NETNS_NET (first three octets, default 10.213.0).
# The addresses exist only inside the two namespaces: traffic between them never leaves the
# veth pair. Each namespace has its own loopback (brought up here): 127.0.0.1 in a is not
# 127.0.0.1 in b, nor the machine's. The ROS master runs in a (ROS_MASTER_URI points there).
set -euo pipefail
a="${VOXPAN_NETNS_A:-voxpan-a}"
b="${VOXPAN_NETNS_B:-voxpan-b}"
net="${VOXPAN_NETNS_NET:-10.213.0}"
va="${a:0:11}-v"  # interface names: at most 15 characters
vb="${b:0:11}-v"

case "${1:-}" in
up)
    ip netns list | grep -qw "$a" || ip netns add "$a"
    ip netns list | grep -qw "$b" || ip netns add "$b"
    if ! ip -n "$a" link show "$va" >/dev/null 2>&1; then
        ip link add "$va" type veth peer name "$vb"
        ip link set "$va" netns "$a"
        ip link set "$vb" netns "$b"
        ip -n "$a" addr add "$net.1/24" dev "$va"
        ip -n "$b" addr add "$net.2/24" dev "$vb"
    fi
    for ns in "$a" "$b"; do ip -n "$ns" link set lo up; done
    ip -n "$a" link set "$va" up
    ip -n "$b" link set "$vb" up
    ;;
down)
    # Deleting a namespace destroys its end of the veth pair, and with it the other end.
    ip netns list | grep -qw "$a" && ip netns del "$a"
    ip netns list | grep -qw "$b" && ip netns del "$b"
    true
    ;;
exec)
    host="${2:?a or b}"; shift 2
    case "$host" in
    a) ns="$a"; ip_="$net.1" ;;
    b) ns="$b"; ip_="$net.2" ;;
    *) echo "host must be a or b" >&2; exit 2 ;;
    esac
    exec ip netns exec "$ns" env ROS_IP="$ip_" ROS_MASTER_URI="http://$net.1:${ROS_PORT:-11311}" "$@"
    ;;
*)
    echo "usage: $0 up|down|exec a|b CMD..." >&2
    exit 2
    ;;
esac
