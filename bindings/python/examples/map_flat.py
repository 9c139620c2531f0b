"""Maps the flat sample from Python, the way `voxpan run` does, and shows the mesh.

    python bindings/python/examples/map_flat.py [DATASET] [--frames N] [--out DIR] [--view]

Per frame: the dataset's network masks are refined on the measured depth, depth holes are
filled, and the frame is fused into the map (its segments matched with the map's instances).
Writes the map file; with --view (and Open3D installed) opens the mesh coloured by instance.
"""

import argparse
import pathlib
import time

import numpy as np

import voxpan

DEFAULT = pathlib.Path(__file__).resolve().parents[3].parent / "shared" / "data" / "flat"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", nargs="?", default=DEFAULT, type=pathlib.Path)
    ap.add_argument("--frames", type=int, default=None, help="map only the first N frames")
    ap.add_argument("--out", type=pathlib.Path, default=pathlib.Path("voxpan-out/python"))
    ap.add_argument("--view", action="store_true", help="show the mesh in Open3D")
    args = ap.parse_args()

    ds = voxpan.open_dataset(args.dataset)
    m = voxpan.PanopticMap(voxel_size=0.02, class_names=ds.class_names)
    n = len(ds) if args.frames is None else min(args.frames, len(ds))
    start = time.perf_counter()
    for i in range(n):
        f = ds[i]
        labels = None
        if "labels" in f:
            labels, _ = voxpan.trim_stuff_planes(f["depth"], f["labels"], f["segments"])
            labels, _ = voxpan.refine(f["depth"], labels, segments=f["segments"])
        depth = voxpan.fill_holes(f["depth"], k=5)
        m.integrate(depth, f["color"], f["intrinsics"], f["pose"],
                    labels=labels, segments=f.get("segments"))
    elapsed = time.perf_counter() - start
    print(f"{n} frames in {elapsed:.1f} s ({n / elapsed:.1f} frames/s), {m.block_count} blocks")

    vertices, triangles, colors, normals = m.mesh(by="instance")
    print(f"mesh: {len(vertices)} vertices, {len(triangles)} triangles")
    for inst in sorted(m.instances(), key=lambda i: -i["voxels"])[:8]:
        print(f"  instance {inst['id']:>3} {inst['class_name'] or '?':<12} {inst['voxels']:>6} voxels")
    args.out.mkdir(parents=True, exist_ok=True)
    m.save(args.out / "map.voxpan")
    print(f"wrote {args.out / 'map.voxpan'}")

    try:
        import open3d as o3d  # optional: only for the viewer
    except ImportError:
        if args.view:
            print("Open3D is not installed (pip install open3d): no viewer")
        return
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices.astype(np.float64)),
        o3d.utility.Vector3iVector(triangles.astype(np.int32)),
    )
    mesh.vertex_colors = o3d.utility.Vector3dVector(colors / 255.0)
    mesh.vertex_normals = o3d.utility.Vector3dVector(normals.astype(np.float64))
    print(f"Open3D mesh: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles")
    if args.view:
        o3d.visualization.draw_geometries([mesh])


if __name__ == "__main__":
    main()
