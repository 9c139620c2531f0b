#!/usr/bin/env python3
"""Dev-time count of the objects a keyframe schedule can show at all (docs/network.md).

Not part of the product. An instance is shown once segments matched it in two frames
(`[tracking] min_observations`), and frames between keyframes carry the map's own labels,
which confirm nothing. So an object in view of fewer than two keyframes cannot appear in a
keyframe map. This reads a flat-format dataset's ground truth (an object is in a frame where
any of its pixels has depth between 0.1 and 5 m, the range the map integrates) and counts, per
schedule, the objects fewer than two keyframes see.

    pip install numpy pillow
    python3 tools/keyframe_coverage.py DATASET [--every 1 2 3 5] [--run OUT/metrics.json...]

`--run` takes the keyframes a `voxpan run` actually made (its metrics.json timeline), for
`every = "auto"` or a segmenter on its own thread.
"""
import argparse
import json
import pathlib
import sys

import numpy as np
from PIL import Image


def frames_in_view(dataset):
    """Object id -> indices of the frames whose ground truth shows it, in frame order."""
    run = dataset / "run1"
    ids = sorted(p.name[:6] for p in run.glob("*_segmentation.png"))
    if not ids:
        sys.exit(f"{run}: no *_segmentation.png (is {dataset} a flat-format dataset?)")
    seen = {}
    for index, frame in enumerate(ids):
        labels = np.array(Image.open(run / f"{frame}_segmentation.png"))
        if labels.ndim == 3:
            labels = labels[..., 0]
        depth = np.array(Image.open(run / f"{frame}_depth.tiff"))
        within = (depth > 0.1) & (depth < 5.0)
        for obj in np.unique(labels[within]):
            seen.setdefault(int(obj), []).append(index)
    return seen, len(ids)


def run_keyframes(path):
    timeline = json.loads(pathlib.Path(path).read_text())["report"]["timeline"]
    return {i for i, frame in enumerate(timeline) if frame["keyframe"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dataset", type=pathlib.Path)
    parser.add_argument("--every", type=int, nargs="*", default=[1, 2, 3, 5])
    parser.add_argument("--run", nargs="*", default=[])
    args = parser.parse_args()
    seen, count = frames_in_view(args.dataset)
    schedules = [(f"every {n}", set(range(0, count, n))) for n in args.every]
    schedules += [(path, run_keyframes(path)) for path in args.run]
    print(f"{len(seen)} objects in {count} frames")
    for name, keyframes in schedules:
        few = sorted(o for o, frames in seen.items() if len(keyframes.intersection(frames)) < 2)
        print(f"{name}: {len(keyframes)} keyframes, {len(few)} objects in fewer than two: {few}")


if __name__ == "__main__":
    main()
