"""The input protocol of the Action2Motion recognisers (``generator_formats.md`` §8.3).

Joint positions in metres in the dataset's **native frame** (HumanAct12: y down, facing -z), the
**root of the first frame of the crop subtracted** (the trajectory is kept; no per-frame centring, no
scaling, no normalisation), **60-frame crops** (100 for CMU-Mocap); clips shorter than that are
padded by repeating their last frame. Frames are flattened joint-major ``[j0x, j0y, j0z, j1x, ...]``
by :class:`~refiner.evaluation.action_recognizer.ActionRecognizer`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Iterable

import numpy as np
import torch

from refiner.core.motion import Motion
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_joints, check_random_state

if TYPE_CHECKING:
    from refiner.evaluation.action_recognizer import RecognizerConfig

__all__ = ["crop_clip", "prepare_clips"]

_CROPS = ("random", "start", "center")


def crop_clip(joints, n_frames: int = 60, start: int = 0) -> np.ndarray:
    """Frames ``start : start + n_frames`` of a clip, padded with its last frame when too short.

    Parameters
    ----------
    joints : ndarray of shape (T, J, 3)
    n_frames : int, default=60
    start : int, default=0
        First frame; clipped to ``[0, max(T - n_frames, 0)]``.

    Returns
    -------
    ndarray of shape (n_frames, J, 3), a new array (no root subtraction).
    """
    x = np.asarray(joints)
    start = int(min(max(start, 0), max(len(x) - n_frames, 0)))
    out = x[start : start + n_frames]
    if len(out) < n_frames:
        out = np.concatenate([out, np.repeat(out[-1:], n_frames - len(out), axis=0)])
    return np.array(out, copy=True)


def prepare_clips(motions, config: RecognizerConfig, *, crop: str = "random", random_state=None) -> np.ndarray:
    """Crop, pad, centre and scale clips for a recogniser (§8.3); see :meth:`ActionRecognizer.prepare`.

    Returns
    -------
    ndarray of shape (B, config.n_frames, J, 3), float32
    """
    if crop not in _CROPS:
        raise ValueError(f"`crop` must be one of {', '.join(_CROPS)}; got {crop!r}.")
    rng = check_random_state(random_state)
    skel = get_skeleton(config.skeleton)
    clips = _as_clip_list(motions, skel.name)
    out = np.empty((len(clips), config.n_frames, skel.n_joints, 3), dtype=np.float32)
    for i, clip in enumerate(clips):
        extra = len(clip) - config.n_frames
        if extra <= 0 or crop == "start":
            start = 0
        elif crop == "center":
            start = extra // 2
        else:
            start = int(rng.integers(extra + 1))
        c = crop_clip(clip, config.n_frames, start)
        out[i] = (c - c[:1, skel.root : skel.root + 1]) * config.input_scale
    return out


def _as_clip_list(motions, skeleton: str) -> list[np.ndarray]:
    """Validated ``(T, J, 3)`` float32 arrays from a Motion, Motions or a (B, T, J, 3) array."""
    if isinstance(motions, Motion):
        motions = [motions]
    if isinstance(motions, (np.ndarray, torch.Tensor)):
        arr = np.asarray(motions.detach().cpu() if isinstance(motions, torch.Tensor) else motions)
        if arr.ndim == 3:
            arr = arr[None]
        return list(check_joints(arr, name="motions", skeleton=skeleton, min_frames=1, batched=True))
    clips = []
    items = list(motions) if isinstance(motions, Iterable) else None
    if items is None:
        raise ValueError(f"`motions` must be a Motion, a sequence of Motion or a (B, T, J, 3) array; "
                         f"got {type(motions).__name__}.")
    if not items:
        raise ValueError("`motions` is empty.")
    for i, m in enumerate(items):
        if isinstance(m, Motion):
            if m.skeleton != skeleton:
                raise ValueError(f"clip {i} of {len(items)} is on skeleton {m.skeleton!r}; this recogniser reads "
                                 f"{skeleton!r} (convert it with an adapter first).")
            clips.append(m.joints)
        else:
            try:
                clips.append(check_joints(m, name="motions", skeleton=skeleton, min_frames=1))
            except ValueError as e:
                raise ValueError(f"clip {i} of {len(items)}: {e}") from e
    return clips
