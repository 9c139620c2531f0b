#!/usr/bin/env python3
"""Write small valid ONNX models that are not YOLO segmentation models, for the error tests.

    make_bad_models.py [--out-dir DIR]

- foreign-conv.onnx: an image model ([1,3,64,64] -> Conv -> [1,4,64,64]), one output;
- det-only.onnx: a detection head without prototypes ([1,3,64,64] -> [1,41,64]), the
  output a YOLO *detection* export has.

Both a few hundred bytes, deterministic (seeded weights), opset 17 like the tiny models.
"""

import argparse
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET, IR_VERSION = 17, 8


def save(graph, path, metadata):
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="voxpan tools/yolo/make_bad_models.py")
    model.ir_version = IR_VERSION
    for k, v in metadata.items():
        model.metadata_props.append(onnx.StringStringEntryProto(key=k, value=v))
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    print(f"wrote {path} ({path.stat().st_size} bytes)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out-dir", default=str(Path(__file__).resolve().parents[2] / "target" / "models"))
    out = Path(ap.parse_args().out_dir)
    out.mkdir(parents=True, exist_ok=True)
    r = np.random.default_rng(0)
    images = helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 64, 64])

    w = numpy_helper.from_array(r.standard_normal((4, 3, 3, 3)).astype(np.float32), "w")
    conv = helper.make_node("Conv", ["images", "w"], ["output0"], pads=[1, 1, 1, 1])
    y = helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 4, 64, 64])
    save(helper.make_graph([conv], "foreign", [images], [y], [w]), out / "foreign-conv.onnx",
         {"description": "not a detector"})

    # A 1x1 conv with 41 channels at stride 8 -> [1, 41, 8, 8] -> [1, 41, 64]: 4 box + 5 classes + 32 coefs.
    w = numpy_helper.from_array(r.standard_normal((41, 3, 1, 1)).astype(np.float32) * 0.1, "w")
    shape = numpy_helper.from_array(np.array([1, 41, 64], np.int64), "shape")
    nodes = [helper.make_node("Conv", ["images", "w"], ["c"], strides=[8, 8]),
             helper.make_node("Reshape", ["c", "shape"], ["output0"])]
    y = helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 41, 64])
    save(helper.make_graph(nodes, "det", [images], [y], [w, shape]), out / "det-only.onnx",
         {"names": "{0: 'chair', 1: 'couch', 2: 'bed', 3: 'dining table', 4: 'tv'}",
          "task": "detect", "imgsz": "[64, 64]"})


if __name__ == "__main__":
    main()
