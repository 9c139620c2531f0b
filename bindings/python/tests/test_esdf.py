"""The distance field against independent references: SciPy's exact Euclidean distance
transform of the same sites, and Open3D's exact distance to the fused mesh; and its queries
on an analytic scene."""

import numpy as np
import pytest

import voxpan

# Flat frames mapped for the data tests: a room and a half, in seconds.
FRAMES = 40


def wall_map(**kwargs):
    """A wall 1.5 m in front of a camera at the origin looking along +z."""
    m = voxpan.PanopticMap(esdf=True, **kwargs)
    w, h = 80, 60
    depth = np.full((h, w), 1.5, np.float32)
    color = np.full((h, w, 3), 128, np.uint8)
    m.integrate(depth, color, (40.0, 40.0, 40.0, 30.0), np.eye(4))
    m.update_esdf()
    return m


def test_distances_and_gradients_in_front_of_a_wall():
    m = wall_map(voxel_size=0.05)
    z = np.linspace(0.4, 1.3, 10)
    points = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
    d = m.distance(points)
    # Sites are the voxels within one voxel of the surface: distances are that close.
    assert np.all(np.abs(d - (1.5 - z)) <= 0.05 + 1e-6), d
    d2, g = m.distance_and_gradient(points)
    assert d2.shape == (10,) and g.shape == (10, 3)
    assert np.all(np.abs(d2 - (1.5 - z)) <= 0.05 + 1e-6), d2
    # Away from the wall is back towards the camera.
    assert np.all(g[:, 2] < -0.9), g
    # Behind the wall, and beside the camera's view, nothing was seen.
    unseen = m.distance(np.array([[0.0, 0.0, 3.0], [5.0, 0.0, 1.0]]))
    assert np.all(np.isnan(unseen))
    with pytest.raises(ValueError, match="points"):
        m.distance(np.zeros((4, 2)))


def flat_map(flat_dir, voxel_size):
    ds = voxpan.open_dataset(flat_dir)
    m = voxpan.PanopticMap(voxel_size=voxel_size, esdf=True)
    for i in range(FRAMES):
        f = ds[i]
        m.integrate(f["depth"], f["color"], f["intrinsics"], f["pose"])
    m.update_esdf()
    return m


@pytest.fixture(scope="module")
def flat_2cm(flat_dir):
    return flat_map(flat_dir, 0.02)


def test_flat_distances_match_scipys_exact_transform(flat_2cm):
    scipy_ndimage = pytest.importorskip("scipy.ndimage")
    m = flat_2cm
    voxel = m.config["tsdf"]["voxel_size"]
    reach = m.config["esdf"]["max_distance"]
    indices, distances = m.esdf_voxels()
    low = indices.min(axis=0)
    shape = tuple(indices.max(axis=0) - low + 1)
    sites = np.zeros(shape, bool)
    at = tuple((indices - low).T)
    sites[at] = distances == 0
    # The exact distance from every voxel centre to the nearest site centre.
    exact = scipy_ndimage.distance_transform_edt(~sites)[at] * voxel
    exact = np.minimum(exact, reach)
    ours = np.abs(distances)
    within = np.abs(ours - exact) <= voxel
    share = within.mean()
    print(f"{len(ours)} voxels: {100 * share:.2f} % within one voxel of SciPy's exact transform")
    assert share >= 0.99, share
    # Where they differ the field is never nearer than the truth (a real site's distance)...
    assert np.all(ours >= exact - 1e-4)


def test_flat_distances_match_open3ds_distance_to_the_mesh(flat_2cm, open3d):
    o3d = open3d
    m = flat_2cm
    voxel = m.config["tsdf"]["voxel_size"]
    vertices, triangles, _, _ = m.mesh()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32))
    )
    # Random points in the observed free space within the field's reach.
    indices, distances = m.esdf_voxels()
    rng = np.random.default_rng(7)
    free = indices[(distances > 0.1) & (distances < 1.0)]
    picked = free[rng.choice(len(free), 20_000, replace=False)]
    points = (picked + rng.uniform(0.0, 1.0, picked.shape)) * voxel
    ours, _ = m.distance_and_gradient(points)
    keep = ~np.isnan(ours)
    mesh = scene.compute_distance(o3d.core.Tensor(points[keep].astype(np.float32))).numpy()
    error = ours[keep] - mesh
    median, p95 = np.median(np.abs(error)), np.percentile(np.abs(error), 95)
    print(f"{keep.sum()} points: |field - mesh distance| median {median / voxel:.2f} voxels, "
          f"95th percentile {p95 / voxel:.2f}")
    # Sites lie within half a voxel of the zero crossing (or are the nearer voxel of the pair
    # it passes between): distances to their centres read that much short, not more.
    assert median <= 0.5 * voxel and p95 <= voxel, (median, p95)


def test_costmap_from_python(flat_2cm):
    c = flat_2cm.costmap(-0.9, 0.5)
    occupancy = c["occupancy"]
    assert occupancy.dtype == np.int8 and occupancy.ndim == 2
    values = set(np.unique(occupancy).tolist())
    assert values == {-1, 0, 100}, values
    assert flat_2cm.costmap(50.0, 51.0) is None


def test_costmap_files_read_back_with_an_independent_reader(flat_2cm, voxpan_bin, tmp_path):
    """`voxpan costmap` writes what map_server reads: Pillow decodes the PGM to the same
    cells as the library's occupancy grid, and the YAML names it with the grid's origin."""
    import subprocess

    from PIL import Image

    path = tmp_path / "map.voxpan"
    flat_2cm.save(path)
    out = tmp_path / "costmap"
    subprocess.run(
        [str(voxpan_bin), "costmap", str(path), "--out", str(out), "--min-z", "-0.9",
         "--max-z", "0.5"],
        check=True, capture_output=True,
    )
    grid = flat_2cm.costmap(-0.9, 0.5)
    image = np.asarray(Image.open(out / "costmap.pgm"))
    # Images run top-down; the grid's row 0 is its lowest y.
    expected = np.select(
        [grid["occupancy"] == 100, grid["occupancy"] == 0], [0, 254], 205
    )[::-1]
    assert image.shape == expected.shape and np.array_equal(image, expected)
    fields = dict(
        line.split(": ", 1) for line in (out / "costmap.yaml").read_text().splitlines()
    )
    assert fields["image"] == "costmap.pgm" and fields["mode"] == "trinary"
    assert float(fields["resolution"]) == grid["resolution"]
    origin = [float(v) for v in fields["origin"].strip("[]").split(",")]
    assert np.allclose(origin[:2], grid["origin"]) and origin[2] == 0.0
