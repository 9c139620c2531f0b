#!/usr/bin/python3
"""Read a ROS 1 bag with Debian's python3-rosbag and decode every message with the message
classes Debian installs (python3-sensor-msgs, python3-tf2-msgs, ...): an implementation
independent of the writer (PyPI rosbags) and of voxpan.

    /usr/bin/python3 tools/ros/check_ros1_bag.py BAG

Prints JSON: {"ok", "counts": {topic: n}, "types": {topic: type}, "md5_ok",
"encodings": {topic: [encoding...]}, "compression"}. Exits 1 with the reader's error when the
bag cannot be read. Run it with Debian's python (/usr/bin/python3), not a venv's: rospy,
rosbag and the message packages live in /usr/lib/python3/dist-packages.
"""

import importlib
import json
import sys

import rosbag


def installed_class(msgtype):
    pkg, name = msgtype.split("/")
    return getattr(importlib.import_module(pkg + ".msg"), name)


def main():
    path = sys.argv[1]
    counts, types, encodings, md5_ok = {}, {}, {}, True
    with rosbag.Bag(path) as bag:
        info = bag.get_type_and_topic_info()
        compression = bag.get_compression_info().compression
        classes = {}
        for topic, t in info.topics.items():
            types[topic] = t.msg_type
            cls = installed_class(t.msg_type)
            classes[topic] = cls
        for conn in bag._connections.values():
            if conn.md5sum != classes[conn.topic]._md5sum:
                md5_ok = False
        for topic, raw, t in bag.read_messages(raw=True):
            _, data, md5, _, _ = raw
            msg = classes[topic]()
            msg.deserialize(data)
            counts[topic] = counts.get(topic, 0) + 1
            if types[topic] == "sensor_msgs/Image":
                encodings.setdefault(topic, set()).add(msg.encoding)
                if msg.header.stamp != t:
                    raise SystemExit(f"{topic}: header stamp {msg.header.stamp} != record time {t}")
                if len(msg.data) != msg.step * msg.height:
                    raise SystemExit(f"{topic} at {t}: data length {len(msg.data)} != step*height")
    print(json.dumps({
        "ok": True, "counts": counts, "types": types, "md5_ok": md5_ok,
        "encodings": {k: sorted(v) for k, v in encodings.items()}, "compression": compression,
    }))


if __name__ == "__main__":
    main()
