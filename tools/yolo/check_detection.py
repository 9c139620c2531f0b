#!/usr/bin/env python3
"""Run a YOLO-seg ONNX model on dataset frames and print its detections.

    check_detection.py MODEL.onnx FRAME.png [FRAME.png ...] [--bench] [--overlay DIR]

Frames are letterboxed to the model's input size (gray 114), detections kept
at confidence 0.25 with class-aware NMS at IoU 0.45, boxes printed in original
image pixels. --bench times inference (median of 10) at 1 and 2 threads.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

sys.path.insert(0, str(Path(__file__).resolve().parent))
from yolo_common import decode, letterbox, masks, nms, parse_names, read_metadata, read_rgb  # noqa: E402


def session(path, threads):
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def bench(path, x, runs=10):
    for t in (1, 2):
        s = session(path, t)
        s.run(None, {"images": x})  # warm-up
        ms = []
        for _ in range(runs):
            t0 = time.perf_counter()
            s.run(None, {"images": x})
            ms.append((time.perf_counter() - t0) * 1e3)
        print(f"  {Path(path).name}: {t} thread(s): median {np.median(ms):.1f} ms "
              f"(min {min(ms):.1f}, max {max(ms):.1f}, {runs} runs)")


def overlay(img, boxes, ms, r, pad, out):
    from PIL import Image, ImageDraw

    H, W = ms.shape[1:] if len(ms) else (0, 0)
    vis = img.astype(np.float32).copy()
    rng = np.random.default_rng(0)
    left, top = pad
    h, w = img.shape[:2]
    ys = np.clip(((np.arange(h) + 0.5) * r + top).astype(int), 0, H - 1) if len(ms) else None
    xs = np.clip(((np.arange(w) + 0.5) * r + left).astype(int), 0, W - 1) if len(ms) else None
    for m in ms:
        sel = m[ys][:, xs]
        vis[sel] = 0.5 * vis[sel] + 0.5 * rng.integers(0, 255, 3)
    im = Image.fromarray(vis.astype(np.uint8))
    d = ImageDraw.Draw(im)
    for b, label in boxes:
        d.rectangle(list(b), outline=(255, 0, 0), width=2)
        d.text((b[0] + 3, b[1] + 2), label, fill=(255, 255, 0))
    im.save(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("frames", nargs="+")
    ap.add_argument("--conf", type=float, default=0.25)
    ap.add_argument("--iou", type=float, default=0.45)
    ap.add_argument("--bench", action="store_true")
    ap.add_argument("--overlay", help="write <frame>_det.png overlays into this folder")
    a = ap.parse_args()

    sess = session(a.model, 2)
    meta = read_metadata(sess)
    names = parse_names(meta["names"])
    _, _, H, W = sess.get_inputs()[0].shape
    print(f"model {a.model}: input {H}x{W}, layout {meta.get('layout', 'ultralytics')}, {len(names)} classes")
    for f in a.frames:
        img = read_rgb(f)
        x, r, (left, top) = letterbox(img, H, W)
        t0 = time.perf_counter()
        out0, out1 = sess.run(["output0", "output1"], {"images": x})
        dt = (time.perf_counter() - t0) * 1e3
        boxes, scores, classes, coefs = decode(out0, meta, a.conf)
        keep = nms(boxes, scores, classes, a.iou)
        boxes, scores, classes, coefs = boxes[keep], scores[keep], classes[keep], coefs[keep]
        ms = masks(coefs, out1[0], boxes, H, W)
        orig = (boxes - [left, top, left, top]) / r
        orig = np.clip(orig, 0, [img.shape[1], img.shape[0]] * 2)
        print(f"{Path(f).name}: {len(keep)} detections ({dt:.0f} ms)")
        for b, s, c, m in zip(orig, scores, classes, ms):
            area = (b[2] - b[0]) * (b[3] - b[1]) * r * r
            print(f"  {names[int(c)]:<14} {s:.3f}  box x1,y1,x2,y2 = "
                  f"{b[0]:6.1f} {b[1]:6.1f} {b[2]:6.1f} {b[3]:6.1f}  mask fill {m.sum() / max(area, 1):.2f}")
        if a.overlay:
            Path(a.overlay).mkdir(parents=True, exist_ok=True)
            labels = [(b, f"{names[int(c)]} {s:.2f}") for b, s, c in zip(orig, scores, classes)]
            overlay(img, labels, ms, r, (left, top), Path(a.overlay) / (Path(f).stem + "_det.png"))
    if a.bench:
        x = letterbox(read_rgb(a.frames[0]), H, W)[0]
        bench(a.model, x)


if __name__ == "__main__":
    main()
