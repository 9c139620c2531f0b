"""Round trips against the command line on the flat sample: `voxpan.refine` equals
`voxpan refine` pixel for pixel, and mapping frames through `voxpan.PanopticMap` gives the map
`voxpan run` builds (blocks, mesh, instances, voxel panoptic quality)."""

import json
import subprocess

import numpy as np
import pytest
from PIL import Image

import voxpan

# Frame ids 0..38 of the sample (every 2nd frame of run1): 20 frames, seconds in a debug build.
FRAMES = "0:38"


def frame_selection(ds, spec):
    start, end = (int(x) for x in spec.split(":"))
    return [i for i, fid in enumerate(ds.frame_ids) if start <= int(fid) <= end]


def map_like_voxpan_run(ds, indices, rule="default", fill_k=5):
    """The per-frame recipe of `voxpan run` (crates/pipeline, crates/perception/perceive):
    the dataset's masks, trimmed off the stuff planes and refined on the measured depth; depth
    holes filled afterwards; segments matched with the map's instances and the frame fused;
    after the last frame, the map consolidated."""
    m = voxpan.PanopticMap(class_names=ds.class_names)
    for i in indices:
        f = ds[i]
        labels = None
        if "labels" in f:
            labels = f["labels"]
            if rule != "none":
                labels, _ = voxpan.trim_stuff_planes(f["depth"], labels, f["segments"])
            labels, _ = voxpan.refine(f["depth"], labels, rule=rule, segments=f["segments"])
        depth = voxpan.fill_holes(f["depth"], k=fill_k)
        m.integrate(depth, f["color"], f["intrinsics"], f["pose"], labels=labels,
                    segments=f.get("segments"))
    m.consolidate()
    return m


@pytest.mark.parametrize("rule", ["default", "paper"])
def test_refine_equals_cli_pixel_for_pixel(flat_dir, voxpan_bin, tmp_path, rule):
    ds = voxpan.open_dataset(flat_dir)
    changed = 0
    for index in [0, 17, 60]:
        f = ds[index]
        run = flat_dir / "run1"
        fid = f["id"]
        out = tmp_path / f"{fid}.png"
        cli = subprocess.run(
            [voxpan_bin, "refine", "--depth", run / f"{fid}_depth.tiff",
             "--segments", run / f"{fid}_predicted.png", "--labels", run / f"{fid}_labels.json",
             "--rule", rule, "--out", out, "--json"],
            check=True, capture_output=True, text=True,
        )
        cli_labels = np.asarray(Image.open(out)).astype(np.uint16)
        labels, reports = voxpan.refine(f["depth"], f["labels"], rule=rule,
                                        segments=f["segments"])
        assert labels.shape == cli_labels.shape
        assert np.array_equal(labels, cli_labels), f"frame {fid}: labels differ"
        assert reports == json.loads(cli.stdout)
        changed += int((labels != f["labels"]).sum())
    assert changed > 0, "refinement changed nothing: a weak test"


def test_map_equals_voxpan_run(flat_dir, voxpan_bin, tmp_path):
    out = tmp_path / "run"
    subprocess.run(
        [voxpan_bin, "run", flat_dir, "--out", out, "--frames", FRAMES, "--threads", "2"],
        check=True, capture_output=True,
    )
    ds = voxpan.open_dataset(flat_dir)
    indices = frame_selection(ds, FRAMES)
    assert len(indices) == 20
    ours = map_like_voxpan_run(ds, indices)

    theirs = voxpan.PanopticMap.load(out / "map.voxpan")
    assert ours.block_count == theirs.block_count > 1000
    v, t, c, _ = ours.mesh(by="rgb")
    with open(out / "mesh_rgb.ply", "rb") as ply:
        header = ply.read(4096).split(b"end_header")[0].decode()
    cli_vertices = int(header.split("element vertex ")[1].split()[0])
    cli_faces = int(header.split("element face ")[1].split()[0])
    assert (len(v), len(t)) == (cli_vertices, cli_faces)
    tv, tt, tc, _ = theirs.mesh(by="rgb")
    assert np.array_equal(v, tv) and np.array_equal(t, tt) and np.array_equal(c, tc)
    strip = lambda xs: [{k: x[k] for k in ("id", "class_id", "voxels", "frames_seen")} for x in xs]
    assert strip(ours.instances()) == strip(theirs.instances())
    assert ours.instance_count == theirs.instance_count > 5

    # Voxel panoptic quality against the tracker-free reference of the same frames: what
    # `voxpan run` writes into metrics.json, computed by the same library function from Python.
    reference = voxpan.eval.reference_map(ds, indices, like=ours)
    pq = voxpan.eval.voxel_pq(ours, reference)
    cli = json.loads((out / "metrics.json").read_text())["panoptic"]
    assert pq == cli
    assert 0 < pq["all"]["pq"] < 100 and pq["objects"] > 5
    assert voxpan.eval.voxel_pq(theirs, reference) == cli
    # `voxpan eval --3d` scores one map per rule against the same reference.
    rows = json.loads(subprocess.run(
        [voxpan_bin, "eval", flat_dir, "--3d", "--frames", FRAMES, "--json"],
        check=True, capture_output=True, text=True,
    ).stdout)["voxel"]
    assert pq == rows["default"]
    paper = voxpan.eval.voxel_pq(map_like_voxpan_run(ds, indices, rule="paper"), reference)
    assert paper == rows["paper"] and paper != pq


def test_dataset_frames(flat_dir):
    ds = voxpan.open_dataset(flat_dir)
    assert len(ds) == 100 and ds.kind == "flat" and ds.frame_ids[1] == "000002"
    f = ds[-1]
    assert f["depth"].dtype == np.float32 and f["depth"].shape == (480, 640)
    assert f["color"].shape == (480, 640, 3) and f["color"].dtype == np.uint8
    assert f["labels"].dtype == np.uint16 and f["ground_truth"].dtype == np.uint16
    assert f["pose"].shape == (4, 4) and f["intrinsics"] == (320.0, 320.0, 320.0, 240.0)
    assert {"id", "class_id", "is_thing"} <= set(f["segments"][0])
    assert sum(1 for _ in ds) == len(ds)
    with pytest.raises(IndexError):
        ds[100]
    s = voxpan.eval.masks(f["labels"], f["ground_truth"])
    assert 0 < s["pq"] < 100


def test_reference_map_arguments(flat_dir):
    ds = voxpan.open_dataset(flat_dir)
    with pytest.raises(IndexError, match="100"):
        voxpan.eval.reference_map(ds, [0, 100])
    with pytest.raises(ValueError, match="indices"):
        voxpan.eval.reference_map(ds, [])
    r = voxpan.eval.reference_map(ds, [0, -1], like=voxpan.PanopticMap(voxel_size=0.05))
    assert r.config["tsdf"]["voxel_size"] == 0.05 and r.block_count > 0
    assert voxpan.eval.voxel_pq(r, r)["all"]["pq"] == 100.0
