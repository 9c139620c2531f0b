"""Small helper to write ONNX graphs with onnx.helper.

Opset 17 / IR 8 on purpose: every op used here (Conv, ConvTranspose, Sigmoid,
Mul, Add, Concat, MaxPool, Resize, Reshape, Transpose, Slice, Softmax) is
covered by both ONNX Runtime and tract at that level.
"""

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = 17
IR_VERSION = 8


class Graph:
    def __init__(self):
        self.nodes, self.inits, self._names = [], [], set()

    def _unique(self, base):
        name, k = base, 1
        while name in self._names:
            k += 1
            name = f"{base}_{k}"
        self._names.add(name)
        return name

    def const(self, base, array):
        name = self._unique(base)
        self.inits.append(numpy_helper.from_array(np.ascontiguousarray(array), name))
        return name

    def op(self, op_type, inputs, base, n_out=1, **attrs):
        outs = [self._unique(base if n_out == 1 else f"{base}:{i}") for i in range(n_out)]
        self.nodes.append(helper.make_node(op_type, inputs, outs, name=outs[0], **attrs))
        return outs[0] if n_out == 1 else outs

    # --- layers -------------------------------------------------------------
    def conv(self, x, w, b, base, stride=1, pad=None, groups=1, dilation=1):
        """Conv2d with symmetric padding; w is OIHW float32, b may be None."""
        k = w.shape[2:]
        if pad is None:
            pad = (k[0] // 2, k[1] // 2)
        pad = (pad, pad) if np.isscalar(pad) else tuple(pad)
        stride = (stride, stride) if np.isscalar(stride) else tuple(stride)
        dilation = (dilation, dilation) if np.isscalar(dilation) else tuple(dilation)
        ins = [x, self.const(f"{base}.weight", w.astype(np.float32))]
        if b is not None:
            ins.append(self.const(f"{base}.bias", b.astype(np.float32)))
        return self.op(
            "Conv", ins, base, kernel_shape=list(k), strides=list(stride),
            pads=[pad[0], pad[1], pad[0], pad[1]], group=groups, dilations=list(dilation),
        )

    def silu(self, x, base):
        # No SiLU op at opset 17: x * sigmoid(x) is what exporters emit too.
        return self.op("Mul", [x, self.op("Sigmoid", [x], f"{base}.sigmoid")], f"{base}.silu")

    def upsample2x_nearest(self, x, base):
        scales = self.const(f"{base}.scales", np.array([1, 1, 2, 2], np.float32))
        # asymmetric + floor is torch's 'nearest' (src = floor(dst / 2)).
        return self.op(
            "Resize", [x, "", scales], base, mode="nearest",
            coordinate_transformation_mode="asymmetric", nearest_mode="floor",
        )

    def concat(self, xs, base, axis=1):
        return self.op("Concat", list(xs), base, axis=axis)

    def slice(self, x, start, end, axis, base):
        return self.op(
            "Slice",
            [x, self.const(f"{base}.starts", np.array([start], np.int64)),
             self.const(f"{base}.ends", np.array([end], np.int64)),
             self.const(f"{base}.axes", np.array([axis], np.int64))],
            base,
        )

    def reshape(self, x, shape, base):
        return self.op("Reshape", [x, self.const(f"{base}.shape", np.array(shape, np.int64))], base)

    # --- model --------------------------------------------------------------
    def model(self, inputs, outputs, metadata, doc=""):
        """inputs/outputs: lists of (name, shape); metadata: dict of str -> str."""
        graph = helper.make_graph(
            self.nodes, "voxpan_yolo",
            [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in inputs],
            [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in outputs],
            initializer=self.inits,
        )
        m = helper.make_model(
            graph, opset_imports=[helper.make_opsetid("", OPSET)],
            producer_name="voxpan-tools-yolo", ir_version=IR_VERSION, doc_string=doc,
        )
        for k, v in metadata.items():
            m.metadata_props.add(key=k, value=str(v))
        onnx.checker.check_model(m, full_check=True)
        return m


def names_repr(names):
    """Class names as ultralytics/YOLOv5 exports store them: str() of a dict."""
    return repr({int(k): str(v) for k, v in names.items()})
