"""Ground contact: heights along the up axis, the joints that touch the ground, the feet."""
from __future__ import annotations

import numpy as np

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton

__all__ = ["heights", "contact_joints", "foot_joints", "horizontal"]

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


def horizontal(v: np.ndarray, skeleton: str | Skeleton) -> np.ndarray:
    """``v (..., 3)`` without its component along the skeleton's up axis."""
    up = get_skeleton(skeleton).up_vector
    return v - (v @ up)[..., None] * up
