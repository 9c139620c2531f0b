"""Make an INT8 copy of a YOLO-seg ONNX model with ONNX Runtime's static quantisation.

    quantize.py IN.onnx OUT.onnx --calibration DIR [--frames START:END[:STEP]]

Weights are INT8 per output channel, activations UINT8 per tensor, calibrated by min/max on
the colour images NNNNNN_color.png of DIR (a flat-format run folder), letterboxed as voxpan
does. The model is written in QDQ form (QuantizeLinear / DequantizeLinear pairs around each
quantised operator), which ONNX Runtime fuses into integer kernels and which tract reads.

The detection head's outputs (box, class and mask-coefficient rows, and the prototypes) are
left in float: they carry pixel coordinates and scores whose ranges one UINT8 scale cannot hold.
Calibrate on frames the model is not scored on (docs/network.md says which).
"""

import argparse
import json
import pathlib
import sys

import numpy as np
import onnx
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from yolo_common import letterbox, read_rgb  # noqa: E402


def frame_range(text):
    parts = [int(p) for p in text.split(":")]
    if len(parts) not in (2, 3) or parts[0] > parts[1]:
        raise argparse.ArgumentTypeError(f"{text!r}: expected START:END[:STEP]")
    step = parts[2] if len(parts) == 3 else 1
    return range(parts[0], parts[1] + 1, step)


class Frames(CalibrationDataReader):
    def __init__(self, paths, input_name, size):
        self.items = iter(paths)
        self.input_name = input_name
        self.size = size

    def get_next(self):
        path = next(self.items, None)
        if path is None:
            return None
        x, _, _ = letterbox(read_rgb(path), *self.size)
        return {self.input_name: x}


def head_nodes(model):
    """Nodes after the last convolutions on the way to each graph output: the detection head's
    decoding (sigmoid, grid offsets, scaling, concatenation), kept in float."""
    producers = {o: n for n in model.graph.node for o in n.output}
    keep = set()
    for output in model.graph.output:
        stack = [output.name]
        while stack:
            node = producers.get(stack.pop())
            if node is None or node.name in keep or node.op_type == "Conv":
                continue
            keep.add(node.name)
            stack.extend(node.input)
    return sorted(keep)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("model", type=pathlib.Path)
    ap.add_argument("out", type=pathlib.Path)
    ap.add_argument("--calibration", type=pathlib.Path, required=True,
                    help="flat-format folder (run1/ or its parent) with NNNNNN_color.png")
    ap.add_argument("--frames", type=frame_range, default=None,
                    help="frame ids to calibrate on, START:END[:STEP] (default: all)")
    args = ap.parse_args()

    folder = args.calibration / "run1" if (args.calibration / "run1").is_dir() else args.calibration
    paths = sorted(folder.glob("*_color.png"))
    if args.frames is not None:
        wanted = set(args.frames)
        paths = [p for p in paths if int(p.name.split("_")[0]) in wanted]
    if not paths:
        sys.exit(f"quantize.py: no NNNNNN_color.png in {folder} for the frames asked")

    model = onnx.load(str(args.model))
    graph_input = model.graph.input[0]
    dims = [d.dim_value for d in graph_input.type.tensor_type.shape.dim]
    size = (dims[2], dims[3])
    prepared = args.out.with_suffix(".prepared.onnx")
    quant_pre_process(str(args.model), str(prepared), skip_symbolic_shape=True)
    prepared_model = onnx.load(str(prepared))
    excluded = head_nodes(prepared_model)
    quantize_static(
        str(prepared),
        str(args.out),
        Frames(paths, graph_input.name, size),
        quant_format=QuantFormat.QDQ,
        per_channel=True,
        weight_type=QuantType.QInt8,
        activation_type=QuantType.QUInt8,
        calibrate_method=CalibrationMethod.MinMax,
        nodes_to_exclude=excluded,
    )
    prepared.unlink()
    # The float model's metadata (class names, strides) travels with the copy.
    quantized = onnx.load(str(args.out))
    del quantized.metadata_props[:]
    for prop in model.metadata_props:
        quantized.metadata_props.add(key=prop.key, value=prop.value)
    onnx.save(quantized, str(args.out))
    print(json.dumps({"model": str(args.out), "calibration_frames": len(paths),
                      "float_nodes": len(excluded)}))


if __name__ == "__main__":
    main()
