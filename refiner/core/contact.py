"""Ground contact: heights along the up axis, the joints that touch the ground, and planted feet.

A foot (:func:`foot_joints`) is *planted* in a frame when it is within ``height``
metres of the lowest point that foot reaches in the clip, and a step between two frames is a
planted step when it is planted in both. Real HumanAct12 clips keep planted feet nearly still;
generated clips and gliding bodies do not, so the slip of planted feet is both evidence of a
flaw and the correction for it (:func:`refiner.refinement.repair_candidates.planted_feet_run`).
"""
from __future__ import annotations

import numpy as np

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton

__all__ = ["heights", "contact_joints", "foot_joints", "planted_feet", "planted_slip", "PLANTED_HEIGHT"]

_CONTACT_WORDS = ("ankle", "foot", "toe", "heel")


def heights(joints, skeleton: str | Skeleton = "humanact12") -> np.ndarray:
    """Height of every joint along the skeleton's up axis.

    Parameters
    ----------
    joints : Motion or array-like of shape (..., J, 3)
        Metres.
    skeleton : str or Skeleton, default="humanact12"
        Ignored for a Motion.

    Returns
    -------
    ndarray of shape (..., J)
        Metres, larger is higher (``-y`` for HumanAct12).
    """
    if isinstance(joints, Motion):
        skeleton, joints = joints.skeleton, joints.joints
    skel = get_skeleton(skeleton)
    return np.asarray(joints, dtype=np.float64) @ skel.up_vector


def contact_joints(skeleton: str | Skeleton) -> tuple[int, ...]:
    """Joints that can touch the ground: names containing ankle, foot, toe or heel."""
    skel = get_skeleton(skeleton)
    idx = tuple(j for j, n in enumerate(skel.joint_names) if any(w in n for w in _CONTACT_WORDS))
    if not idx:
        raise ValueError(f"skeleton {skel.name!r} has no ankle/foot/toe/heel joints; pass `feet` explicitly.")
    return idx


def foot_joints(skeleton: str | Skeleton) -> tuple[int, ...]:
    """The lowest joint of each foot: per side the first of foot, toe, heel, ankle that exists.

    HumanAct12 / HumanML3D: ``left_foot``, ``right_foot`` (SMPL 10, 11, as GMD); CMU: the toes; UESTC:
    the heels.
    """
    skel = get_skeleton(skeleton)
    out = []
    for side in ("left", "right"):
        for word in ("foot", "toe", "heel", "ankle"):
            if f"{side}_{word}" in skel.joint_names:
                out.append(skel.index(f"{side}_{word}"))
                break
    if len(out) != 2:
        raise ValueError(f"skeleton {skel.name!r} has no left/right foot joints; pass `feet` explicitly.")
    return tuple(out)


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
