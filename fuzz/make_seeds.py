"""Writes the seeds of the bag_file and live_messages fuzz targets from bags of a tiny
synthetic world (written by tools/ros/make_test_bags.py):

    target/ros-venv/bin/python fuzz/make_seeds.py BAGS_DIR

BAGS_DIR holds NAME.bag (ROS 1) and NAME-mcap/ (ROS 2). bag_file's seeds are the bag files
(ROS 1, MCAP and SQLite); live_messages' are one message body of each type from the ROS 1
bag (TCPROS bytes) and the MCAP (CDR), behind the target's selector byte; assembler's are
every message of the ROS 1 bag and the MCAP in log order, as `[input][length u16 LE][body]`
behind the set-up byte (wire, masks from topics)."""
import sys
from pathlib import Path

from rosbags.highlevel import AnyReader

# The target's decoders, by ROS type: (selector >> 1).
DECODERS = {
    "sensor_msgs/msg/Image": None,  # colour, depth or labels: by topic below
    "sensor_msgs/msg/CameraInfo": 3,
    "tf2_msgs/msg/TFMessage": 4,
    "geometry_msgs/msg/PoseStamped": 5,
    "std_msgs/msg/String": 6,
}
IMAGE_BY_WORD = {"color": 0, "depth": 1, "segments": 2}
# The assembler target's inputs, by the default topics (voxpan_bag::BagOptions).
ASSEMBLER_INPUTS = {
    "/camera/color/image_raw": 0,
    "/camera/aligned_depth_to_color/image_raw": 1,
    "/camera/color/camera_info": 2,
    "/tf": 3,
    "/tf_static": 4,
    "/camera/segments/image": 6,
    "/camera/segments/labels": 7,
}


def assembler_seed(bag: Path, wire: int) -> bytes:
    out = bytearray([wire | 2])
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            code = ASSEMBLER_INPUTS.get(conn.topic)
            if code is not None and len(raw) < 1 << 16:
                out += bytes([code]) + len(raw).to_bytes(2, "little") + raw
    return bytes(out)


def selector(topic: str, msgtype: str):
    code = DECODERS.get(msgtype, -1)
    if code is None:
        code = next((c for w, c in IMAGE_BY_WORD.items() if w in topic), None)
    return None if code in (None, -1) else code


def main() -> None:
    bags = Path(sys.argv[1])
    here = Path(__file__).resolve().parent / "seeds"
    out_bags, out_live = here / "bag_file", here / "live_messages"
    out_bags.mkdir(parents=True, exist_ok=True)
    out_live.mkdir(parents=True, exist_ok=True)
    ros1 = next(bags.glob("*.bag"))
    mcap = next(bags.glob("*-mcap"))
    db3 = next(bags.glob("*-db3/*.db3"))
    for src, name in [(ros1, "ros1.bag"), (next(mcap.glob("*.mcap")), "ros2.mcap"),
                      (db3, "ros2.db3")]:
        (out_bags / name).write_bytes(src.read_bytes())
    out_assembler = here / "assembler"
    out_assembler.mkdir(parents=True, exist_ok=True)
    for path, wire, tag in [(ros1, 0, "ros1"), (next(mcap.glob("*.mcap")), 1, "cdr")]:
        (out_assembler / f"{tag}-stream").write_bytes(assembler_seed(path, wire))
    for path, wire, tag in [(ros1, 0, "ros1"), (mcap, 1, "cdr")]:
        seen = set()
        with AnyReader([path]) as reader:
            for conn, _, raw in reader.messages():
                code = selector(conn.topic, conn.msgtype)
                if code is None or (code, conn.topic) in seen:
                    continue
                seen.add((code, conn.topic))
                stem = conn.topic.strip("/").replace("/", "_")
                (out_live / f"{tag}-{stem}").write_bytes(bytes([code << 1 | wire]) + raw)


if __name__ == "__main__":
    main()
