#!/usr/bin/env python3
"""Dev-time oracle for voxpan's surface accuracy: exact point-to-mesh distances with trimesh.

Not part of the product. Computes, for every vertex of a reconstruction, the exact distance to
the nearest triangle of a ground-truth mesh (trimesh.proximity.closest_point, an R-tree of
triangles and an exact closest-point test), and prints the statistics voxpan reports: mean,
median and 95th percentile (nearest rank: the ceil(q n)-th smallest value, as voxpan-eval
defines them) and the share within a threshold.

    pip install trimesh==4.12.2 rtree==1.4.1 scipy numpy
    python3 tools/surface_reference.py TRUTH.ply RECON.ply [--threshold 0.02] [--json]
    python3 tools/surface_reference.py --subsample 40 RECON.ply OUT.ply   # every 40th vertex

The golden case in crates/eval/tests/golden/surface/ was written with this script.
"""
import json
import math
import sys

import numpy as np
import trimesh


def nearest_rank(sorted_values, q):
    rank = min(max(math.ceil(q * len(sorted_values)), 1), len(sorted_values))
    return float(sorted_values[rank - 1])


def scores(truth_path, recon_path, threshold):
    truth = trimesh.load(truth_path, process=False, force="mesh")
    recon = trimesh.load(recon_path, process=False)
    points = np.asarray(recon.vertices, dtype=np.float64)
    _, distances, _ = trimesh.proximity.closest_point(truth, points)
    d = np.sort(distances)
    return {
        "vertices": int(len(d)),
        "mean": float(d.mean()),
        "median": nearest_rank(d, 0.5),
        "p95": nearest_rank(d, 0.95),
        "within": float(100.0 * np.count_nonzero(d <= threshold) / len(d)),
        "threshold": threshold,
    }


def subsample(recon_path, out_path, step):
    recon = trimesh.load(recon_path, process=False)
    points = np.asarray(recon.vertices)[::step]
    trimesh.PointCloud(points).export(out_path)
    print(f"{len(points)} of {len(recon.vertices)} vertices -> {out_path}")


def main(argv):
    if argv[:1] == ["--subsample"]:
        subsample(argv[2], argv[3], int(argv[1]))
        return
    threshold = 0.02
    if "--threshold" in argv:
        i = argv.index("--threshold")
        threshold = float(argv[i + 1])
        del argv[i : i + 2]
    as_json = "--json" in argv
    argv = [a for a in argv if a != "--json"]
    result = scores(argv[0], argv[1], threshold)
    if as_json:
        print(json.dumps(result, indent=2))
    else:
        print(
            f"{result['vertices']} vertices: mean {1000 * result['mean']:.3f} mm, "
            f"median {1000 * result['median']:.3f} mm, p95 {1000 * result['p95']:.3f} mm, "
            f"{result['within']:.2f} % within {threshold} m"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
