#!/usr/bin/env python3
"""Write ROS 1 and ROS 2 test bags from a flat-format folder, with PyPI `rosbags`.

An implementation independent of voxpan writes the bags voxpan's bag reader is tested on:

    target/ros-venv/bin/python tools/ros/make_test_bags.py SRC OUT [options]

SRC is a flat-format dataset root (Intrinsics.txt + run1/) or a run folder (its parent then
holds Intrinsics.txt): the flat sample (../shared/data/flat) or `voxpan synth --out DIR`.
OUT gets, for NAME (default: "flat", "synth", or --name):

    NAME.bag            ROS 1, uncompressed chunks        (format ros1)
    NAME-bz2.bag        ROS 1, bz2 chunks                 (format ros1-bz2)
    NAME-lz4.bag        ROS 1, lz4 chunks                 (format ros1-lz4)
    NAME-mcap/          ROS 2 bag folder: metadata.yaml + NAME-mcap.mcap (format mcap;
                        --mcap-zstd for zstd chunks)
    NAME-db3/           ROS 2 bag folder: metadata.yaml + NAME-db3.db3 (format db3)
    NAME.manifest.json  what was written: topics, counts, stamps, frames, tf chain, options

Topics (RealSense ROS driver defaults, each can be renamed with an option):

    /camera/color/image_raw                    sensor_msgs/Image, rgb8 (--color-encoding)
    /camera/color/camera_info                  sensor_msgs/CameraInfo (from Intrinsics.txt)
    /camera/aligned_depth_to_color/image_raw   sensor_msgs/Image, 16UC1 mm or 32FC1 m (NaN =
                                               no data)  (--depth-encoding)
    /camera/aligned_depth_to_color/camera_info sensor_msgs/CameraInfo
    /tf_static                                 tf2_msgs/TFMessage: base_link -> camera_link ->
                                               camera_color_optical_frame (latched / transient
                                               local)
    /tf                                        tf2_msgs/TFMessage: world -> base_link, at every
                                               depth stamp plus --tf-rate Hz in between
    /camera/segments/image                     sensor_msgs/Image 16UC1 label image
                                               (_predicted.png), 0 = void (--label-encoding)
    /camera/segments/labels                    std_msgs/String, JSON: {"header": {"stamp":
                                               {"sec", "nanosec"}, "frame_id"}, "segments":
                                               [the frame's _labels.json entries]}
    /camera/ground_truth/image                 (--with-gt) 16UC1 _segmentation.png
    /camera/pose                               (--pose posestamped|both)
                                               geometry_msgs/PoseStamped, world <- optical

Stamps: the frame's timestamp (timestamps.csv, nanoseconds; stamps below 1e17 ns, as a
synthetic sequence's, get --time-offset-s added so that no stamp is 0) is the depth stamp and
the pose stamp; colour, colour camera_info, label image and segment list are stamped
--color-offset-ms later (default 3 ms) to exercise synchronisation. Every message's record
time is its header stamp (tf_static: the first stamp).

The chain world -> base_link -> camera_link -> camera_color_optical_frame composes to the
flat T_world_camera exactly up to float64 rounding (the manifest gives the largest
deviation).

--malform KIND writes damaged bags (NAME-KIND...): `truncated` (file cut mid-chunk),
`unknown-encoding` (one colour image in "yuv422"), `missing-camera-info` (no camera_info
topic), `tf-gap` (no /tf samples in the middle third of the sequence), `duplicate-stamp`
(the middle frame carries the stamp of the frame before it, its own /tf sample included).
The manifest says
which topic, frame and time a reader's error should name.

--export-flat DIR writes the frames as the bags carry them, in the flat layout, so that
"map from the bag == map from the folder" compares like with like: 16UC1 depth quantised to
millimetres (depth = float32(mm) / float32(1000)), mono8 colour as grey RGB, poses composed
from the tf chain, the depth stamps in timestamps.csv.

Each bag is checked after writing (--no-verify skips it): ROS 1 bags with Debian's
`rosbag info` and python3-rosbag + genpy (check_ros1_bag.py under /usr/bin/python3); ROS 2
bags with PyPI `mcap` + `mcap-ros2-support` (an independent CDR decoder; .db3 blobs are
decoded with the definitions stored in the database) and with rosbags' own reader. A
summary per bag is printed: topic, type, count, rate, duration.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shutil
import sqlite3
import subprocess
import sys
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import lz4.frame
import numpy as np
import tifffile
from PIL import Image
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

HERE = Path(__file__).resolve().parent
FORMATS = ("ros1", "ros1-bz2", "ros1-lz4", "mcap", "db3")
MALFORMS = ("truncated", "unknown-encoding", "missing-camera-info", "tf-gap", "duplicate-stamp")
ABSOLUTE_STAMP_NS = 10**17  # stamps below this are relative (synthetic): offset them

# tf2_msgs/TFMessage is missing from rosbags' ROS 1 Noetic store; its one-line definition.
TFMESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms\n"


# ---------------------------------------------------------------------------------------------
# Rigid transforms (float64, 4x4 homogeneous; quaternions x, y, z, w as in ROS)


def quat_to_matrix(q) -> np.ndarray:
    x, y, z, w = q
    n = x * x + y * y + z * z + w * w
    s = 2.0 / n
    return np.array(
        [
            [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
            [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
            [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
        ]
    )


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (largest-pivot method)."""
    t = np.trace(r)
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = [s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = [(r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def make_transform(translation, quat) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(quat)
    m[:3, 3] = translation
    return m


def invert(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def slerp(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
    else:
        th = math.acos(d)
        q = (math.sin((1 - a) * th) * q0 + math.sin(a * th) * q1) / math.sin(th)
    return q / np.linalg.norm(q)


def yaw_pitch_quat(yaw: float, pitch: float) -> np.ndarray:
    """Rotation about z by yaw, then about the new y by pitch (radians)."""
    cz, sz = math.cos(yaw / 2), math.sin(yaw / 2)
    cy, sy = math.cos(pitch / 2), math.sin(pitch / 2)
    # q_z * q_y
    return np.array([-sz * sy, cz * sy, sz * cy, cz * cy])


# The static part of the chain: base_link -> camera_link (a camera on a mast, tilted down
# 10 degrees and turned 5 degrees left), camera_link -> optical (x right, y down, z forward
# from x forward, y left, z up: the quaternion the RealSense driver publishes).
BASE_TO_LINK = ((0.05, -0.02, 0.30), yaw_pitch_quat(math.radians(5), math.radians(10)))
LINK_TO_OPTICAL = ((0.0, 0.015, 0.0), np.array([-0.5, 0.5, -0.5, 0.5]))


# ---------------------------------------------------------------------------------------------
# Frames


@dataclass
class Frame:
    id: str
    t_ns: int  # depth stamp (frame time)
    color: np.ndarray  # H x W x 3 uint8 RGB
    depth: np.ndarray  # H x W float32 metres, <= 0 or non-finite = no data
    pose: np.ndarray  # 4x4 T_world_camera (optical)
    labels: np.ndarray | None  # H x W uint8/uint16, 0 = void
    segments: list | None
    gt: np.ndarray | None


@dataclass
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float


def read_intrinsics(path: Path) -> Intrinsics:
    vals = {}
    for line in path.read_text().splitlines():
        if ":" in line:
            k, v = line.split(":", 1)
            parts = v.split()
            if parts:
                try:
                    vals[k.strip()] = float(parts[0])
                except ValueError:
                    pass
    return Intrinsics(
        int(vals["Res_x"]), int(vals["Res_y"]), vals["f_x"], vals["f_y"], vals["u"], vals["v"]
    )


def locate(src: Path) -> tuple[Path, Path]:
    """(root with Intrinsics.txt, run folder with the frames)."""
    if (src / "Intrinsics.txt").is_file():
        runs = sorted(p for p in src.iterdir() if p.is_dir() and any(p.glob("*_depth.tiff")))
        if not runs:
            sys.exit(f"{src}: no run folder with *_depth.tiff")
        return src, runs[0]
    if (src.parent / "Intrinsics.txt").is_file() and any(src.glob("*_depth.tiff")):
        return src.parent, src
    sys.exit(f"{src}: not a flat-format folder (no Intrinsics.txt)")


def channel0(a: np.ndarray) -> np.ndarray:
    return a[..., 0] if a.ndim == 3 else a


def load_frames(run: Path, max_frames: int | None, time_offset_s: float) -> list[Frame]:
    ids = sorted(p.name[: -len("_depth.tiff")] for p in run.glob("*_depth.tiff"))
    stamps: dict[str, int] = {}
    ts_file = run / "timestamps.csv"
    if ts_file.is_file():
        with ts_file.open() as f:
            for row in csv.reader(f):
                if len(row) >= 2 and row[0] != "ImageID":
                    stamps[row[0].strip()] = int(row[1])
    ids = [i for i in ids if (run / f"{i}_color.png").is_file() and (run / f"{i}_pose.txt").is_file()]
    if not stamps:
        stamps = {i: round(k * 1e9 / 30) for k, i in enumerate(ids)}
    ids = sorted((i for i in ids if i in stamps), key=lambda i: stamps[i])
    if max_frames:
        ids = ids[:max_frames]
    if len(ids) < 2:
        sys.exit(f"{run}: fewer than 2 usable frames")
    offset = 0
    if stamps[ids[0]] < ABSOLUTE_STAMP_NS:
        offset = round(time_offset_s * 1e9)
    frames = []
    for i in ids:
        color = np.asarray(Image.open(run / f"{i}_color.png").convert("RGB"), dtype=np.uint8)
        depth = tifffile.imread(run / f"{i}_depth.tiff").astype(np.float32)
        pose = np.loadtxt(run / f"{i}_pose.txt", dtype=np.float64).reshape(4, 4)
        labels = segments = gt = None
        if (run / f"{i}_predicted.png").is_file():
            labels = channel0(np.asarray(Image.open(run / f"{i}_predicted.png")))
            lj = run / f"{i}_labels.json"
            segments = json.loads(lj.read_text()) if lj.is_file() else []
        if (run / f"{i}_segmentation.png").is_file():
            gt = channel0(np.asarray(Image.open(run / f"{i}_segmentation.png")))
        frames.append(Frame(i, stamps[i] + offset, color, depth, pose, labels, segments, gt))
    for a, b in zip(frames, frames[1:]):
        if b.t_ns <= a.t_ns:
            sys.exit(f"frames {a.id} and {b.id} have non-increasing stamps")
    return frames


# ---------------------------------------------------------------------------------------------
# Pixel encodings


def encode_color(rgb: np.ndarray, encoding: str) -> tuple[np.ndarray, int]:
    """(bytes as uint8 array, step) for a colour encoding."""
    h, w, _ = rgb.shape
    if encoding == "rgb8":
        out = rgb
    elif encoding == "bgr8":
        out = rgb[..., ::-1]
    elif encoding == "rgba8":
        out = np.dstack([rgb, np.full((h, w), 255, np.uint8)])
    elif encoding == "bgra8":
        out = np.dstack([rgb[..., ::-1], np.full((h, w), 255, np.uint8)])
    elif encoding == "mono8":
        out = grey(rgb)
    elif encoding == "yuv422":  # only for --malform unknown-encoding: 2 bytes a pixel
        out = np.zeros((h, w, 2), np.uint8)
    else:
        raise ValueError(encoding)
    out = np.ascontiguousarray(out)
    return out.reshape(-1).view(np.uint8), out.strides[0]


def grey(rgb: np.ndarray) -> np.ndarray:
    """ITU-R BT.601 luma, integer: (299 R + 587 G + 114 B + 500) / 1000."""
    r, g, b = (rgb[..., k].astype(np.uint32) for k in range(3))
    return ((299 * r + 587 * g + 114 * b + 500) // 1000).astype(np.uint8)


def valid_depth(d: np.ndarray) -> np.ndarray:
    return np.isfinite(d) & (d > 0)


def encode_depth(d: np.ndarray, encoding: str) -> tuple[np.ndarray, int]:
    if encoding == "32FC1":
        out = np.where(valid_depth(d), d, np.float32("nan")).astype("<f4")
    elif encoding == "16UC1":
        out = depth_to_mm(d).astype("<u2")
    else:
        raise ValueError(encoding)
    out = np.ascontiguousarray(out)
    return out.reshape(-1).view(np.uint8), out.strides[0]


def depth_to_mm(d: np.ndarray) -> np.ndarray:
    """Millimetres, 0 = no data: invalid depth and depth beyond 65.535 m become 0."""
    mm = np.zeros(d.shape, np.uint16)
    ok = valid_depth(d) & (d * 1000.0 < 65535.5)
    mm[ok] = np.rint(d[ok].astype(np.float64) * 1000.0).astype(np.uint16)
    return mm


def depth_as_carried(d: np.ndarray, encoding: str) -> np.ndarray:
    """The float32 metres a reader gets back from the bag (0 = no data)."""
    if encoding == "16UC1":
        return depth_to_mm(d).astype(np.float32) / np.float32(1000.0)
    return np.where(valid_depth(d), d, np.float32(0)).astype(np.float32)


def encode_labels(lab: np.ndarray, encoding: str) -> tuple[np.ndarray, int]:
    if encoding in ("16UC1", "mono16"):
        out = lab.astype("<u2")
    elif encoding in ("8UC1", "mono8"):
        if lab.max(initial=0) > 255:
            raise ValueError("label ids above 255 do not fit 8UC1")
        out = lab.astype(np.uint8)
    else:
        raise ValueError(encoding)
    out = np.ascontiguousarray(out)
    return out.reshape(-1).view(np.uint8), out.strides[0]


# ---------------------------------------------------------------------------------------------
# The message plan: format-neutral descriptions, turned into each typestore's classes later


@dataclass
class Msg:
    t_ns: int  # record time
    topic: str
    kind: str  # image, info, tf, tf_static, string, pose
    fields: dict = field(default_factory=dict)


TYPES = {
    "image": "sensor_msgs/msg/Image",
    "info": "sensor_msgs/msg/CameraInfo",
    "tf": "tf2_msgs/msg/TFMessage",
    "tf_static": "tf2_msgs/msg/TFMessage",
    "string": "std_msgs/msg/String",
    "pose": "geometry_msgs/msg/PoseStamped",
}


def stamp_of(t_ns: int) -> tuple[int, int]:
    return t_ns // 10**9, t_ns % 10**9


def plan_messages(frames: list[Frame], k: Intrinsics, a) -> tuple[list[Msg], dict]:
    """All messages of one bag, and facts for the manifest."""
    msgs: list[Msg] = []
    facts: dict = {"malform": a.malform}
    if a.malform == "duplicate-stamp":
        frames = [dataclasses.replace(f) for f in frames]
        mid = len(frames) // 2
        frames[mid].t_ns = frames[mid - 1].t_ns
        facts["duplicate_stamp"] = {"frames": [frames[mid - 1].id, frames[mid].id],
                                    "stamp_ns": frames[mid].t_ns}
    off = round(a.color_offset_ms * 1e6)
    optical = a.optical_frame
    t_base_link = make_transform(*BASE_TO_LINK)
    t_link_optical = make_transform(*LINK_TO_OPTICAL)
    t_base_optical = t_base_link @ t_link_optical
    t_optical_base = invert(t_base_optical)

    # world -> base_link at each frame so that the chain gives the flat pose.
    world_base = [f.pose @ t_optical_base for f in frames]
    wb_q = [matrix_to_quat(m[:3, :3]) for m in world_base]
    wb_t = [m[:3, 3].copy() for m in world_base]

    # tf samples: every frame stamp, plus --tf-rate samples strictly between frames.
    samples: list[tuple[int, np.ndarray, np.ndarray]] = []
    for i, f in enumerate(frames):
        samples.append((f.t_ns, wb_t[i], wb_q[i]))
        if i + 1 < len(frames) and a.tf_rate > 0:
            t0, t1 = f.t_ns, frames[i + 1].t_ns
            step = round(1e9 / a.tf_rate)
            t = t0 + step
            while t < t1 - step // 4:
                s = (t - t0) / (t1 - t0)
                samples.append(
                    (t, (1 - s) * wb_t[i] + s * wb_t[i + 1], slerp(wb_q[i], wb_q[i + 1], s))
                )
                t += step

    if a.malform == "tf-gap":
        # A window around the middle, a third of the sequence but at least 0.6 s where the
        # sequence is that long, bounded by the frames on either side.
        t0, t1 = frames[0].t_ns, frames[-1].t_ns
        mid, half = (t0 + t1) // 2, max((t1 - t0) // 6, 300_000_000)
        lo = max([f.t_ns for f in frames[:-1] if f.t_ns <= mid - half] or [t0])
        hi = min([f.t_ns for f in frames[1:] if f.t_ns >= mid + half] or [t1])
        samples = [s for s in samples if not lo < s[0] < hi]
        hit = [f for f in frames if lo < f.t_ns < hi]
        facts["tf_gap"] = {
            "topic": "/tf",
            "parent": a.world_frame,
            "child": a.base_frame,
            "last_before_ns": lo,
            "first_after_ns": hi,
            "gap_s": (hi - lo) / 1e9,
            "frames_without_pose": [f.id for f in hit],
            "stamps_without_pose_ns": [f.t_ns for f in hit],
        }

    def tf_entry(t_ns, parent, child, trans, quat):
        return {"t_ns": t_ns, "parent": parent, "child": child,
                "translation": [float(v) for v in trans], "rotation": [float(v) for v in quat]}

    first = frames[0].t_ns
    if a.pose in ("tf", "both"):
        msgs.append(Msg(first, a.tf_static_topic, "tf_static", {"transforms": [
            tf_entry(first, a.base_frame, a.camera_link_frame, *BASE_TO_LINK),
            tf_entry(first, a.camera_link_frame, optical, *LINK_TO_OPTICAL),
        ]}))
        for t, tr, q in samples:
            msgs.append(Msg(t, a.tf_topic, "tf", {"transforms": [
                tf_entry(t, a.world_frame, a.base_frame, tr, q)]}))

    carried_poses = []
    for i, f in enumerate(frames):
        tc = f.t_ns + off
        # Pose as a reader composes it from the chain's messages.
        chain = make_transform(wb_t[i], wb_q[i]) @ t_base_link @ t_link_optical
        carried_poses.append(chain)
        enc = a.color_encoding
        if a.malform == "unknown-encoding" and i == min(1, len(frames) - 1):
            enc = "yuv422"
            facts["unknown_encoding"] = {"topic": a.color_topic, "frame": f.id,
                                         "stamp_ns": tc, "encoding": enc}
        data, step = encode_color(f.color, enc)
        h, w = f.color.shape[:2]
        msgs.append(Msg(tc, a.color_topic, "image", dict(
            t_ns=tc, frame_id=optical, height=h, width=w, encoding=enc, step=step, data=data)))
        data, step = encode_depth(f.depth, a.depth_encoding)
        msgs.append(Msg(f.t_ns, a.depth_topic, "image", dict(
            t_ns=f.t_ns, frame_id=optical, height=h, width=w, encoding=a.depth_encoding,
            step=step, data=data)))
        if a.malform != "missing-camera-info":
            msgs.append(Msg(tc, a.info_topic, "info",
                            dict(t_ns=tc, frame_id=optical, k=k, d=a.distortion)))
            msgs.append(Msg(f.t_ns, a.depth_info_topic, "info",
                            dict(t_ns=f.t_ns, frame_id=optical, k=k)))
        if f.labels is not None and not a.no_labels:
            data, step = encode_labels(f.labels, a.label_encoding)
            msgs.append(Msg(tc, a.labels_topic, "image", dict(
                t_ns=tc, frame_id=optical, height=h, width=w, encoding=a.label_encoding,
                step=step, data=data)))
            sec, nsec = stamp_of(tc)
            doc = {"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": optical},
                   "segments": f.segments}
            msgs.append(Msg(tc, a.segments_topic, "string",
                            {"data": json.dumps(doc, separators=(",", ":"))}))
        if f.gt is not None and a.with_gt:
            data, step = encode_labels(f.gt, "16UC1")
            msgs.append(Msg(tc, a.gt_topic, "image", dict(
                t_ns=tc, frame_id=optical, height=h, width=w, encoding="16UC1", step=step,
                data=data)))
        if a.pose in ("posestamped", "both"):
            q = matrix_to_quat(chain[:3, :3])
            msgs.append(Msg(f.t_ns, a.pose_topic, "pose", dict(
                t_ns=f.t_ns, frame_id=a.world_frame, position=chain[:3, 3], orientation=q)))
    if a.malform == "missing-camera-info":
        facts["missing_camera_info"] = {"topics": [a.info_topic, a.depth_info_topic]}

    msgs.sort(key=lambda m: (m.t_ns, m.topic))
    dev = max(float(np.abs(c - f.pose).max()) for c, f in zip(carried_poses, frames))
    facts["chain_vs_flat_pose_max_abs"] = dev
    facts["carried_poses"] = carried_poses
    return msgs, facts


# ---------------------------------------------------------------------------------------------
# Typestores and serialisation


def typestore(ros1: bool):
    if ros1:
        ts = get_typestore(Stores.ROS1_NOETIC)
        if "tf2_msgs/msg/TFMessage" not in ts.types:
            ts.register(get_types_from_msg(TFMESSAGE_MSG, "tf2_msgs/msg/TFMessage"))
        return ts
    return get_typestore(Stores.ROS2_JAZZY)


class Builder:
    """Turns a Msg into the typestore's message object and serialises it."""

    def __init__(self, ts, ros1: bool):
        self.ts, self.ros1 = ts, ros1
        self.seq: dict[str, int] = {}
        T = ts.types
        self.Time = T["builtin_interfaces/msg/Time"]
        self.Header = T["std_msgs/msg/Header"]
        self.Image = T["sensor_msgs/msg/Image"]
        self.Info = T["sensor_msgs/msg/CameraInfo"]
        self.Roi = T["sensor_msgs/msg/RegionOfInterest"]
        self.TF = T["tf2_msgs/msg/TFMessage"]
        self.TS = T["geometry_msgs/msg/TransformStamped"]
        self.Transform = T["geometry_msgs/msg/Transform"]
        self.Vec = T["geometry_msgs/msg/Vector3"]
        self.Quat = T["geometry_msgs/msg/Quaternion"]
        self.Point = T["geometry_msgs/msg/Point"]
        self.Pose = T["geometry_msgs/msg/Pose"]
        self.PoseStamped = T["geometry_msgs/msg/PoseStamped"]
        self.String = T["std_msgs/msg/String"]

    def header(self, topic: str, t_ns: int, frame_id: str):
        sec, nsec = stamp_of(t_ns)
        stamp = self.Time(sec=sec, nanosec=nsec)
        if self.ros1:
            seq = self.seq.get(topic, 0)
            self.seq[topic] = seq + 1
            return self.Header(seq=seq, stamp=stamp, frame_id=frame_id)
        return self.Header(stamp=stamp, frame_id=frame_id)

    def build(self, m: Msg):
        f = m.fields
        if m.kind == "image":
            return self.Image(header=self.header(m.topic, f["t_ns"], f["frame_id"]),
                              height=f["height"], width=f["width"], encoding=f["encoding"],
                              is_bigendian=0, step=f["step"], data=f["data"])
        if m.kind == "info":
            k: Intrinsics = f["k"]
            kk = np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], np.float64)
            rr = np.eye(3).reshape(-1)
            pp = np.array([k.fx, 0, k.cx, 0, 0, k.fy, k.cy, 0, 0, 0, 1, 0], np.float64)
            dd = np.zeros(5, np.float64)
            dd[:len(f.get("d") or [])] = f.get("d") or []
            roi = self.Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
            common = dict(header=self.header(m.topic, f["t_ns"], f["frame_id"]),
                          height=k.height, width=k.width, distortion_model="plumb_bob",
                          binning_x=0, binning_y=0, roi=roi)
            if self.ros1:
                return self.Info(**common, D=dd, K=kk, R=rr, P=pp)
            return self.Info(**common, d=dd, k=kk, r=rr, p=pp)
        if m.kind in ("tf", "tf_static"):
            out = []
            for e in f["transforms"]:
                tr, q = e["translation"], e["rotation"]
                out.append(self.TS(
                    header=self.header(m.topic, e["t_ns"], e["parent"]),
                    child_frame_id=e["child"],
                    transform=self.Transform(
                        translation=self.Vec(x=tr[0], y=tr[1], z=tr[2]),
                        rotation=self.Quat(x=q[0], y=q[1], z=q[2], w=q[3]))))
            return self.TF(transforms=out)
        if m.kind == "string":
            return self.String(data=f["data"])
        if m.kind == "pose":
            p, q = f["position"], f["orientation"]
            return self.PoseStamped(
                header=self.header(m.topic, f["t_ns"], f["frame_id"]),
                pose=self.Pose(position=self.Point(x=p[0], y=p[1], z=p[2]),
                               orientation=self.Quat(x=q[0], y=q[1], z=q[2], w=q[3])))
        raise ValueError(m.kind)

    def serialize(self, m: Msg) -> bytes:
        obj = self.build(m)
        if self.ros1:
            return bytes(self.ts.serialize_ros1(obj, TYPES[m.kind]))
        return bytes(self.ts.serialize_cdr(obj, TYPES[m.kind]))


def qos(transient_local: bool) -> Qos:
    zero = QosTime(0, 0)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1 if transient_local else 10,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=zero, lifespan=zero, liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero, avoid_ros_namespace_conventions=False,
    )


def roslz4_compress(data: bytes) -> bytes:
    """An LZ4 frame laid out as ROS 1's roslz4 writes and reads it: independent blocks, no
    content size, a content checksum. roslz4 (Debian python3-roslz4, and rosbag's C++ reader)
    rejects other layouts, including the frame PyPI rosbags writes by default (linked blocks,
    a content size, no content checksum): "malformed data to decompress"."""
    return lz4.frame.compress(data, 0, block_size=lz4.frame.BLOCKSIZE_MAX1MB,
                              block_linked=False, content_checksum=True, store_size=False)


def write_ros1(path: Path, msgs: list[Msg], compression: str | None,
               lz4_layout: str = "roslz4") -> None:
    ts = typestore(True)
    b = Builder(ts, True)
    w = Ros1Writer(path)
    if compression:
        w.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
        if compression == "lz4" and lz4_layout == "roslz4":
            w.compressor = roslz4_compress
    with w:
        conns = {}
        for m in msgs:
            if m.topic not in conns:
                conns[m.topic] = w.add_connection(
                    m.topic, TYPES[m.kind], typestore=ts, callerid="/make_test_bags",
                    latching=1 if m.kind == "tf_static" else None)
            w.write(conns[m.topic], m.t_ns, b.serialize(m))


def write_ros2(path: Path, msgs: list[Msg], plugin: str, zstd: bool, version: int) -> Path:
    ts = typestore(False)
    b = Builder(ts, False)
    w = Ros2Writer(path, version=version,
                   storage_plugin=StoragePlugin.MCAP if plugin == "mcap" else StoragePlugin.SQLITE3)
    if zstd:
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with w:
        conns = {}
        for m in msgs:
            if m.topic not in conns:
                conns[m.topic] = w.add_connection(
                    m.topic, TYPES[m.kind], typestore=ts,
                    offered_qos_profiles=[qos(m.kind == "tf_static")])
            w.write(conns[m.topic], m.t_ns, b.serialize(m))
    files = sorted(path.glob(f"*.{plugin}"))
    assert len(files) == 1, files
    return files[0]


def truncate(path: Path, fraction: float = 0.6) -> dict:
    size = path.stat().st_size
    cut = int(size * fraction)
    with path.open("r+b") as f:
        f.truncate(cut)
    return {"file": path.name, "original_size": size, "truncated_to": cut}


# ---------------------------------------------------------------------------------------------
# Verification


def ros1_check(path: Path) -> dict:
    """Debian's rosbag + genpy (system python3) decode every message: an independent reader."""
    info = subprocess.run(["rosbag", "info", str(path)], capture_output=True, text=True)
    out = subprocess.run(["/usr/bin/python3", str(HERE / "check_ros1_bag.py"), str(path)],
                         capture_output=True, text=True)
    if out.returncode != 0:
        return {"ok": False, "rosbag_info_rc": info.returncode,
                "error": (out.stderr or out.stdout).strip().splitlines()[-1:]}
    res = json.loads(out.stdout)
    res["rosbag_info_rc"] = info.returncode
    res["rosbag_info"] = info.stdout
    return res


def ros2_mcap_check(path: Path) -> dict:
    """PyPI mcap + mcap-ros2-support (its own CDR decoder, from the schemas in the file)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    counts: dict[str, int] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            check_decoded(channel.topic, schema.name, decoded, message.log_time)
    return {"ok": True, "counts": counts}


def ros2_db3_check(path: Path) -> dict:
    """sqlite3 + mcap-ros2-support's dynamic CDR decoder fed the definitions the .db3 stores."""
    from mcap_ros2._dynamic import generate_dynamic

    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    defs = {t: (e, d) for t, e, d in con.execute(
        "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions")}
    topics = {i: (n, t) for i, n, t in con.execute("SELECT id, name, type FROM topics")}
    decoders = {}
    for tid, (name, typ) in topics.items():
        enc, text = defs[typ]
        assert enc == "ros2msg", enc
        decoders[tid] = generate_dynamic(typ, text)[typ]
    counts: dict[str, int] = {}
    for tid, t, data in con.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp"):
        name, typ = topics[tid]
        counts[name] = counts.get(name, 0) + 1
        check_decoded(name, typ, decoders[tid](data), t)
    con.close()
    return {"ok": True, "counts": counts}


def check_decoded(topic: str, typ: str, msg, t_ns: int) -> None:
    """Record time == header stamp; image sizes consistent."""
    if typ.endswith("Image"):
        st = msg.header.stamp
        assert st.sec * 10**9 + st.nanosec == t_ns, (topic, t_ns)
        assert len(msg.data) == msg.step * msg.height, topic


def summarise(path: Path) -> dict:
    """What `voxpan info` should print, computed with rosbags' reader."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as r:
        out = {"duration_s": (r.end_time - r.start_time) / 1e9, "start_ns": r.start_time,
               "end_ns": r.end_time, "topics": {}}
        stamps: dict[str, list[int]] = {}
        for c, t, _ in r.messages():
            stamps.setdefault(c.topic, []).append(t)
        for c in r.connections:
            s = stamps.get(c.topic, [])
            rate = (len(s) - 1) / ((s[-1] - s[0]) / 1e9) if len(s) > 1 and s[-1] > s[0] else None
            out["topics"][c.topic] = {"type": c.msgtype, "count": len(s), "rate_hz": rate}
    return out


def print_summary(name: str, s: dict) -> None:
    print(f"  {name}: {s['duration_s']:.3f} s, {sum(t['count'] for t in s['topics'].values())} messages")
    for topic, t in sorted(s["topics"].items()):
        rate = f"{t['rate_hz']:.2f} Hz" if t["rate_hz"] else "-"
        print(f"    {topic:45s} {t['type']:32s} {t['count']:6d}  {rate}")


# ---------------------------------------------------------------------------------------------


def export_flat(dest: Path, root: Path, frames: list[Frame], k: Intrinsics, facts: dict, a) -> None:
    run = dest / "run1"
    run.mkdir(parents=True, exist_ok=True)
    for name in ("Intrinsics.txt", "detectron_labels.csv", "groundtruth_labels.csv",
                 "groundtruth_labels_classes.csv", "infrared_corrections.csv"):
        if (root / name).is_file():
            shutil.copy(root / name, dest / name)
    lines = ["ImageID,TimeStamp"]
    for f, pose in zip(frames, facts["carried_poses"]):
        color = f.color
        if a.color_encoding == "mono8":
            g = grey(f.color)
            color = np.dstack([g, g, g])
        Image.fromarray(color).save(run / f"{f.id}_color.png")
        tifffile.imwrite(run / f"{f.id}_depth.tiff", depth_as_carried(f.depth, a.depth_encoding))
        (run / f"{f.id}_pose.txt").write_text(
            "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in pose))
        if f.labels is not None and not a.no_labels:
            Image.fromarray(f.labels).save(run / f"{f.id}_predicted.png")
            (run / f"{f.id}_labels.json").write_text(json.dumps(f.segments))
        if f.gt is not None:
            Image.fromarray(f.gt).save(run / f"{f.id}_segmentation.png")
        lines.append(f"{f.id},{f.t_ns}")
    (run / "timestamps.csv").write_text("\n".join(lines) + "\n")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("src", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--name")
    p.add_argument("--frames", type=int, help="use the first N frames (by stamp)")
    p.add_argument("--formats", default=",".join(FORMATS),
                   help=f"comma-separated subset of {','.join(FORMATS)}")
    p.add_argument("--color-encoding", default="rgb8",
                   choices=["rgb8", "bgr8", "rgba8", "bgra8", "mono8"])
    p.add_argument("--depth-encoding", default="16UC1", choices=["16UC1", "32FC1"])
    p.add_argument("--label-encoding", default="16UC1", choices=["16UC1", "mono16", "8UC1", "mono8"])
    p.add_argument("--pose", default="tf", choices=["tf", "posestamped", "both"])
    p.add_argument("--tf-rate", type=float, default=30.0,
                   help="extra /tf samples per second between frames (0: only at frames)")
    p.add_argument("--color-offset-ms", type=float, default=3.0)
    p.add_argument("--time-offset-s", type=float, default=1_700_000_000.0,
                   help="added to relative (synthetic) stamps")
    p.add_argument("--no-labels", action="store_true")
    p.add_argument("--distortion", type=float, nargs="+", metavar="D",
                   help="plumb_bob coefficients of the colour camera_info (k1 k2 p1 p2 k3; "
                        "default all 0: rectified)")
    p.add_argument("--with-gt", action="store_true", help="also the ground-truth label image")
    p.add_argument("--malform", choices=MALFORMS)
    p.add_argument("--lz4-layout", default="roslz4", choices=["roslz4", "rosbags"],
                   help="LZ4 frame layout of ros1-lz4 chunks: as ROS 1 writes them (default), "
                   "or rosbags' default, which ROS 1's own reader rejects")
    p.add_argument("--mcap-zstd", action="store_true", help="zstd-compressed MCAP chunks")
    p.add_argument("--ros2-version", type=int, default=9, choices=[8, 9],
                   help="rosbag2 metadata version (8 Iron, 9 Jazzy)")
    p.add_argument("--export-flat", type=Path, help="write the frames as carried, flat layout")
    p.add_argument("--no-verify", action="store_true")
    p.add_argument("--force", action="store_true", help="replace existing outputs")
    g = p.add_argument_group("topics and frames")
    g.add_argument("--color-topic", default="/camera/color/image_raw")
    g.add_argument("--info-topic", default="/camera/color/camera_info")
    g.add_argument("--depth-topic", default="/camera/aligned_depth_to_color/image_raw")
    g.add_argument("--depth-info-topic", default="/camera/aligned_depth_to_color/camera_info")
    g.add_argument("--labels-topic", default="/camera/segments/image")
    g.add_argument("--segments-topic", default="/camera/segments/labels")
    g.add_argument("--gt-topic", default="/camera/ground_truth/image")
    g.add_argument("--pose-topic", default="/camera/pose")
    g.add_argument("--tf-topic", default="/tf")
    g.add_argument("--tf-static-topic", default="/tf_static")
    g.add_argument("--world-frame", default="world")
    g.add_argument("--base-frame", default="base_link")
    g.add_argument("--camera-link-frame", default="camera_link")
    g.add_argument("--optical-frame", default="camera_color_optical_frame")
    a = p.parse_args()

    formats = [f for f in a.formats.split(",") if f]
    for f in formats:
        if f not in FORMATS:
            p.error(f"unknown format {f}")
    root, run = locate(a.src)
    k = read_intrinsics(root / "Intrinsics.txt")
    frames = load_frames(run, a.frames, a.time_offset_s)
    h, w = frames[0].color.shape[:2]
    if (w, h) != (k.width, k.height):
        sys.exit(f"images are {w}x{h} but Intrinsics.txt says {k.width}x{k.height}")
    name = a.name or ("flat" if root.name == "flat" else root.name)
    if a.malform:
        name = f"{name}-{a.malform}"
    a.out.mkdir(parents=True, exist_ok=True)

    msgs, facts = plan_messages(frames, k, a)
    print(f"{len(frames)} frames {w}x{h} from {run}, {len(msgs)} messages; chain vs flat pose "
          f"max |diff| {facts['chain_vs_flat_pose_max_abs']:.2e}")

    outputs = {}
    for fmt in formats:
        if fmt.startswith("ros1"):
            comp = fmt[5:] or None
            path = a.out / (f"{name}-{comp}.bag" if comp else f"{name}.bag")
            target = path
        else:
            path = a.out / f"{name}-{fmt}"
        if path.exists():
            if not a.force:
                sys.exit(f"{path} exists (use --force)")
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        if fmt.startswith("ros1"):
            write_ros1(path, msgs, comp, a.lz4_layout)
        else:
            target = write_ros2(path, msgs, fmt, a.mcap_zstd and fmt == "mcap", a.ros2_version)
        entry = {"format": fmt, "path": str(path), "file": str(target),
                 "size": target.stat().st_size}
        if a.malform == "truncated":
            entry["truncated"] = truncate(target)
        outputs[fmt] = entry

    expected_counts: dict[str, int] = {}
    for m in msgs:
        expected_counts[m.topic] = expected_counts.get(m.topic, 0) + 1
    ok = True
    if not a.no_verify:
        print("verify:")
        for fmt, e in outputs.items():
            path, target = Path(e["path"]), Path(e["file"])
            try:
                if fmt.startswith("ros1"):
                    r = ros1_check(path)
                elif fmt == "mcap":
                    r = ros2_mcap_check(target)
                else:
                    r = ros2_db3_check(target)
            except Exception as err:  # noqa: BLE001 - reported, judged below
                r = {"ok": False, "error": f"{type(err).__name__}: {err}"}
            if a.malform == "truncated":
                good = not r.get("ok")
                what = f"unreadable as expected ({r.get('error')})" if good else "READ FINE?!"
            else:
                good = r.get("ok") and r.get("counts") == expected_counts
                what = "counts match" if good else f"MISMATCH {r}"
                if good and fmt.startswith("ros1"):
                    good = r["rosbag_info_rc"] == 0 and r.get("md5_ok", False)
                    what += ", rosbag info ok, md5sums = Debian's" if good else f" but {r}"
            e["verify"] = {k2: v for k2, v in r.items() if k2 != "rosbag_info"}
            print(f"  {fmt:9s} {'ok ' if good else 'BAD'} {what}")
            ok &= bool(good)
            if a.malform != "truncated":
                s = summarise(path)
                e["summary"] = s
                print_summary(path.name, s)

    facts.pop("carried_poses_unused", None)
    poses = facts.pop("carried_poses")
    if a.export_flat:
        export_flat(a.export_flat, root, frames, k, {"carried_poses": poses}, a)
        print(f"exported the frames as carried to {a.export_flat}")
    manifest = {
        "source": str(run), "name": name, "frames": len(frames), "width": w, "height": h,
        "intrinsics": vars(k),
        "options": {kk: (str(v) if isinstance(v, Path) else v) for kk, v in vars(a).items()},
        "frame_ids": [f.id for f in frames],
        "depth_stamps_ns": [f.t_ns for f in frames],
        "color_stamps_ns": [f.t_ns + round(a.color_offset_ms * 1e6) for f in frames],
        "expected_counts": expected_counts,
        "tf_chain": [a.world_frame, a.base_frame, a.camera_link_frame, a.optical_frame],
        "static_transforms": {
            f"{a.base_frame}->{a.camera_link_frame}": [list(BASE_TO_LINK[0]), list(map(float, BASE_TO_LINK[1]))],
            f"{a.camera_link_frame}->{a.optical_frame}": [list(LINK_TO_OPTICAL[0]), list(map(float, LINK_TO_OPTICAL[1]))],
        },
        "poses_T_world_optical": [[list(map(float, r)) for r in m] for m in poses],
        "facts": facts,
        "outputs": outputs,
    }
    (a.out / f"{name}.manifest.json").write_text(json.dumps(manifest, indent=1))
    print(f"wrote {a.out / (name + '.manifest.json')}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
