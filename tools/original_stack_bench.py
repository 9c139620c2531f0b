#!/usr/bin/env python3
"""Dev-time benchmark: the original's stack against `voxpan bench`, in one run, same frames.

The original maps with KDEpy refinement (the released rule, `utils.remove_outliers`, as in
tools/kdepy_reference.py) and Open3D's VoxelBlockGrid TSDF (here: 2 cm voxels, truncation 2
voxels, depth cut at 5 m, colour, on the CPU with 2 threads). This times both per frame on the
flat frames, then runs `voxpan bench` on the same frames and prints the ratio of per-frame
times: medians on both sides (the original's median frame, voxpan's median interval between
mapped frames), and, printed beside, means (the original's mean frame against voxpan's whole
run, its start-up included). Frames are decoded before timing the original, so its figure
leaves decoding out while voxpan's includes it: the ratio is, if anything, in the original's
favour.

The two take turns for `--rounds` rounds (default 3), each ratio from one round's pair, and the
median ratio is printed last: a shared machine's load changes within minutes, and a ratio of
two runs minutes apart measures that as much as the programs. Each round also times `voxpan
bench --truncation 2`, the original's band (voxpan's default is 3 voxels), for the ratio at
equal settings, and the original's decoding of the same files (tifffile, Pillow), for the ratio
with decoding counted on both sides; the headline ratio is voxpan's defaults' against the
original without its decoding.

    pip install KDEpy==1.1.12 scipy numpy tifffile pillow open3d-cpu==0.20.0
    python3 tools/original_stack_bench.py ../shared/data/flat target/release/voxpan [--threads 2] [--rounds 3]

Not part of the product or of CI (timings belong to benchmarks, not tests).
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import time
import warnings

import numpy as np

# KDEpy's ISJ divides by zero on masks of one repeated depth; the original runs with the same
# warnings, and the rule falls back as it does there.
warnings.filterwarnings("ignore", category=RuntimeWarning)


def load_frames(flat):
    import tifffile
    from PIL import Image

    run = os.path.join(flat, "run1")
    ids = sorted(f[:6] for f in os.listdir(run) if f.endswith("_predicted.png"))
    for fid in ids:
        base = os.path.join(run, fid)
        depth = tifffile.imread(base + "_depth.tiff").astype(np.float32)
        color = np.ascontiguousarray(np.array(Image.open(base + "_color.png").convert("RGB")))
        pred = np.array(Image.open(base + "_predicted.png"))
        pose = np.loadtxt(base + "_pose.txt").reshape(4, 4)  # T_world_camera
        yield fid, depth, color, pred, pose


def time_decoding(flat):
    """Median ms the original's readers (tifffile, Pillow, NumPy) take to decode a frame."""
    times, start = [], time.perf_counter()
    for _ in load_frames(flat):
        now = time.perf_counter()
        times.append(1e3 * (now - start))
        start = now
    return statistics.median(times)


def flat_intrinsics(flat):
    values = {}
    with open(os.path.join(flat, "Intrinsics.txt")) as f:
        for line in f:
            m = re.match(r"\s*(\w+):\s*([-0-9.]+)", line)
            if m:
                values[m.group(1)] = float(m.group(2))
    return values["f_x"], values["f_y"], values["u"], values["v"]


def time_original(flat, frames, threads):
    # Open3D's CPU kernels are OpenMP loops: the thread count must be set before it loads.
    os.environ["OMP_NUM_THREADS"] = str(threads)
    import open3d as o3d
    import open3d.core as o3c

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from kdepy_reference import refine_frame

    fx, fy, cx, cy = flat_intrinsics(flat)
    intrinsic = o3c.Tensor([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], o3c.float64)
    device = o3c.Device("CPU:0")
    grid = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"),
        attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
        attr_channels=((1), (1), (3)),
        voxel_size=0.02,
        block_resolution=8,
        block_count=100000,
        device=device,
    )
    depth_scale, depth_max, trunc = 1.0, 5.0, 2.0
    refine_ms, integrate_ms = [], []
    for _, depth, color, pred, pose in frames:
        t0 = time.perf_counter()
        refine_frame(depth, pred, "release")
        t1 = time.perf_counter()
        depth_image = o3d.t.geometry.Image(o3c.Tensor(depth)).to(device)
        # Open3D takes (float depth, float colour in [0, 1]) or (uint16, uint8).
        color_image = o3d.t.geometry.Image(o3c.Tensor(color.astype(np.float32) / 255.0)).to(device)
        extrinsic = o3c.Tensor(np.linalg.inv(pose), o3c.float64)
        blocks = grid.compute_unique_block_coordinates(
            depth_image, intrinsic, extrinsic, depth_scale, depth_max, trunc
        )
        grid.integrate(blocks, depth_image, color_image, intrinsic, extrinsic,
                       depth_scale, depth_max, trunc)
        t2 = time.perf_counter()
        refine_ms.append(1e3 * (t1 - t0))
        integrate_ms.append(1e3 * (t2 - t1))
    t0 = time.perf_counter()
    mesh = grid.extract_triangle_mesh()
    mesh_ms = 1e3 * (time.perf_counter() - t0)
    totals = [r + i for r, i in zip(refine_ms, integrate_ms)]
    return dict(frames=len(totals), refine=statistics.median(refine_ms),
                integrate=statistics.median(integrate_ms), total=statistics.median(totals),
                mean=statistics.fmean(totals),
                mesh=mesh_ms, triangles=len(mesh.triangle.indices))


def time_voxpan(flat, binary, threads, extra=()):
    out = subprocess.run([binary, "bench", flat, "--threads", str(threads), *extra],
                         check=True, capture_output=True, text=True).stdout
    print("\n".join(l for l in out.splitlines() if l.startswith("refinement default")))
    m = re.search(r"refinement default: ([0-9.]+) frames/s .*?([0-9.]+) over the whole run"
                  r".*final mesh ([0-9.]+) ms", out)
    if not m:
        sys.exit(f"could not read `voxpan bench`'s default-refinement line from:\n{out}")
    return float(m.group(1)), float(m.group(2)), float(m.group(3))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("flat", help="flat dataset root (Intrinsics.txt, run1/)")
    p.add_argument("voxpan", help="the voxpan binary (a release build)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    if args.rounds < 1:
        sys.exit("--rounds must be at least 1")

    frames = list(load_frames(args.flat))
    ratios, means, equal, decoded = [], [], [], []
    for round_ in range(1, args.rounds + 1):
        orig = time_original(args.flat, frames, args.threads)
        print(f"round {round_}: original stack on {orig['frames']} frames (median ms per frame): "
              f"KDEpy release-rule refinement {orig['refine']:.1f}, Open3D VoxelBlockGrid "
              f"integration {orig['integrate']:.1f}, together {orig['total']:.1f} "
              f"({1e3 / orig['total']:.1f} frames/s); final mesh {orig['mesh']:.0f} ms "
              f"({orig['triangles']} triangles)")
        fps, whole_run, mesh_ms = time_voxpan(args.flat, args.voxpan, args.threads)
        ratio = orig["total"] * fps / 1e3
        ratios.append(ratio)
        means.append(orig["mean"] * whole_run / 1e3)
        print(f"round {round_}: voxpan {fps:.1f} frames/s ({1e3 / fps:.1f} ms per frame, decoding "
              f"included), final mesh {mesh_ms:.0f} ms; ratio {ratio:.2f}x the original's frame "
              f"rate, {orig['mesh'] / mesh_ms:.1f}x its mesh extraction; in means (voxpan's "
              f"whole run, start-up included, {whole_run:.1f} frames/s, against the original's "
              f"mean {orig['mean']:.1f} ms) {means[-1]:.2f}x")
        fps2, _, _ = time_voxpan(args.flat, args.voxpan, args.threads, ["--truncation", "2"])
        equal.append(orig["total"] * fps2 / 1e3)
        print(f"round {round_}: voxpan at the original's truncation (2 voxels) {fps2:.1f} "
              f"frames/s; ratio {equal[-1]:.2f}x")
        decode_ms = time_decoding(args.flat)
        decoded.append((orig["total"] + decode_ms) * fps / 1e3)
        print(f"round {round_}: the original's decoding {decode_ms:.1f} ms a frame; with it "
              f"counted, voxpan (defaults) is {decoded[-1]:.2f}x its frame rate")
    listed = lambda rs: ", ".join(f"{r:.2f}" for r in rs)
    print(f"ratio over {len(ratios)} rounds: median {statistics.median(ratios):.2f}x "
          f"(each: {listed(ratios)}); in means: median {statistics.median(means):.2f}x (each: "
          f"{listed(means)}); at the original's truncation: median "
          f"{statistics.median(equal):.2f}x (each: {listed(equal)}); decoding counted on both "
          f"sides: median {statistics.median(decoded):.2f}x (each: {listed(decoded)})")


if __name__ == "__main__":
    main()
