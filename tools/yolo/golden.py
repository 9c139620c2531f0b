#!/usr/bin/env python3
"""Write golden ONNX Runtime outputs for a model, for backend cross-checks.

    golden.py MODEL.onnx [--seed 0] [--frame PNG] [--cases uniform flat]

Writes MODEL.golden.json and MODEL.golden.bin next to the model (or into
--out-dir). The .bin is every tensor back to back, float32 little-endian,
C order; the JSON says where each one is:

  {"model": "x.onnx", "model_sha256": ..., "onnxruntime": "1.31.1",
   "cases": [{"name": "uniform", "seed": 0,
              "tensors": {"images":  {"offset": 0, "shape": [1,3,H,W], "dtype": "f32"},
                          "output0": {...}, "output1": {...}},
              "detections": [{"class": 3, "name": "chair", "score": .9,
                              "box_xyxy": [x1,y1,x2,y2], "mask_area": 1234}, ...]},
             {"name": "flat", "frame": "...png", "letterbox": {"r": .25, "left": 0, "top": 4}, ...}],
   "ort_opt_vs_noopt_max_abs": {"output0": ..., "output1": ...}}

Offsets are in bytes. `detections` (confidence 0.25, class-aware NMS 0.45,
boxes in model input pixels, mask area in input pixels) are for checking
post-processing; compare them with a tolerance, not bit for bit.
`ort_opt_vs_noopt_max_abs` is how far ONNX Runtime moves from itself when its
graph optimisations are switched off: a floor for a fair cross-backend tolerance.
"""

import argparse
import hashlib
import json
import re
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort

sys.path.insert(0, str(Path(__file__).resolve().parent))
from yolo_common import decode, letterbox, masks, nms, parse_names, read_metadata, read_rgb  # noqa: E402

DEFAULT_FRAME = Path(__file__).resolve().parents[3] / "shared" / "data" / "flat" / "run1" / "000074_color.png"


def session(path, optimize=True):
    so = ort.SessionOptions()
    # One thread: reductions then run in a fixed order, so reruns are bit-identical.
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    if not optimize:
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def detections(out0, out1, meta, H, W):
    names = parse_names(meta["names"])
    boxes, scores, classes, coefs = decode(out0, meta, 0.25)
    keep = nms(boxes, scores, classes, 0.45)
    ms = masks(coefs[keep], out1[0], boxes[keep], H, W)
    return [
        {"class": int(c), "name": names[int(c)], "score": round(float(s), 6),
         "box_xyxy": [round(float(v), 4) for v in b], "mask_area": int(m.sum())}
        for b, s, c, m in zip(boxes[keep], scores[keep], classes[keep], ms)
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frame", default=str(DEFAULT_FRAME))
    ap.add_argument("--cases", nargs="+", choices=["uniform", "flat"],
                    help="default: uniform, plus flat when the frame exists")
    ap.add_argument("--out-dir")
    a = ap.parse_args()

    if a.cases is None:
        a.cases = ["uniform"] + (["flat"] if Path(a.frame).is_file() else [])
        if "flat" not in a.cases:
            print(f"note: {a.frame} not found, writing the uniform case only", file=sys.stderr)
    model = Path(a.model)
    sess, plain = session(model), session(model, optimize=False)
    meta = read_metadata(sess)
    _, _, H, W = sess.get_inputs()[0].shape
    out_dir = Path(a.out_dir) if a.out_dir else model.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = model.name[: -len(".onnx")] if model.name.endswith(".onnx") else model.name
    blob, cases, worst = bytearray(), [], {}

    def put(arr):
        arr = np.ascontiguousarray(arr, dtype="<f4")
        entry = {"offset": len(blob), "shape": list(arr.shape), "dtype": "f32"}
        blob.extend(arr.tobytes())
        return entry

    for name in a.cases:
        case = {"name": name}
        if name == "uniform":
            x = np.random.default_rng(a.seed).random((1, 3, H, W), dtype=np.float32)
            case["seed"] = a.seed
            case["generator"] = "numpy.random.default_rng(seed).random((1,3,H,W), dtype=float32)"
        else:
            x, r, (left, top) = letterbox(read_rgb(a.frame), H, W)
            case["frame"] = Path(a.frame).name
            case["letterbox"] = {"r": r, "left": left, "top": top, "pad_value": 114}
        out0, out1 = sess.run(["output0", "output1"], {"images": x})
        ref0, ref1 = plain.run(["output0", "output1"], {"images": x})
        for k, (p, q) in {"output0": (out0, ref0), "output1": (out1, ref1)}.items():
            worst[k] = max(worst.get(k, 0.0), float(np.abs(p - q).max()))
        case["tensors"] = {"images": put(x), "output0": put(out0), "output1": put(out1)}
        case["detections"] = detections(out0, out1, meta, H, W)
        cases.append(case)

    bin_path, json_path = out_dir / f"{stem}.golden.bin", out_dir / f"{stem}.golden.json"
    bin_path.write_bytes(bytes(blob))
    header = {
        "model": model.name,
        "model_sha256": hashlib.sha256(model.read_bytes()).hexdigest(),
        "onnxruntime": ort.__version__,
        "bin": bin_path.name,
        "bin_sha256": hashlib.sha256(blob).hexdigest(),
        "metadata": meta,
        "cases": cases,
        "ort_opt_vs_noopt_max_abs": worst,
    }
    # Indented for reading, but each list of numbers kept on one line.
    text = re.sub(r"\[[^\[\]{}]*\]", lambda m: re.sub(r"\s+", " ", m.group(0)).replace("[ ", "[").replace(" ]", "]"),
                  json.dumps(header, indent=1))
    json_path.write_text(text + "\n")
    print(f"wrote {json_path} and {bin_path.name} ({len(blob)} bytes); "
          f"ORT opt vs no-opt max abs: {', '.join(f'{k} {v:.2e}' for k, v in worst.items())}; "
          + ", ".join(f"{c['name']}: {len(c['detections'])} detections" for c in cases))


if __name__ == "__main__":
    main()
