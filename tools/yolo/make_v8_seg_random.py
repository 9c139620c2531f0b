#!/usr/bin/env python3
"""Write two tiny, seeded, random-weight YOLO segmentation models for tests.

    make_v8_seg_random.py [--out-dir target/models] [--seed 0]

  tiny-yolov8-seg-random.onnx  ultralytics YOLOv8/YOLO11-seg layout:
      output0 [1, 4+C+32, N]  cx, cy, w, h (input px), C sigmoided scores, 32 raw coefs
      output1 [1, 32, H/4, W/4]
      no `layout` metadata key, like real ultralytics exports.
  tiny-yolov5-seg-random.onnx  YOLOv5-seg layout (same as convert_yolov5_seg.py):
      output0 [1, N, 5+C+32], output1 [1, 32, H/4, W/4], `layout`=`yolov5-seg`.

Both have a non-square input (H != W) and a class count other than 80 so a
consumer that swaps axes or hard-codes COCO fails. The weights are random
(no trained model is involved), so the files are free to redistribute; only
the shapes and the decode math are real: strides 8/16/32, grid offsets,
v8's distribution-focal box regression, v5's anchors.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import onnx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from convert_yolov5_seg import yolov5_seg_head  # noqa: E402
from onnxgraph import Graph, names_repr  # noqa: E402

H, W = 128, 160
STRIDES = (8, 16, 32)
NM = 32
REG_MAX = 16  # v8 DFL bins
# SiLU roughly halves a zero-mean signal; this gain keeps feature std near 1.
BACKBONE_GAIN = 1.6
V8_NAMES = {0: "chair", 1: "couch", 2: "bed", 3: "dining table", 4: "tv"}
V5_NAMES = {0: "person", 1: "chair", 2: "refrigerator"}
# YOLOv5's COCO anchors (w, h in pixels per stride level) scaled by 1/4 for the
# small input, so random boxes stay about image-sized.
V5_ANCHORS = (np.array([[10, 13, 16, 30, 33, 23], [30, 61, 62, 45, 59, 119],
                        [116, 90, 156, 198, 373, 326]], np.float64) / 4).tolist()


class Rand:
    def __init__(self, seed):
        self.rng = np.random.default_rng(seed)

    def conv(self, cout, cin, k, gain=1.0):
        # He-style scale keeps activations O(1) through the stack, so outputs
        # neither saturate nor vanish and tolerance checks stay meaningful.
        std = gain * np.sqrt(2.0 / (cin * k * k))
        w = self.rng.normal(0, std, (cout, cin, k, k)).astype(np.float32)
        b = self.rng.normal(0, 0.1, cout).astype(np.float32)
        return w, b


def backbone(g, r):
    """Strided 3x3 convs + SiLU; returns the stride-8/16/32 feature maps."""
    x, c, feats = "images", 3, []
    for i, cout in enumerate((8, 16, 16, 16, 16)):
        w, b = r.conv(cout, c, 3, gain=BACKBONE_GAIN)
        x = g.silu(g.conv(x, w, b, f"backbone.{i}", stride=2), f"backbone.{i}")
        c = cout
        if i >= 2:
            feats.append(x)
    return feats, c


def proto(g, r, x, c, upsample):
    w, b = r.conv(c, c, 3)
    x = g.silu(g.conv(x, w, b, "proto.cv1"), "proto.cv1")
    x = upsample(x)
    w, b = r.conv(c, c, 3)
    x = g.silu(g.conv(x, w, b, "proto.cv2"), "proto.cv2")
    w, b = r.conv(NM, c, 1)
    x = g.silu(g.conv(x, w, b, "proto.cv3"), "proto.cv3")
    return g.op("Identity", [x], "output1")


def meta(names, extra):
    d = {
        "description": "voxpan test model: random weights, real YOLO-seg output layout",
        "names": names_repr(names),
        "stride": str(max(STRIDES)),
        "imgsz": json.dumps([H, W]),
        "task": "segment",
        "batch": "1",
    }
    d.update(extra)
    return d


def make_v8(seed):
    r, g = Rand(seed), Graph()
    nc = len(V8_NAMES)
    feats, c = backbone(g, r)
    boxes, scores, coefs, a_ctr, a_str = [], [], [], [], []
    for i, (x, s) in enumerate(zip(feats, STRIDES)):
        ny, nx = H // s, W // s
        n = ny * nx
        w, b = r.conv(4 * REG_MAX, c, 1)
        # Favour low bins so boxes span a few cells, not the whole image.
        b += np.tile(-0.5 * np.arange(REG_MAX, dtype=np.float32), 4)
        boxes.append(g.reshape(g.conv(x, w, b, f"head.{i}.box"), [1, 4 * REG_MAX, n], f"head.{i}.box.flat"))
        w, b = r.conv(nc, c, 1)
        b -= 2.5  # most cells below the 0.25 threshold, a few above: like a real scene
        scores.append(g.reshape(g.conv(x, w, b, f"head.{i}.cls"), [1, nc, n], f"head.{i}.cls.flat"))
        w, b = r.conv(NM, c, 1)
        coefs.append(g.reshape(g.conv(x, w, b, f"head.{i}.coef"), [1, NM, n], f"head.{i}.coef.flat"))
        gy, gx = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        a_ctr.append(np.stack([gx.ravel(), gy.ravel()]) + 0.5)  # cell centres, grid units
        a_str.append(np.full((1, n), float(s)))
    box = g.concat(boxes, "head.box", axis=2)  # [1, 64, N]
    n_all = sum((H // s) * (W // s) for s in STRIDES)
    # DFL: softmax over REG_MAX bins per side, expectation via a fixed 1x1 conv.
    box = g.reshape(box, [1, 4, REG_MAX, n_all], "dfl.view")
    box = g.op("Transpose", [box], "dfl.perm", perm=[0, 2, 1, 3])  # [1, 16, 4, N]
    box = g.op("Softmax", [box], "dfl.softmax", axis=1)
    bins = np.arange(REG_MAX, dtype=np.float32).reshape(1, REG_MAX, 1, 1)
    dist = g.reshape(g.conv(box, bins, None, "dfl.conv"), [1, 4, n_all], "dfl.dist")  # l, t, r, b
    lt = g.slice(dist, 0, 2, 1, "dist.lt")
    rb = g.slice(dist, 2, 4, 1, "dist.rb")
    ctr = g.const("anchors", np.concatenate(a_ctr, 1)[None].astype(np.float32))  # [1, 2, N]
    half = g.const("half", np.array(0.5, np.float32))
    # centre = anchor + (rb - lt) / 2, size = lt + rb; then grid units -> pixels.
    cxy = g.op("Add", [ctr, g.op("Mul", [g.op("Sub", [rb, lt], "box.d"), half], "box.d2")], "box.cxy")
    wh = g.op("Add", [lt, rb], "box.wh")
    stride = g.const("strides", np.concatenate(a_str, 1)[None].astype(np.float32))  # [1, 1, N]
    xywh = g.op("Mul", [g.concat([cxy, wh], "box.xywh.grid"), stride], "box.xywh")
    cls = g.op("Sigmoid", [g.concat(scores, "head.cls", axis=2)], "head.cls.sigmoid")
    g.concat([xywh, cls, g.concat(coefs, "head.coef", axis=2)], "output0", axis=1)
    up_w, up_b = r.conv(c, c, 2)  # ConvTranspose weight is [Cin, Cout, k, k]; Cin == Cout here
    proto(g, r, feats[0], c, lambda x: g.op(
        "ConvTranspose",  # ultralytics' Proto upsamples with a learned 2x2/2 deconvolution
        [x, g.const("proto.up.weight", up_w), g.const("proto.up.bias", up_b)],
        "proto.up", kernel_shape=[2, 2], strides=[2, 2]))
    return g.model(
        [("images", [1, 3, H, W])],
        [("output0", [1, 4 + nc + NM, n_all]), ("output1", [1, NM, H // 4, W // 4])],
        meta(V8_NAMES, {}),
    )


def make_v5(seed):
    r, g = Rand(seed), Graph()
    nc = len(V5_NAMES)
    na = len(V5_ANCHORS[0]) // 2
    feats, c = backbone(g, r)
    maps = []
    for i, x in enumerate(feats):
        w, b = r.conv(na * (5 + nc + NM), c, 1)
        b = b.reshape(na, 5 + nc + NM)
        b[:, 4] -= 2.0  # objectness mostly low, as in a real scene
        maps.append(g.conv(x, w, b.ravel(), f"head.{i}"))
    anchors = np.array(V5_ANCHORS, np.float64).reshape(len(STRIDES), na, 2)
    shape0 = yolov5_seg_head(g, maps, np.array(STRIDES, np.float64), anchors, nc, NM, H, W, "head")
    proto(g, r, feats[0], c, lambda x: g.upsample2x_nearest(x, "proto.up"))
    return g.model(
        [("images", [1, 3, H, W])],
        [("output0", list(shape0)), ("output1", [1, NM, H // 4, W // 4])],
        meta(V5_NAMES, {"layout": "yolov5-seg", "anchors": json.dumps(anchors.tolist())}),
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out-dir", default=str(Path(__file__).resolve().parents[2] / "target" / "models"))
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    out = Path(a.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, make in (("tiny-yolov8-seg-random.onnx", make_v8), ("tiny-yolov5-seg-random.onnx", make_v5)):
        p = out / name
        onnx.save(make(a.seed), p)
        print(f"wrote {p} ({p.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
