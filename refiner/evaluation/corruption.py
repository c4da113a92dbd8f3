"""What every seeded flaw shares: the :class:`Corruption` it returns, the severities, and its set-up and write-back.

A flaw family (:mod:`refiner.evaluation.anchor_flaws`, :mod:`refiner.evaluation.transition_flaws`,
:mod:`refiner.evaluation.ground_flaws`; the registry is :mod:`refiner.evaluation.flaws`) validates its
input and draws its random choices through :func:`prepare_corruption`, and writes its result through
:func:`finish_corruption`, so untouched frames stay bit-identical to the input.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from refiner.concepts.segmentation import Segmentation, segment
from refiner.core.motion import Motion
from refiner.core.validation import check_random_state

__all__ = ["Corruption", "SEVERITIES", "MIN_FRAMES", "prepare_corruption", "finish_corruption"]

SEVERITIES = (1, 2, 3)
#: Fewest frames a clip needs to be corrupted.
MIN_FRAMES = 8


class Corruption(NamedTuple):
    """A corrupted clip and where it was corrupted.

    Attributes
    ----------
    motion : Motion
        The corrupted clip (same length, skeleton, fps and action as the input).
    mask : ndarray of bool, shape (T,)
        True at the frames the corruption touched; all other frames equal the input exactly.
    """

    motion: Motion
    mask: np.ndarray


def prepare_corruption(motion, severity, random_state, segmentation, penalty, *, need_anchors: bool = True):
    """Validated Motion, float64 joints, anchors (None unless needed), rng and the severity's table index (0-2)."""
    if isinstance(severity, (bool, np.bool_)) or severity not in SEVERITIES:
        raise ValueError(f"`severity` must be one of {SEVERITIES}; got {severity!r}.")
    m = motion if isinstance(motion, Motion) else Motion(motion)
    if m.n_frames < MIN_FRAMES:
        raise ValueError(f"`motion` is too short to corrupt: needs at least {MIN_FRAMES} frames; got {m.n_frames}.")
    if segmentation is not None and (
        not isinstance(segmentation, Segmentation) or segmentation.n_frames != m.n_frames
    ):
        raise ValueError(f"`segmentation` must be a Segmentation of this {m.n_frames}-frame clip.")
    anchors = None
    if need_anchors:
        seg = segmentation if segmentation is not None else segment(m.joints, penalty=penalty)
        anchors = np.asarray(seg.anchors)
    rng = check_random_state(random_state)
    return m, m.joints.astype(np.float64), anchors, rng, int(severity) - 1


def finish_corruption(m: Motion, x: np.ndarray, new: np.ndarray, mask: np.ndarray) -> Corruption:
    """Write ``new`` into the masked frames only, so untouched frames stay bit-identical."""
    out = m.numpy()
    out[mask] = new[mask].astype(np.float32)
    mask = mask.copy()
    mask.flags.writeable = False
    return Corruption(m.with_joints(out), mask)
