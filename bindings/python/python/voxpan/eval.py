"""Evaluation with voxpan's protocols (see voxpan-eval)."""

from ._native import eval_masks as masks

__all__ = ["masks"]
