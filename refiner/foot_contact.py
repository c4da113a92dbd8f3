"""Planted feet and their slip: a foot that stays on the ground does not slide.

A foot (:func:`refiner.physics.foot_joints`) is *planted* in a frame when it is within ``height``
metres of the lowest point that foot reaches in the clip, and a step between two frames is a
planted step when it is planted in both. Real HumanAct12 clips keep planted feet nearly still;
generated clips and gliding bodies do not, so the slip of planted feet is both evidence of a
flaw and the correction for it (:func:`refiner.repair_candidates.planted_feet_run`).
"""
from __future__ import annotations

import numpy as np

from refiner.physics import foot_joints, heights
from refiner.skeletons import Skeleton, get_skeleton

__all__ = ["planted_feet", "planted_slip", "PLANTED_HEIGHT"]

#: Metres above a foot's lowest point within which it counts as planted.
PLANTED_HEIGHT = 0.03


def planted_feet(joints: np.ndarray, skeleton: str | Skeleton, height: float = PLANTED_HEIGHT) -> np.ndarray:
    """``(..., T, F)`` bool: which foot is planted in which frame of joints ``(..., T, J, 3)`` metres."""
    skel = get_skeleton(skeleton)
    h = heights(np.asarray(joints)[..., list(foot_joints(skel)), :], skel)  # (..., T, F)
    return (h - h.min(-2, keepdims=True)) < height


def planted_slip(joints: np.ndarray, skeleton: str | Skeleton, height: float = PLANTED_HEIGHT) -> np.ndarray:
    """``(..., T - 1, 3)`` metres: the mean horizontal displacement of the feet planted in both frames of
    each step of joints ``(..., T, J, 3)``; zero where no foot is planted."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)
    feet = list(foot_joints(skel))
    planted = planted_feet(x, skel, height)
    both = (planted[..., 1:, :] & planted[..., :-1, :])[..., None]  # (..., T-1, F, 1)
    step = np.diff(x[..., feet, :], axis=-3)
    up = skel.up_vector
    step = step - (step @ up)[..., None] * up
    n = both.sum(-2)
    return np.where(n > 0, (step * both).sum(-2) / np.maximum(n, 1), 0.0)
