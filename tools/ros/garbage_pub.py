"""Publishes garbage on every topic the named ROS 1 nodes subscribe to, as anyone on a robot's
network could (ROS 1 has no authentication):

    python3 garbage_pub.py --count K [--type TOPIC=TYPE ...] NODE [NODE ...]

For each topic a node subscribes to (asked of the master; its type from the master, the
node, or --type), K message bodies of random bytes
(a fixed seed per topic, 16 to 2,000 bytes) are sent with the topic's real type and MD5 sum,
so the TCPROS handshake succeeds and only the body is wrong. Bytes 0-3 and 12-15 hold
0xFFFFFFF0: a header's frame_id length or a message's first array or string length then
claims more than the body holds, so no body can decode as a valid message by chance.

Prints `garbage NODE TOPIC TYPE K` for each node and topic, then `published N`. Needs
Debian's rospy and the standard message packages (tools/ros/setup.sh)."""
import argparse
import random
import sys
import time
from xmlrpc.client import ServerProxy

import genpy
import rosgraph
import roslib.message
import rospy


def garbage_class(msg_type: str):
    real = roslib.message.get_message_class(msg_type)
    if real is None:
        sys.exit(f"garbage_pub: no message class for {msg_type}")

    class Garbage(genpy.Message):
        __slots__ = ["raw"]
        _slot_types = ["uint8[]"]
        _type = real._type
        _md5sum = real._md5sum
        _full_text = real._full_text
        _has_header = False

        def __init__(self, raw: bytes = b""):
            self.raw = raw

        def serialize(self, buff):
            buff.write(self.raw)

    return Garbage


def bodies(topic: str, count: int) -> list[bytes]:
    rng = random.Random(topic)
    out = []
    for i in range(count):
        body = bytearray(rng.randbytes(rng.choice([16, 40, 300, 2000])))
        body[0:4] = body[12:16] = (0xFFFFFFF0).to_bytes(4, "little")
        out.append(bytes(body))
    return out


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--count", type=int, default=3)
    p.add_argument("--type", action="append", default=[], metavar="TOPIC=TYPE",
                   help="a subscribed topic's type, where no publisher or node declares it")
    p.add_argument("nodes", nargs="+")
    a = p.parse_args()
    rospy.init_node("voxpan_garbage", anonymous=True, disable_signals=True)
    master = rosgraph.Master(rospy.get_name())
    _, subscriptions, _ = master.getSystemState()
    # The master lists types of published topics only; nodes may say their subscriptions'
    # (roslibrust's say `*`); the rest come from --type.
    types = dict(master.getTopicTypes())
    types.update(spec.split("=", 1) for spec in a.type)
    for node in a.nodes:
        code, message, subscribed = ServerProxy(master.lookupNode(node)).getSubscriptions(
            rospy.get_name())
        if code != 1:
            sys.exit(f"garbage_pub: {node}'s getSubscriptions: {message}")
        types.update({t: ty for t, ty in subscribed if ty != "*"})
    targets = {}  # topic -> subscribing nodes among those named
    for topic, nodes in subscriptions:
        named = [n for n in nodes if n in a.nodes]
        if named:
            targets[topic] = named
    missing = [n for n in a.nodes if not any(n in ns for ns in targets.values())]
    if missing:
        sys.exit(f"garbage_pub: {missing} subscribe to nothing the master knows of")
    publishers, classes = {}, {}
    for topic in sorted(targets):
        if topic not in types:
            sys.exit(f"garbage_pub: the master knows no type for {topic}")
        classes[topic] = garbage_class(types[topic])
        publishers[topic] = rospy.Publisher(topic, classes[topic], queue_size=1000)
    deadline = time.monotonic() + 15
    while any(publishers[t].get_num_connections() < len(targets[t]) for t in publishers):
        if time.monotonic() > deadline:
            late = [t for t in publishers if publishers[t].get_num_connections() < len(targets[t])]
            sys.exit(f"garbage_pub: no connection to every subscriber of {late}")
        time.sleep(0.05)
    published = 0
    for topic, publisher in publishers.items():
        for body in bodies(topic, a.count):
            publisher.publish(classes[topic](body))
            published += 1
            time.sleep(0.01)
        for node in targets[topic]:
            print(f"garbage {node} {topic} {types[topic]} {a.count}", flush=True)
    # The queues drain before the publishers go.
    time.sleep(2)
    print(f"published {published}", flush=True)
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
