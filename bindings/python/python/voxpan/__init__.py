"""voxpan from Python: RGB-D panoptic mapping with numpy arrays in and out.

The work is done by voxpan's Rust libraries (the extension module ``voxpan._native``) with the
GIL released; this package only re-exports it and groups the evaluation under ``voxpan.eval``.
"""

from ._native import (
    Dataset as Dataset,
    PanopticMap as PanopticMap,
    VoxpanError as VoxpanError,
    fill_holes as fill_holes,
    kde as kde,
    open_dataset as open_dataset,
    refine as refine,
    trim_stuff_planes as trim_stuff_planes,
)
from . import eval as eval  # noqa: A004 (voxpan.eval, as the issue names it)

__all__ = [
    "Dataset",
    "PanopticMap",
    "VoxpanError",
    "eval",
    "fill_holes",
    "kde",
    "open_dataset",
    "refine",
    "trim_stuff_planes",
]
