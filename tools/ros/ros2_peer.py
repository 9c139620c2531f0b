#!/usr/bin/env python3
"""A ROS 2 peer on rmw_zenoh's wire format, written independently of voxpan (PyPI
eclipse-zenoh for the transport, rosbags for type hashes and CDR, xxhash for publisher ids),
for voxpan's live ROS 2 tests and benchmark. There is no rclpy here; this plays the parts a
ROS 2 system plays around voxpan's nodes:

- the router (rmw_zenohd's role): a zenoh session in router mode listening on --listen; or,
  with --connect instead, no router: only a peer of the router at that endpoint;
- `ros2 bag play`: a peer node that declares its node and publisher liveliness tokens and puts
  every message of a ROS 2 bag (.mcap or .db3 folder) on the topic's data key with the
  33-byte attachment (sequence, timestamp, publisher id), in the bag's timing scaled by --rate;
  it starts only when voxpan's subscriptions for --wait-for are visible in the ROS graph (their
  liveliness tokens), as a lazy ROS 2 publisher would;
- `ros2 topic echo`: subscribes each --echo TOPIC=TYPE, checks every sample's attachment and
  decodes it with rosbags' CDR deserializer;
- `ros2 node list` / `topic list`: records every liveliness token and checks it parses by
  rmw_zenoh's rules.

- anyone on the network: with --garbage K, K bad samples on every data key a voxpan node
  subscribes to (from its liveliness tokens): without an attachment, with a garbage one, and
  with a valid attachment around a CDR body whose first lengths claim more than it holds;
  prints `garbage NODE TOPIC K` for each, and (without --bag) exits after them.

Runs until SIGINT or SIGTERM, then writes --report (JSON). Prints "played N messages in S s"
when the bag is done, and "echoed TOPIC N" as each echoed sample arrives.

  ros2_peer.py --listen tcp/127.0.0.1:7447 --bag BAGDIR --rate 0.25 \\
      --wait-for /camera/color/image_raw,/tf --echo /voxpan/depth=sensor_msgs/msg/Image \\
      --report peer.json
"""
from __future__ import annotations

import argparse
import json
import re
import os
import signal
import sys
import threading
import time
from pathlib import Path

import xxhash
import zenoh
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from zenoh.ext import Int64, z_deserialize, z_serialize

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def dds_name(msgtype: str) -> str:
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def data_key(domain: int, topic: str, msgtype: str) -> str:
    return f"{domain}/{topic.strip('/')}/{dds_name(msgtype)}/{TYPESTORE.hash_rihs01(msgtype)}"


def mangle(name: str) -> str:
    return name.replace("/", "%")


def parse_token(key: str) -> dict:
    """rmw_zenoh's liveliness_utils.cpp rules: admin space @ros2_lv, at least 9 parts for a
    node and 13 for a publisher or subscription, none empty."""
    parts = key.split("/")
    if parts[0] != "@ros2_lv" or len(parts) < 9 or any(p == "" for p in parts):
        raise ValueError(f"not an rmw_zenoh token: {key}")
    token = {
        "domain": int(parts[1]),
        "zid": parts[2],
        "node_id": int(parts[3]),
        "id": int(parts[4]),
        "kind": parts[5],
        "enclave": parts[6].replace("%", "/"),
        "namespace": parts[7].replace("%", "/"),
        "node": parts[8],
    }
    if token["kind"] in ("MP", "MS", "SS", "SC"):
        if len(parts) < 13:
            raise ValueError(f"endpoint token with {len(parts)} parts: {key}")
        token.update(
            topic=parts[9].replace("%", "/"),
            type=parts[10],
            hash=parts[11],
            qos=parts[12],
        )
    elif token["kind"] != "NN":
        raise ValueError(f"unknown entity kind {token['kind']}: {key}")
    return token


def summary(msgtype: str, msg) -> dict:
    if msgtype == "sensor_msgs/msg/Image":
        return {
            "encoding": msg.encoding,
            "width": int(msg.width),
            "height": int(msg.height),
            "stamp_ns": int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec),
            "frame_id": msg.header.frame_id,
        }
    if msgtype == "std_msgs/msg/String":
        return {"data": msg.data[:400]}
    if msgtype == "visualization_msgs/msg/MarkerArray":
        return {
            "markers": len(msg.markers),
            "points": sum(len(m.points) for m in msg.markers),
            "types": sorted({int(m.type) for m in msg.markers}),
        }
    if msgtype == "sensor_msgs/msg/CameraInfo":
        return {"width": int(msg.width), "k": [float(v) for v in msg.k]}
    if msgtype == "geometry_msgs/msg/PoseStamped":
        p = msg.pose.position
        return {"frame_id": msg.header.frame_id, "position": [p.x, p.y, p.z]}
    if msgtype == "nav_msgs/msg/OccupancyGrid":
        data = [int(v) for v in msg.data]
        return {
            "width": int(msg.info.width),
            "height": int(msg.info.height),
            "resolution": float(msg.info.resolution),
            "cells": {str(v): data.count(v) for v in (-1, 0, 100)},
        }
    if msgtype == "sensor_msgs/msg/PointCloud2":
        return {
            "fields": [(f.name, int(f.offset), int(f.datatype)) for f in msg.fields],
            "width": int(msg.width),
            "point_step": int(msg.point_step),
            "bytes": len(msg.data),
        }
    return {}


class Echo:
    def __init__(self, topic: str, msgtype: str):
        self.topic, self.msgtype = topic, msgtype
        self.count = 0
        self.lost = 0
        self.errors: list[str] = []
        self.first: dict | None = None
        self.stamps: list[int] = []
        self.last_seq: dict[bytes, int] = {}
        self.lock = threading.Lock()

    def on_sample(self, sample) -> None:
        with self.lock:
            try:
                if sample.attachment is None:
                    raise ValueError("no attachment")
                raw = sample.attachment.to_bytes()
                if len(raw) != 33:
                    raise ValueError(f"attachment of {len(raw)} bytes, not 33")
                seq, stamp, gid = z_deserialize(tuple[Int64, Int64, bytes], sample.attachment)
                if len(gid) != 16:
                    raise ValueError(f"publisher id of {len(gid)} bytes")
                if abs(time.time_ns() - int(stamp)) > 60 * 10**9:
                    raise ValueError(f"attachment timestamp {int(stamp)} is not now")
                # rmw_zenoh counts a gap in a publisher's sequence as lost messages.
                previous = self.last_seq.get(gid, 0)
                if int(seq) <= previous:
                    raise ValueError(f"sequence {int(seq)} after {previous}")
                self.lost += int(seq) - previous - 1
                self.last_seq[gid] = int(seq)
                payload = sample.payload.to_bytes()
                self.count += 1
                print(f"echoed {self.topic} {self.count}", flush=True)
                # rosbags decodes in Python: a mesh update of tens of megabytes takes seconds,
                # which would hold zenoh's receiving thread. Those are decoded once.
                if self.first is not None and len(payload) > 1 << 20:
                    return
                msg = TYPESTORE.deserialize_cdr(payload, self.msgtype)
                if self.first is None:
                    self.first = summary(self.msgtype, msg)
                header = getattr(msg, "header", None)
                if header is not None:
                    self.stamps.append(int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec))
            except Exception as e:  # recorded, reported, and the test fails on it
                if len(self.errors) < 5:
                    self.errors.append(f"{type(e).__name__}: {e}")

    def report(self) -> dict:
        with self.lock:
            return {"type": self.msgtype, "count": self.count, "lost": self.lost, "errors": self.errors,
                    "first": self.first, "stamps": self.stamps}


def any_port(endpoint: str) -> str:
    """`tcp/HOST:PORT` -> `tcp/HOST:0`: a peer listens on its router's host, any port."""
    return re.sub(r":\d+$", ":0", endpoint)


def session(mode: str, listen: str | None = None, connect: str | None = None) -> zenoh.Session:
    """A router (listening) or a peer; a peer listens too, on the router's host, any port, as
    rmw_zenoh's nodes do (tcp/localhost:0): peers that found each other through the router
    connect directly, whichever side dials."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("scouting/multicast/enabled", "false")
    if listen:
        c.insert_json5("listen/endpoints", json.dumps([listen]))
    if connect:
        c.insert_json5("connect/endpoints", json.dumps([connect]))
    return zenoh.open(c)


def play(peer: zenoh.Session, bag: Path, rate: float, domain: int, stop: threading.Event) -> int:
    """Puts every message of the bag, as a ROS 2 node named rosbag2_player would."""
    zid = str(peer.zid())
    node = f"@ros2_lv/{domain}/{zid}/0/0/NN/%/%/rosbag2_player"
    keep = [peer.liveliness().declare_token(node)]
    publishers = {}
    with AnyReader([bag]) as reader:
        for i, conn in enumerate(reader.connections, start=1):
            t = conn.msgtype
            qos = ":1:2,:,:,:,," if conn.topic == "/tf_static" else "::2,:,:,:,,"
            token = (f"@ros2_lv/{domain}/{zid}/0/{i}/MP/%/%/rosbag2_player/{mangle(conn.topic)}/"
                     f"{dds_name(t)}/{TYPESTORE.hash_rihs01(t)}/{qos}")
            keep.append(peer.liveliness().declare_token(token))
            gid = xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")
            # Every message delivered (BLOCK, as rmw_zenoh for reliable keep-all): the test
            # compares maps.
            publisher = peer.declare_publisher(data_key(domain, conn.topic, t),
                                               congestion_control=zenoh.CongestionControl.BLOCK)
            publishers[conn.id] = [publisher, gid, 0]
        start, first = time.monotonic(), None
        played = 0
        for conn, stamp, raw in reader.messages():
            if stop.is_set():
                break
            first = stamp if first is None else first
            wait = start + (stamp - first) / 1e9 / rate - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            entry = publishers[conn.id]
            entry[2] += 1
            attachment = z_serialize((Int64(entry[2]), Int64(time.time_ns()), entry[1]))
            entry[0].put(bytes(raw), attachment=attachment)
            played += 1
    return played


def garbage(peer: zenoh.Session, tokens: list[dict], count: int) -> None:
    """Bad samples on every key a voxpan node subscribes to; each must be counted as bad."""
    import random
    zid = str(peer.zid())
    gid = xxhash.xxh3_128_intdigest(f"garbage {zid}".encode()).to_bytes(16, "little")
    seen = set()
    subscriptions = [t for t in tokens
                     if t["kind"] == "MS" and t["node"].startswith("voxpan") and not t.get("gone")]
    for t in sorted(subscriptions, key=lambda t: (t["node"], t["topic"])):
        if (t["node"], t["topic"]) in seen:
            continue
        seen.add((t["node"], t["topic"]))
        key = f"{t['domain']}/{t['topic'].strip('/')}/{t['type']}/{t['hash']}"
        rng = random.Random(key)
        for i in range(count):
            body = bytearray(rng.randbytes(rng.choice([16, 40, 300, 2000])))
            # A valid little-endian CDR header, then a header's frame_id length (or a
            # message's first string or sequence length) past the body.
            body[0:4] = b"\x00\x01\x00\x00"
            body[4:8] = body[12:16] = (0xFFFFFFF0).to_bytes(4, "little")
            if i % 3 == 0:
                peer.put(key, bytes(body), congestion_control=zenoh.CongestionControl.BLOCK)
            elif i % 3 == 1:
                peer.put(key, bytes(body), attachment=rng.randbytes(10),
                         congestion_control=zenoh.CongestionControl.BLOCK)
            else:
                attachment = z_serialize((Int64(i + 1), Int64(time.time_ns()), gid))
                peer.put(key, bytes(body), attachment=attachment,
                         congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.01)
        print(f"garbage {t['node']} {t['topic']} {count}", flush=True)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--listen", help="be the router, on this endpoint, e.g. tcp/127.0.0.1:7447")
    where.add_argument("--connect", help="be only a peer, of the router at this endpoint")
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--bag", type=Path, help="ROS 2 bag folder to play")
    p.add_argument("--rate", type=float, default=1.0)
    p.add_argument("--wait-for", default="",
                   help="comma-separated topics: wait until each has a subscription (then play --bag)")
    p.add_argument("--wait-timeout", type=float, default=60.0)
    p.add_argument("--echo", action="append", default=[], metavar="TOPIC=TYPE")
    p.add_argument("--report", type=Path, required=True)
    p.add_argument("--garbage", type=int, default=0, metavar="K",
                   help="K bad samples on every key a voxpan node subscribes to, after --wait-for")
    a = p.parse_args()

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    # The router, or (--connect) a peer that plays and watches without one: data then flows
    # between the peers directly, as between rmw_zenoh's nodes, and outlives the router.
    if a.listen:
        hub = session("router", listen=a.listen)
    else:
        hub = session("peer", listen=any_port(a.connect), connect=a.connect)
    tokens: dict[str, dict] = {}
    token_errors: list[str] = []
    lock = threading.Lock()

    def on_token(sample) -> None:
        key = str(sample.key_expr)
        with lock:
            if sample.kind == zenoh.SampleKind.PUT:
                try:
                    tokens[key] = parse_token(key)
                except ValueError as e:
                    token_errors.append(str(e))
            else:
                tokens.get(key, {})["gone"] = True

    keep = [hub.liveliness().declare_subscriber(f"@ros2_lv/{a.domain}/**", on_token, history=True)]
    echoes = []
    for spec in a.echo:
        topic, msgtype = spec.split("=", 1)
        e = Echo(topic, msgtype)
        echoes.append(e)
        keep.append(hub.declare_subscriber(data_key(a.domain, topic, msgtype), e.on_sample))
    print(f"router listening on {a.listen}" if a.listen else f"peer of {a.connect}", flush=True)

    played = None
    wanted = {t for t in a.wait_for.split(",") if t}
    if wanted:
        deadline = time.monotonic() + a.wait_timeout
        while not stop.is_set():
            with lock:
                seen = {t.get("topic") for t in tokens.values() if t["kind"] == "MS" and not t.get("gone")}
            if wanted <= seen:
                break
            if time.monotonic() > deadline:
                print(f"no subscription for {sorted(wanted - seen)} after {a.wait_timeout} s", file=sys.stderr)
                return 1
            time.sleep(0.05)
        print("subscriptions seen", flush=True)
    if a.garbage:
        # Every subscription's token and route in place (as before playing a bag).
        time.sleep(1.0)
        with lock:
            known = list(tokens.values())
        garbage(hub, known, a.garbage)
        time.sleep(1.0)
        if not a.bag:
            stop.set()
    if a.bag:
        # The subscriptions' routes reach the router with their tokens; a moment for the
        # nodes' peers to learn them too.
        time.sleep(0.5)
        if a.listen:
            peer = session("peer", listen=any_port(a.listen), connect=a.listen)
            keep.append(peer)
        else:
            peer = hub
        began = time.monotonic()
        played = play(peer, a.bag, a.rate, a.domain, stop)
        print(f"played {played} messages in {time.monotonic() - began:.3f} s", flush=True)

    while not stop.is_set():
        time.sleep(0.05)
    with lock:
        report = {
            "played": played,
            "tokens": list(tokens.values()),
            "token_errors": token_errors,
            "echo": {e.topic: e.report() for e in echoes},
        }
    a.report.write_text(json.dumps(report, indent=1))
    for k in keep[::-1]:
        if isinstance(k, zenoh.Session):
            k.close()
    hub.close()
    return 0


if __name__ == "__main__":
    try:
        code = main()
    except BaseException:
        import traceback
        traceback.print_exc()
        code = 1
    sys.stdout.flush()
    sys.stderr.flush()
    # zenoh's threads would keep a failed run alive.
    os._exit(code)
