# Type stubs for the Rust extension (src/*.rs); voxpan/__init__.py re-exports these names.
from collections.abc import Iterator, Sequence
from os import PathLike
from typing import Any, Literal, Optional, Union

import numpy as np
import numpy.typing as npt

Intrinsics = Union[tuple[float, float, float, float], Sequence[Sequence[float]], npt.NDArray[Any]]
"""(fx, fy, cx, cy) or a 3x3 camera matrix K."""
Pose = Union[npt.NDArray[Any], Sequence[Sequence[float]]]
"""A 4x4 rigid T_world_camera (camera to world, optical frame: x right, y down, z forward)."""
Segment = dict[str, Any]
"""{"id": int, "class_id": int | None, "is_thing": bool | None, "score": float | None}"""

class VoxpanError(RuntimeError):
    """An error reported by voxpan's libraries (the message is theirs)."""

def refine(
    depth: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint16],
    rule: Literal["none", "paper", "release", "default"] = "default",
    things: Optional[Sequence[int]] = None,
    segments: Optional[Sequence[Segment]] = None,
    things_only: bool = False,
    kde: Optional[Literal["isj", "kdepy"]] = None,
) -> tuple[npt.NDArray[np.uint16], list[dict[str, Any]]]:
    """Refines every segment of `labels` (uint16 HxW, 0 = void) on the measured `depth`
    (float32 HxW, metres); removed pixels become 0. Returns the refined labels and one report
    per segment (id, pixels, valid_depth, kept, removed, low, high, bandwidth, status), as
    `voxpan refine --json`."""

def trim_stuff_planes(
    depth: npt.NDArray[np.float32],
    labels: npt.NDArray[np.uint16],
    segments: Sequence[Segment],
) -> tuple[npt.NDArray[np.uint16], list[dict[str, Any]]]:
    """Trims thing masks off the frame's stuff planes (`voxpan run`'s step after refinement):
    thing pixels on a plane fitted to a stuff segment go to that segment, unless the thing lies
    flat on the planes. Returns the labels and one report per thing (id, pixels, on_stuff,
    removed)."""

def kde(
    values: npt.NDArray[np.floating[Any]], method: Literal["isj", "kdepy"] = "isj"
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float]:
    """Density of 1-D `values` on a 1024-point grid: (grid, density, bandwidth)."""

def fill_holes(
    depth: npt.NDArray[np.float32], k: int = 5, sigma: Optional[float] = None
) -> npt.NDArray[np.float32]:
    """Depth with holes filled by a Gaussian-weighted average of valid neighbours (k x k)."""

def eval_masks(
    pred: Union[npt.NDArray[np.uint16], Sequence[npt.NDArray[np.uint16]]],
    gt: Union[npt.NDArray[np.uint16], Sequence[npt.NDArray[np.uint16]]],
) -> dict[str, Any]:
    """voxpan's 2-D mask protocol: frames, mean_matched_iou, pq, sq, rq, precision, recall
    (percent), tp, n_pred, n_gt."""

def voxel_pq(map: PanopticMap, reference: PanopticMap) -> dict[str, Any]:
    """Panoptic quality over voxels of `map`'s instances against `reference`'s objects (same
    voxel size), as `voxpan run` writes it into metrics.json ("panoptic") and
    `voxpan eval --3d --json` prints it: "all", "things", "stuff" (each pq, sq, rq in percent,
    tp, fp, fn_), instances, small_instances, objects, over_segmented, under_segmenting."""

def reference_map(
    dataset: Dataset,
    indices: Optional[Sequence[int]] = None,
    like: Optional[PanopticMap] = None,
) -> PanopticMap:
    """The tracker-free reference of `voxpan eval --3d`: the ground-truth segmentation of
    `indices` (default all frames) fused with its own ids, no association. `like`: a map whose
    configuration the reference takes (voxpan's defaults otherwise)."""

def open_dataset(path: Union[str, PathLike[str]]) -> Dataset:
    """Opens a flat (panoptic_mapping) or TUM RGB-D folder."""

class Dataset:
    """Frames loaded on access. Each frame is a dict: id, timestamp, depth (float32 HxW),
    color (uint8 HxWx3), pose (float64 4x4), intrinsics (fx, fy, cx, cy), size (w, h), and
    when present labels (uint16 HxW) with segments (list of dicts) and ground_truth."""

    def __len__(self) -> int: ...
    def __getitem__(self, index: int) -> dict[str, Any]: ...
    def __iter__(self) -> DatasetIter: ...
    @property
    def kind(self) -> str: ...
    @property
    def frame_ids(self) -> list[str]: ...
    @property
    def class_names(self) -> dict[int, str]: ...
    @property
    def skipped(self) -> list[tuple[str, str]]: ...

class DatasetIter(Iterator[dict[str, Any]]):
    def __iter__(self) -> DatasetIter: ...
    def __next__(self) -> dict[str, Any]: ...

class PanopticMap:
    """A panoptic TSDF map on hashed voxel blocks. None means voxpan's default (shown)."""

    def __init__(
        self,
        voxel_size: Optional[float] = 0.02,
        truncation_voxels: Optional[float] = 3.0,
        max_range: Optional[float] = 5.0,
        min_range: Optional[float] = 0.1,
        max_weight: Optional[float] = 10000.0,
        min_overlap: Optional[float] = 0.5,
        min_pixels: Optional[int] = 8,
        downscale: Optional[int] = 4,
        min_observations: Optional[int] = 2,
        min_voxels: Optional[int] = 12,
        merge_votes: Optional[int] = 2,
        class_aware_things: Optional[bool] = True,
        max_memory_gb: Optional[float] = None,
        class_names: Optional[dict[int, str]] = None,
        esdf: Optional[bool] = False,
        esdf_max_distance: Optional[float] = 2.0,
        consolidate_every: Optional[int] = 0,
    ) -> None: ...
    def integrate(
        self,
        depth: npt.NDArray[np.float32],
        color: npt.NDArray[np.uint8],
        intrinsics: Intrinsics,
        pose: Pose,
        labels: Optional[npt.NDArray[np.uint16]] = None,
        segments: Optional[Sequence[Segment]] = None,
        identified: bool = False,
    ) -> dict[str, Any]:
        """Fuses one frame (associating `labels`' segments with map instances first;
        with `identified=True` the label ids are the instances, shown once seen in
        `min_observations` frames: pass `min_observations=1` to show them at once);
        returns the frame report (integration, association, track_ms, integrate_ms)."""
    def mesh(
        self, by: Literal["rgb", "instance", "class"] = "rgb"
    ) -> tuple[
        npt.NDArray[np.float32],
        npt.NDArray[np.uint32],
        npt.NDArray[np.uint8],
        npt.NDArray[np.float32],
    ]:
        """(vertices Nx3, triangles Mx3, colors Nx3, normals Nx3) of the welded mesh."""
    def instances(self) -> list[dict[str, Any]]: ...
    def render(
        self, intrinsics: Intrinsics, pose: Pose, size: tuple[int, int]
    ) -> dict[str, npt.NDArray[Any]]:
        """Ray cast from a camera of `size` (width, height): depth, color, instances, normals."""
    def update_esdf(self) -> dict[str, int]:
        """Brings the distance field up to date (all blocks the first time, then the changed)."""
    def distance(self, points: npt.NDArray[np.floating[Any]]) -> npt.NDArray[np.float32]:
        """Signed distances (N,) at points Nx3, NaN where unobserved."""
    def distance_and_gradient(
        self, points: npt.NDArray[np.floating[Any]]
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """Trilinear signed distances (N,) and gradients Nx3, NaN where unobserved."""
    def esdf_voxels(self) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float32]]:
        """(voxel indices Mx3, signed distances (M,)) of every observed voxel; sites read 0."""
    def costmap(
        self, min_z: float, max_z: float, robot_radius: float = 0.0
    ) -> Optional[dict[str, Any]]:
        """occupancy (int8 rows x columns: 100, 0, -1), resolution, origin; None if empty."""
    def save(self, path: Union[str, PathLike[str]]) -> None: ...
    @staticmethod
    def load(path: Union[str, PathLike[str]]) -> PanopticMap: ...
    def consolidate(self) -> int:
        """Joins instances of any class meeting along a seam, not told apart; returns the merges."""
    def set_class_names(self, names: dict[int, str]) -> None: ...
    @property
    def block_count(self) -> int: ...
    @property
    def instance_count(self) -> int: ...
    @property
    def memory_bytes(self) -> int: ...
    @property
    def config(self) -> dict[str, dict[str, Any]]: ...
