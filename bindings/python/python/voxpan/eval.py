"""Evaluation with voxpan's protocols (see voxpan-eval): `masks`, the 2-D protocol of
`voxpan eval`; `voxel_pq` against a `reference_map`, the 3-D protocol of `voxpan eval --3d`."""

from ._native import eval_masks as masks
from ._native import reference_map as reference_map
from ._native import voxel_pq as voxel_pq

__all__ = ["masks", "reference_map", "voxel_pq"]
