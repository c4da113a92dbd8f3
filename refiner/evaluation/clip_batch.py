"""One clip or a batch of clips as the physical metrics read them: joints in metres with their skeleton and fps.

Every metric of :mod:`refiner.evaluation.physics` and :mod:`refiner.evaluation.ground_metrics` takes a
:class:`~refiner.core.motion.Motion`, or joint positions ``(T, J, 3)`` / ``(B, T, J, 3)`` in metres in a
registered skeleton's frame, and gives one value for a clip and one per clip for a batch.
"""
from __future__ import annotations

import numpy as np

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton
from refiner.core.validation import check_joints

__all__ = ["as_clip_batch", "per_clip", "horizontal"]


def as_clip_batch(x, skeleton, fps, *, min_frames: int = 2) -> tuple[np.ndarray, Skeleton, float, bool]:
    """``(B, T, J, 3)`` float64 joints, their Skeleton, the fps and whether ``x`` was a single clip.

    A Motion brings its own skeleton and fps (``fps`` overrides the latter); an array is checked
    against ``skeleton`` and gets its fps. Raises a ValueError for a clip under ``min_frames`` frames,
    a wrong shape, NaN or Inf, or a non-positive fps.
    """
    if isinstance(x, Motion):
        skel, rate = x.skeleton_info, x.fps if fps is None else fps
        arr, single = x.joints[None].astype(np.float64), True
        if len(arr[0]) < min_frames:
            raise ValueError(f"`motion` is too short: needs at least {min_frames} frames; got {len(arr[0])}.")
    else:
        skel = get_skeleton(skeleton)
        raw = np.asarray(x.detach().cpu() if hasattr(x, "detach") else x)
        single = raw.ndim == 3
        check_joints(raw[None] if single else raw, name="joints", skeleton=skel, min_frames=min_frames, batched=True)
        arr = np.array(raw[None] if single else raw, dtype=np.float64)  # validated above; keep float64 precision
        rate = skel.fps if fps is None else fps
    if not (isinstance(rate, (int, float, np.number)) and np.isfinite(rate) and rate > 0):
        raise ValueError(f"`fps` must be a positive number; got {rate!r}.")
    return arr, skel, float(rate), single


def per_clip(values: np.ndarray, single: bool):
    """A float for a single clip, else the ``(B,)`` array of values."""
    return float(values[0]) if single else values


def horizontal(x: np.ndarray, skel: Skeleton) -> np.ndarray:
    """``x`` (..., 3) with its component along the skeleton's up axis removed."""
    up = skel.up_vector
    return x - (x @ up)[..., None] * up
