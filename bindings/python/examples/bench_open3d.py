"""voxpan's TSDF map against Open3D's VoxelBlockGrid, from one Python script on the same frames.

    python bindings/python/examples/bench_open3d.py [DATASET] [--frames N]

Both fuse each frame's measured depth (float32 metres, no hole filling) and colour with the
same settings: 2 cm voxels, blocks of 8^3 voxels, truncation 3 voxels (voxpan's default
`truncation_voxels`), depth up to 5 m (voxpan's `max_range`). voxpan: `PanopticMap.integrate`
without labels (TSDF and colour only, no association). Open3D: `compute_unique_block_coordinates`
+ `integrate` of `open3d.t.geometry.VoxelBlockGrid` on the CPU (tsdf, weight, colour). Each call
is timed from Python, so numpy conversions are included on both sides; the two libraries take
turns frame by frame, so background load hits both alike. At the end each extracts its whole
mesh once (voxpan: `mesh()`, a first call meshes every block; Open3D: `extract_triangle_mesh`
with weight threshold 0.5, i.e. observed at least once, as voxpan meshes every observed voxel)
and hands over numpy arrays. Frames are decoded beforehand, and for Open3D, whose float depth
needs float colour, the colours are converted to float32 beforehand too (that conversion is
timed separately, not counted). Build voxpan optimised
(`bindings/python/setup.sh --release`); Open3D: `pip install open3d-cpu`.
"""

import argparse
import os
import pathlib
import platform
import statistics
import time

import numpy as np

import voxpan

try:
    import open3d as o3d
    import open3d.core as o3c
except ImportError as e:  # the comparison needs it; voxpan never does
    raise SystemExit(f"open3d is needed for this benchmark: pip install open3d-cpu ({e})")

DEFAULT = pathlib.Path(__file__).resolve().parents[3].parent / "shared" / "data" / "flat"
VOXEL = 0.02
TRUNCATION_VOXELS = 3.0
DEPTH_MAX = 5.0


def cpu_model() -> str:
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def area(vertices, triangles) -> float:
    """Surface area: the two meshes tessellate differently, so it tells whether they agree."""
    a, b, c = (vertices[triangles[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", default=DEFAULT, type=pathlib.Path)
    ap.add_argument("--frames", type=int, default=None, help="only the first N frames")
    args = ap.parse_args()

    ds = voxpan.open_dataset(args.dataset)
    n = len(ds) if args.frames is None else min(args.frames, len(ds))
    frames = [ds[i] for i in range(n)]
    convert = []
    for f in frames:
        t0 = time.perf_counter()
        f["color_f32"] = f["color"].astype(np.float32) / 255.0
        convert.append((time.perf_counter() - t0) * 1e3)

    m = voxpan.PanopticMap(voxel_size=VOXEL, truncation_voxels=TRUNCATION_VOXELS,
                           max_range=DEPTH_MAX)
    cpu = o3c.Device("CPU:0")
    # Room for every block the sample touches, so no rehash lands inside a timed call
    # (voxpan's map grows without one).
    vbg = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"),
        attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
        attr_channels=((1), (1), (3)),
        voxel_size=VOXEL, block_resolution=8, block_count=60_000, device=cpu,
    )

    load_before = os.getloadavg()
    ours, inside, theirs = [], [], []
    for f in frames:
        fx, fy, cx, cy = f["intrinsics"]
        t0 = time.perf_counter()
        report = m.integrate(f["depth"], f["color"], f["intrinsics"], f["pose"])
        t1 = time.perf_counter()
        # Open3D's extrinsic maps world to camera: the inverse of voxpan's T_world_camera.
        intrinsic = o3c.Tensor([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], o3c.float64)
        extrinsic = o3c.Tensor(np.linalg.inv(f["pose"]), o3c.float64)
        depth = o3d.t.geometry.Image(o3c.Tensor(f["depth"]))
        color = o3d.t.geometry.Image(o3c.Tensor(f["color_f32"]))
        blocks = vbg.compute_unique_block_coordinates(
            depth, intrinsic, extrinsic, 1.0, DEPTH_MAX, TRUNCATION_VOXELS)
        vbg.integrate(blocks, depth, color, intrinsic, extrinsic, 1.0, DEPTH_MAX,
                      TRUNCATION_VOXELS)
        t2 = time.perf_counter()
        ours.append((t1 - t0) * 1e3)
        inside.append(report["integrate_ms"])
        theirs.append((t2 - t1) * 1e3)

    t0 = time.perf_counter()
    v, t, c, nrm = m.mesh(by="rgb")
    t1 = time.perf_counter()
    # Open3D meshes where weight > threshold; its weights count frames.
    mesh = vbg.extract_triangle_mesh(weight_threshold=0.5)
    o3d_arrays = [mesh.vertex.positions.numpy(), mesh.triangle.indices.numpy()]
    o3d_arrays += [mesh.vertex[k].numpy() for k in ("colors", "normals") if k in mesh.vertex]
    t2 = time.perf_counter()
    load_after = os.getloadavg()

    med = statistics.median
    ours_mesh, theirs_mesh = (t1 - t0) * 1e3, (t2 - t1) * 1e3
    print(f"{n} frames of {args.dataset}; voxel {VOXEL} m, truncation {TRUNCATION_VOXELS:g} "
          f"voxels, depth <= {DEPTH_MAX:g} m, blocks of 8^3")
    print(f"machine: {cpu_model()}, {os.cpu_count()} cores; "
          f"load average {load_before[0]:.2f} before, {load_after[0]:.2f} after; "
          f"Open3D {o3d.__version__}")
    print(f"{'':<26} {'voxpan':>10} {'Open3D':>10} {'Open3D/voxpan':>14}")
    print(f"{'integrate, ms/frame (med)':<26} {med(ours):>10.2f} {med(theirs):>10.2f} "
          f"{med(theirs) / med(ours):>14.2f}")
    print(f"{'integrate, total s':<26} {sum(ours) / 1e3:>10.2f} {sum(theirs) / 1e3:>10.2f} "
          f"{sum(theirs) / sum(ours):>14.2f}")
    print(f"{'full mesh, ms':<26} {ours_mesh:>10.1f} {theirs_mesh:>10.1f} "
          f"{theirs_mesh / ours_mesh:>14.2f}")
    print(f"{'mesh vertices':<26} {len(v):>10} {len(o3d_arrays[0]):>10}")
    print(f"{'mesh triangles':<26} {len(t):>10} {len(o3d_arrays[1]):>10}")
    print(f"{'mesh area, m^2':<26} {area(v, t):>10.1f} {area(*o3d_arrays[:2]):>10.1f}")
    print(f"{'blocks':<26} {m.block_count:>10} {vbg.hashmap().size():>10}")
    print(f"voxpan's own integrate time inside the call: {med(inside):.2f} ms/frame (median); "
          f"colour to float32 for Open3D (not counted): {med(convert):.2f} ms/frame")


if __name__ == "__main__":
    main()
