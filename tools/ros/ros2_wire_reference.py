#!/usr/bin/env python3
"""ROS 2 / rmw_zenoh wire bytes from independent implementations, for voxpan-ros's tests.

Reads a JSON request on stdin and prints JSON:
- "hashes": RIHS01 type hashes computed by PyPI rosbags (Typestore.hash_rihs01, Jazzy store);
- "cdr": hex of each message serialized by rosbags' CDR serializer (with the encapsulation
  header), the message built from the request's plain values;
- "attachment": hex of zenoh's own serializer (eclipse-zenoh z_serialize) on
  (Int64 sequence, Int64 timestamp, 16 bytes), rmw_zenoh's attachment;
- "gids": XXH3-128 (PyPI xxhash) of each token, 16 bytes little endian.
"""
import json
import sys

import numpy as np
import xxhash
from rosbags.typesys import Stores, get_typestore
from zenoh.ext import Int64, z_serialize

ts = get_typestore(Stores.ROS2_JAZZY)
T = ts.types


def header(h):
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=h["sec"], nanosec=h["nanosec"]),
        frame_id=h["frame_id"])


def pose(p):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](*p["t"]),
        orientation=T["geometry_msgs/msg/Quaternion"](*p["q"]))


def color(c):
    return T["std_msgs/msg/ColorRGBA"](*[np.float32(x) for x in c])


def build(kind, v):
    if kind == "sensor_msgs/msg/Image":
        return T[kind](header=header(v["header"]), height=v["height"], width=v["width"],
                       encoding=v["encoding"], is_bigendian=v["is_bigendian"], step=v["step"],
                       data=np.array(v["data"], dtype=np.uint8))
    if kind == "sensor_msgs/msg/CameraInfo":
        f = np.float64
        return T[kind](header=header(v["header"]), height=v["height"], width=v["width"],
                       distortion_model=v["distortion_model"], d=np.array(v["d"], dtype=f),
                       k=np.array(v["k"], dtype=f), r=np.array(v["r"], dtype=f),
                       p=np.array(v["p"], dtype=f), binning_x=v["binning"][0],
                       binning_y=v["binning"][1],
                       roi=T["sensor_msgs/msg/RegionOfInterest"](*v["roi"]))
    if kind == "geometry_msgs/msg/PoseStamped":
        return T[kind](header=header(v["header"]), pose=pose(v["pose"]))
    if kind == "std_msgs/msg/String":
        return T[kind](data=v["data"])
    if kind == "visualization_msgs/msg/MarkerArray":
        markers = []
        for m in v["markers"]:
            empty_header = header({"sec": 0, "nanosec": 0, "frame_id": ""})
            markers.append(T["visualization_msgs/msg/Marker"](
                header=header(m["header"]), ns=m["ns"], id=m["id"], type=m["type"],
                action=m["action"], pose=pose(m["pose"]),
                scale=T["geometry_msgs/msg/Vector3"](*m["scale"]), color=color(m["color"]),
                lifetime=T["builtin_interfaces/msg/Duration"](
                    sec=m["lifetime"][0], nanosec=m["lifetime"][1]),
                frame_locked=m["frame_locked"],
                points=[T["geometry_msgs/msg/Point"](*p) for p in m["points"]],
                colors=[color(c) for c in m["colors"]],
                texture_resource="",
                texture=T["sensor_msgs/msg/CompressedImage"](
                    header=empty_header, format="", data=np.array([], dtype=np.uint8)),
                uv_coordinates=[], text=m["text"], mesh_resource=m["mesh_resource"],
                mesh_file=T["visualization_msgs/msg/MeshFile"](
                    filename="", data=np.array([], dtype=np.uint8)),
                mesh_use_embedded_materials=m["mesh_use_embedded_materials"]))
        return T[kind](markers=markers)
    if kind == "nav_msgs/msg/OccupancyGrid":
        info = T["nav_msgs/msg/MapMetaData"](
            map_load_time=T["builtin_interfaces/msg/Time"](
                sec=v["load_time"][0], nanosec=v["load_time"][1]),
            resolution=np.float32(v["resolution"]), width=v["width"], height=v["height"],
            origin=pose(v["origin"]))
        return T[kind](header=header(v["header"]), info=info,
                       data=np.array(v["data"], dtype=np.int8))
    if kind == "sensor_msgs/msg/PointCloud2":
        fields = [T["sensor_msgs/msg/PointField"](name=f["name"], offset=f["offset"],
                                                  datatype=f["datatype"], count=f["count"])
                  for f in v["fields"]]
        return T[kind](header=header(v["header"]), height=v["height"], width=v["width"],
                       fields=fields, is_bigendian=v["is_bigendian"],
                       point_step=v["point_step"], row_step=v["row_step"],
                       data=np.array(v["data"], dtype=np.uint8), is_dense=v["is_dense"])
    raise SystemExit(f"unknown type {kind}")


def main():
    req = json.load(sys.stdin)
    out = {"hashes": {t: ts.hash_rihs01(t) for t in req["types"]}}
    out["cdr"] = [bytes(ts.serialize_cdr(build(m["type"], m["value"]), m["type"])).hex()
                  for m in req["messages"]]
    a = req["attachment"]
    out["attachment"] = z_serialize(
        (Int64(a["sequence"]), Int64(a["timestamp_ns"]), bytes.fromhex(a["gid"]))).to_bytes().hex()
    out["gids"] = [xxhash.xxh3_128_intdigest(t.encode()).to_bytes(16, "little").hex()
                   for t in req["tokens"]]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
