#!/usr/bin/env python3
"""Dev-time measure of how much of a network's thing masks is the object, by object size
(docs/design/association.md, "How far the synthetic masks are from a network's").

Not part of the product. For every ground-truth thing in every frame (PanopticID 1 in
groundtruth_labels.csv) it takes the predicted thing mask that covers most of the object's
pixels and, when that mask covers at least half of them, reads the mask's area over the
object's and the object's share of the mask (1.0: the mask is all object; 0.3: seven tenths of
it is what lies beside or behind). Objects are binned by their share of the image, so that
datasets of other resolutions compare. What association meets is this share: a mask that is
mostly wall lands, after refinement, on the wall.

    pip install numpy pillow
    python3 tools/mask_purity.py DATASET [DATASET...] [--masks DIR] [--every K]

DATASET is a flat-format dataset (run1/NNNNNN_segmentation.png, _predicted.png,
_labels.json); `--masks DIR` reads the predicted masks from DIR instead (as `voxpan segment
--out DIR` writes a network's), for the one dataset given. `--every K` reads every Kth frame.
"""
import argparse
import csv
import json
import pathlib
import sys

import numpy as np
from PIL import Image

BINS = [(0.0, 0.002), (0.002, 0.01), (0.01, 0.05), (0.05, 1.0)]


def thing_objects(dataset):
    """Ground-truth instance ids that are things."""
    path = dataset / "groundtruth_labels.csv"
    if not path.is_file():
        sys.exit(f"{path}: missing (is {dataset} a flat-format dataset?)")
    with path.open() as f:
        return {int(row["InstanceID"]) for row in csv.DictReader(f) if row["PanopticID"] == "1"}


def read_labels(path):
    labels = np.array(Image.open(path))
    return labels[..., 0] if labels.ndim == 3 else labels


def measure(dataset, masks, every):
    """One (object share of image, mask area / object area, object share of mask) per object
    a mask covers at least half of, and the count of objects none does."""
    things = thing_objects(dataset)
    run = dataset / "run1"
    frames = sorted(p.name[:6] for p in run.glob("*_segmentation.png"))[::every]
    if not frames:
        sys.exit(f"{run}: no *_segmentation.png")
    rows, uncovered = [], 0
    for frame in frames:
        truth = read_labels(run / f"{frame}_segmentation.png")
        predicted_path = masks / f"{frame}_predicted.png"
        if not predicted_path.is_file():
            sys.exit(f"{predicted_path}: missing (frame {frame})")
        predicted = read_labels(predicted_path)
        segments = json.loads((masks / f"{frame}_labels.json").read_text())
        thing_ids = [s["id"] for s in segments if s.get("isthing")]
        thing_mask = np.isin(predicted, thing_ids)
        areas = np.bincount(predicted.ravel())
        for obj in np.unique(truth):
            if int(obj) not in things:
                continue
            on_object = truth == obj
            object_area = int(on_object.sum())
            ids, counts = np.unique(predicted[on_object & thing_mask], return_counts=True)
            if len(ids) == 0 or 2 * counts.max() < object_area:
                uncovered += 1
                continue
            best = int(ids[counts.argmax()])
            overlap = int(counts.max())
            area = int(areas[best])
            rows.append((object_area / truth.size, area / object_area, overlap / area))
    return np.array(rows).reshape(-1, 3), uncovered


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("datasets", nargs="+", type=pathlib.Path)
    parser.add_argument("--masks", type=pathlib.Path, help="predicted masks' folder")
    parser.add_argument("--every", type=int, default=1)
    args = parser.parse_args()
    if args.masks and len(args.datasets) != 1:
        sys.exit("--masks goes with one dataset")
    for dataset in args.datasets:
        rows, uncovered = measure(dataset, args.masks or dataset / "run1", max(args.every, 1))
        print(f"{dataset}{' with ' + str(args.masks) if args.masks else ''}: "
              f"{len(rows)} objects masked, {uncovered} not covered at half by a thing mask")
        print("  object, share of image   objects   mask / object area   object share of mask (medians)")
        for low, high in BINS:
            sel = (rows[:, 0] >= low) & (rows[:, 0] < high)
            if sel.any():
                print(f"  {100 * low:5.1f}-{100 * high:5.1f} %        {sel.sum():7d}   "
                      f"{np.median(rows[sel, 1]):18.2f}   {np.median(rows[sel, 2]):10.2f}")


if __name__ == "__main__":
    main()
