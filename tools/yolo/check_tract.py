#!/usr/bin/env python3
"""Compare tract (the `tract` PyPI bindings of the same engine voxpan's Rust side
uses) with the ONNX Runtime goldens written by golden.py.

    check_tract.py MODEL.onnx [MODEL.onnx ...]

Reads MODEL.golden.json/.bin next to each model, runs every case through tract
and prints the max abs difference per output, the tract run time, and the
model properties tract exposes (ONNX metadata_props appear as
`onnx.metadata_props.<key>`).
"""

import json
import sys
import time
from pathlib import Path

import numpy as np
import tract


def load_golden(model):
    stem = model.with_suffix("")
    head = json.loads(Path(f"{stem}.golden.json").read_text())
    blob = Path(f"{stem}.golden.bin").read_bytes()

    def tensor(t):
        n = int(np.prod(t["shape"]))
        return np.frombuffer(blob, "<f4", count=n, offset=t["offset"]).reshape(t["shape"])

    return head, tensor


def main():
    for path in map(Path, sys.argv[1:]):
        head, tensor = load_golden(path)
        t0 = time.perf_counter()
        model = tract.onnx().load(str(path)).into_model()
        props = model.property_keys()  # string tensors; the python bindings only list them
        run = model.into_runnable()
        print(f"{path.name}: tract {tract.version()} load+optimise {time.perf_counter() - t0:.2f} s, "
              f"golden from onnxruntime {head['onnxruntime']}")
        print(f"  properties: {sorted(props)}")
        for case in head["cases"]:
            x = tensor(case["tensors"]["images"]).copy()
            t0 = time.perf_counter()
            outs = [o.to_numpy() for o in run.run([x])]
            dt = (time.perf_counter() - t0) * 1e3
            diffs = []
            for name, got in zip(("output0", "output1"), outs):
                want = tensor(case["tensors"][name])
                assert got.shape == want.shape, (name, got.shape, want.shape)
                diffs.append(f"{name} max abs {np.abs(got - want).max():.2e} (|ref| max {np.abs(want).max():.1f})")
            print(f"  {case['name']}: {', '.join(diffs)}; {dt:.0f} ms")


if __name__ == "__main__":
    main()
