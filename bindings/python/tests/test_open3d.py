"""Interop with Open3D: the mesh arrays of `voxpan.PanopticMap.mesh()` go into an
`open3d.geometry.TriangleMesh` unchanged (counts, colours, normals, bounds, area), as
bindings/python/examples/map_flat.py hands them over."""

import numpy as np

import voxpan

# A few flat frames: a mesh of real structure (thousands of triangles) in a second or two.
FRAMES = 5


def test_open3d_triangle_mesh_from_voxpan_mesh(flat_dir, open3d):
    o3d = open3d
    ds = voxpan.open_dataset(flat_dir)
    m = voxpan.PanopticMap(class_names=ds.class_names)
    for i in range(FRAMES):
        f = ds[i]
        m.integrate(f["depth"], f["color"], f["intrinsics"], f["pose"])
    vertices, triangles, colors, normals = m.mesh(by="rgb")
    assert len(triangles) > 10_000

    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices.astype(np.float64)),
        o3d.utility.Vector3iVector(triangles.astype(np.int32)),
    )
    mesh.vertex_colors = o3d.utility.Vector3dVector(colors / 255.0)
    mesh.vertex_normals = o3d.utility.Vector3dVector(normals.astype(np.float64))
    assert len(mesh.vertices) == len(vertices)
    assert len(mesh.triangles) == len(triangles)
    assert len(mesh.vertex_colors) == len(mesh.vertex_normals) == len(vertices)
    assert mesh.has_vertex_colors() and mesh.has_vertex_normals()
    # The same numbers come back out.
    assert np.array_equal(np.asarray(mesh.triangles), triangles.astype(np.int32))
    assert np.array_equal(np.asarray(mesh.vertices), vertices.astype(np.float64))
    box = mesh.get_axis_aligned_bounding_box()
    assert np.allclose(box.get_min_bound(), vertices.min(axis=0), atol=1e-6)
    assert np.allclose(box.get_max_bound(), vertices.max(axis=0), atol=1e-6)
    # Open3D reads the triangles as we index them: its area is ours.
    a, b, c = (vertices[triangles[:, k]].astype(np.float64) for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    assert abs(mesh.get_surface_area() - area) < 1e-6 * area
    # voxpan welds its block meshes: no two vertices at the same place.
    welded = o3d.geometry.TriangleMesh(mesh).remove_duplicated_vertices()
    assert len(welded.vertices) == len(vertices)
    # Winding and normals agree: Open3D's face normals point along voxpan's vertex normals.
    mesh.compute_triangle_normals()
    faces = np.asarray(mesh.triangle_normals)
    along = np.einsum("ij,ij->i", faces, normals[triangles].mean(axis=1))
    assert (along > 0).mean() > 0.99
