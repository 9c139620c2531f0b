"""The Python API on small synthetic inputs: results, and arguments refused with ValueError."""

import numpy as np
import pytest

import voxpan

H, W = 60, 80
K = (40.0, 40.0, 40.0, 30.0)


def box_scene():
    """A box at 1 m in front of a wall at 2 m (1 mm noise); its mask bleeds 6 px onto the wall."""
    rng = np.random.default_rng(7)
    depth = np.full((H, W), 2.0, np.float32)
    depth[20:40, 30:50] = 1.0
    depth += rng.normal(0.0, 0.001, (H, W)).astype(np.float32)
    labels = np.zeros((H, W), np.uint16)
    labels[14:46, 24:56] = 1
    return depth, labels


def test_refine_removes_the_bleed_only():
    depth, labels = box_scene()
    refined, reports = voxpan.refine(depth, labels, things=[1])
    assert refined.dtype == np.uint16 and refined.shape == (H, W)
    assert (refined[20:40, 30:50] == 1).all()
    assert (refined[depth > 1.5] == 0).all()
    (r,) = reports
    assert r["id"] == 1 and r["removed"] == 32 * 32 - 20 * 20
    assert r["status"]["status"] == "refined" and r["low"] <= 1.0 <= r["high"]
    # The input is not modified.
    assert (labels[14:46, 24:56] == 1).all()


def test_refine_rules_and_segments():
    depth, labels = box_scene()
    for rule in ["none", "paper", "release", "default"]:
        voxpan.refine(depth, labels, rule=rule)
    seg = [{"id": 1, "is_thing": False, "class_id": 3}]
    refined, reports = voxpan.refine(depth, labels, segments=seg, things_only=True)
    assert reports[0]["status"]["reason"] == "not_a_thing"
    assert (refined == labels).all()
    with pytest.raises(ValueError, match="rule"):
        voxpan.refine(depth, labels, rule="magic")
    with pytest.raises(ValueError, match="segments"):
        voxpan.refine(depth, labels, segments=[{"id": "x"}])


def test_trim_gives_the_bleed_on_the_wall_to_the_wall():
    # The box scene with the wall as a stuff segment (id 2) around the box's mask (id 1):
    # the mask's 6 px on the wall plane go to the wall, the box keeps its pixels.
    depth, labels = box_scene()
    labels[labels == 0] = 2
    seg = [{"id": 1, "is_thing": True}, {"id": 2, "is_thing": False}]
    trimmed, reports = voxpan.trim_stuff_planes(depth, labels, seg)
    assert trimmed.dtype == np.uint16 and trimmed.shape == (H, W)
    assert (trimmed[20:40, 30:50] == 1).all()
    bleed = (labels == 1) & (depth > 1.5)
    assert (trimmed[bleed] == 2).mean() > 0.97  # 2.5 sigma keeps 98.8 % of a plane's pixels
    (r,) = reports
    assert r["id"] == 1 and r["removed"] == r["on_stuff"] == int((trimmed[bleed] == 2).sum())
    with pytest.raises(ValueError, match="labels"):
        voxpan.trim_stuff_planes(depth, labels[:, :-1].copy(), seg)


def test_kde_matches_a_normal_density():
    rng = np.random.default_rng(1)
    values = rng.normal(0.0, 1.0, 5000)
    grid, density, bw = voxpan.kde(values)
    assert grid.shape == density.shape and len(grid) >= 1024
    assert 0.05 < bw < 0.5
    peak = grid[np.argmax(density)]
    assert abs(peak) < 0.2
    assert abs(np.trapezoid(density, grid) - 1.0) < 0.01
    _, _, bw32 = voxpan.kde(values.astype(np.float32), method="kdepy")
    assert bw32 > 0
    with pytest.raises(ValueError, match="values"):
        voxpan.kde(np.ones(10))
    with pytest.raises(ValueError, match="method"):
        voxpan.kde(values, method="silverman")


def test_fill_holes():
    depth = np.full((H, W), 1.5, np.float32)
    depth[10, 10] = 0.0
    depth[20, 20] = np.nan
    filled = voxpan.fill_holes(depth, k=5)
    assert filled[10, 10] == pytest.approx(1.5) and filled[20, 20] == pytest.approx(1.5)
    assert depth[10, 10] == 0.0  # a new array
    with pytest.raises(ValueError, match="k"):
        voxpan.fill_holes(depth, k=0)


def test_eval_masks():
    gt = np.repeat(np.arange(4, dtype=np.uint16), 20)[None, :].repeat(H, 0)
    s = voxpan.eval.masks(gt + 5, gt)
    assert s["pq"] == 100.0 and s["frames"] == 1
    s = voxpan.eval.masks([gt + 5, np.zeros_like(gt)], [gt, gt])
    assert s["frames"] == 2 and s["tp"] == 4
    with pytest.raises(ValueError, match="gt"):
        voxpan.eval.masks(gt, gt[:10])


def wall_frame():
    depth = np.full((H, W), 1.5, np.float32)
    color = np.full((H, W, 3), 200, np.uint8)
    labels = np.ones((H, W), np.uint16)
    return depth, color, labels


def integrate_cabinet_by_halves(m):
    """Fuses a cabinet front filling the view into `m`, segmented as its left half in two
    frames, then as its right half in two more (the other half void)."""
    depth, color, _ = wall_frame()
    seg = [{"id": 1, "class_id": 30, "is_thing": True}]
    for half in (0, 0, 1, 1):
        labels = np.zeros((H, W), np.uint16)
        labels[:, half * W // 2 : (half + 1) * W // 2] = 1
        m.integrate(depth, color, K, np.eye(4), labels=labels, segments=seg)


def test_consolidate_joins_an_object_segmented_one_half_at_a_time():
    # The cabinet cut in halves: two instances, one after.
    m = voxpan.PanopticMap(voxel_size=0.05, class_names={30: "cabinet"})
    integrate_cabinet_by_halves(m)
    assert m.instance_count == 2
    assert m.consolidate() == 1
    (inst,) = m.instances()
    assert inst["class_name"] == "cabinet" and m.consolidate() == 0


def test_a_map_consolidating_every_four_frames_joins_the_halves_itself():
    # The cabinet above in a map that consolidates after every fourth frame: one instance
    # after the fourth frame, with no call.
    m = voxpan.PanopticMap(voxel_size=0.05, class_names={30: "cabinet"}, consolidate_every=4)
    assert m.config["tracking"]["consolidate_every"] == 4
    integrate_cabinet_by_halves(m)
    assert m.instance_count == 1 and m.consolidate() == 0


def test_map_integrate_mesh_render_save_load(tmp_path):
    m = voxpan.PanopticMap(voxel_size=0.05, class_names={7: "wall"})
    depth, color, labels = wall_frame()
    seg = [{"id": 1, "class_id": 7, "is_thing": False}]
    for _ in range(2):
        report = m.integrate(depth, color, K, np.eye(4), labels=labels, segments=seg)
    assert report["integration"] is not None and m.block_count > 0
    v, t, c, n = m.mesh(by="instance")
    assert v.shape[1] == 3 and v.dtype == np.float32 and t.dtype == np.uint32
    assert c.shape == v.shape and c.dtype == np.uint8 and n.shape == v.shape
    assert len(t) > 100 and t.max() < len(v)
    (inst,) = m.instances()
    assert inst["class_name"] == "wall" and inst["voxels"] > 0
    view = m.render(K, np.eye(4), (W, H))
    assert view["depth"].shape == (H, W) and view["color"].shape == (H, W, 3)
    assert abs(view["depth"][30, 40] - 1.5) < 0.05 and view["instances"][30, 40] == inst["id"]
    path = tmp_path / "wall.voxpan"
    m.save(path)
    back = voxpan.PanopticMap.load(str(path))
    assert back.block_count == m.block_count
    assert len(back.mesh()[0]) == len(v)
    assert back.config["tsdf"]["voxel_size"] == 0.05


def test_map_hides_instances_under_min_voxels():
    depth, color, labels = wall_frame()
    labels[30, 40] = 2  # one pixel, 3.75 cm square on the wall: a few surface voxels
    seg = [
        {"id": 1, "class_id": 7, "is_thing": False},
        {"id": 2, "class_id": 3, "is_thing": True},
    ]
    sizes = {}
    for min_voxels in (None, 0):
        # Size alone hides here: instances show from their first frame.
        m = voxpan.PanopticMap(min_voxels=min_voxels, min_observations=1)
        m.integrate(depth, color, K, np.eye(4), labels=labels, segments=seg, identified=True)
        sizes[min_voxels] = {i["id"]: i["voxels"] for i in m.instances()}
        assert m.instance_count == len(sizes[min_voxels])
    assert 0 < sizes[0][2] < 12, sizes
    assert 2 not in sizes[None] and sizes[None][1] == sizes[0][1]


def test_map_errors():
    with pytest.raises(ValueError, match="voxel_size"):
        voxpan.PanopticMap(voxel_size=float("inf"))
    with pytest.raises(voxpan.VoxpanError, match="nowhere.voxpan"):
        voxpan.PanopticMap.load("/nowhere.voxpan")
    with pytest.raises(voxpan.VoxpanError, match="does not exist"):
        voxpan.open_dataset("/nowhere")
    m = voxpan.PanopticMap()
    depth, color, labels = wall_frame()
    with pytest.raises(ValueError, match="by"):
        m.mesh(by="depth")
    with pytest.raises(ValueError, match="pose"):
        m.integrate(depth, color, K, np.ones((4, 4)))
    with pytest.raises(ValueError, match="pose"):
        m.integrate(depth, color, K, np.eye(3))
    with pytest.raises(ValueError, match="intrinsics"):
        m.integrate(depth, color, (0.0, 40.0, 40.0, 30.0), np.eye(4))
    with pytest.raises(ValueError, match="segments"):
        m.integrate(depth, color, K, np.eye(4), segments=[])
    assert m.block_count == 0


BAD_DEPTHS = {
    "float64": np.full((H, W), 1.5),
    "int": np.ones((H, W), np.int32),
    "1-D": np.ones(H * W, np.float32),
    "3-D": np.ones((H, W, 1), np.float32),
    "empty": np.ones((0, W), np.float32),
    "strided": np.ones((H, 2 * W), np.float32)[:, ::2],
    "Fortran": np.asfortranarray(np.ones((H, W), np.float32)),
    "big-endian": np.ones((H, W), ">f4"),
    "list": [[1.0] * W] * H,
    "None": None,
}


@pytest.mark.parametrize("name", BAD_DEPTHS)
def test_bad_depth_arrays_raise_value_error(name):
    bad = BAD_DEPTHS[name]
    _, color, labels = wall_frame()
    with pytest.raises((ValueError, TypeError), match="depth"):
        voxpan.fill_holes(bad)
    with pytest.raises((ValueError, TypeError), match="depth"):
        voxpan.refine(bad, labels)
    with pytest.raises((ValueError, TypeError), match="depth"):
        voxpan.PanopticMap().integrate(bad, color, K, np.eye(4))


def test_bad_label_and_color_arrays_raise_value_error():
    depth, color, labels = wall_frame()
    m = voxpan.PanopticMap()
    for bad in [labels.astype(np.int64), labels.astype(np.uint8), labels[:, ::2], labels[:10]]:
        with pytest.raises(ValueError, match="labels"):
            voxpan.refine(depth, bad)
        with pytest.raises(ValueError, match="labels"):
            m.integrate(depth, color, K, np.eye(4), labels=bad)
    for bad in [color[..., :2], color.astype(np.float32), color[:, :, ::-1], color[:10]]:
        with pytest.raises(ValueError, match="color"):
            m.integrate(depth, bad, K, np.eye(4))
    for bad in [labels.astype(np.int32), labels[::2]]:
        with pytest.raises(ValueError, match="pred"):
            voxpan.eval.masks(bad, labels)
    assert m.block_count == 0


def two_part_wall_map(first_id, second_id, voxel_size=0.05):
    """A wall whose left 70 % is one object and the rest another, ids as given (fused as
    identified, so the ids are the map's instances)."""
    depth, color, _ = wall_frame()
    labels = np.full((H, W), second_id, np.uint16)
    labels[:, : W * 7 // 10] = first_id
    m = voxpan.PanopticMap(voxel_size=voxel_size)
    for _ in range(2):
        m.integrate(depth, color, K, np.eye(4), labels=labels, identified=True)
    return m


def test_voxel_pq():
    truth = two_part_wall_map(1, 2)
    s = voxpan.eval.voxel_pq(two_part_wall_map(7, 9), truth)
    # Other ids, same partition: a perfect score.
    assert (s["all"]["tp"], s["all"]["fp"], s["all"]["fn_"]) == (2, 0, 0)
    assert s["all"]["pq"] == pytest.approx(100.0) and s["objects"] == 2
    # The same object on both sides (one lock, not two).
    assert voxpan.eval.voxel_pq(truth, truth)["all"]["pq"] == pytest.approx(100.0)
    # One instance over both objects: it matches the larger one only.
    merged = voxpan.eval.voxel_pq(two_part_wall_map(3, 3), truth)
    assert (merged["all"]["tp"], merged["all"]["fn_"]) == (1, 1)
    assert merged["under_segmenting"] == 1 and merged["all"]["pq"] < 60
    with pytest.raises(ValueError, match="voxel size"):
        voxpan.eval.voxel_pq(two_part_wall_map(1, 2, voxel_size=0.04), truth)
    with pytest.raises(TypeError):
        voxpan.eval.voxel_pq(truth, None)
