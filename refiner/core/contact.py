"""Ground contact: heights along the up axis, the joints that touch the ground, and planted feet.

A foot (:func:`foot_joints`) is *planted* in a frame when it is within ``height``
metres of the lowest point that foot reaches nearby and does not swing, and a step between two frames is a
planted step when it is planted in both. Real HumanAct12 clips keep planted feet nearly still;
generated clips and gliding bodies do not, so the slip of planted feet is both evidence of a
flaw and the correction for it (:func:`refiner.refinement.repair_candidates.planted_feet_run`).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import minimum_filter1d, uniform_filter1d

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton

__all__ = ["heights", "contact_joints", "foot_joints", "planted_feet", "planted_slip", "glide_steps", "skating", "horizontal", "on_ground_as", "PLANTED_HEIGHT",
           "PLANTED_WINDOW", "PLANTED_SPEED", "SKATING_WINDOW"]

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


#: Metres above a foot's lowest point nearby (:data:`PLANTED_WINDOW`) within which it counts as planted.
PLANTED_HEIGHT = 0.05
#: Frames (2 s at 20 fps) over which that lowest point is taken. A floor slopes and mocap drifts (a CMU walk's toes
#: settle 7 cm lower over 6 s), so the clip's single lowest point missed later steps; None: the whole clip.
PLANTED_WINDOW = 41
#: Metres per frame a planted foot stays under (1.4 m/s at 20 fps): a swinging foot skims the ground at 10-25 cm
#: per frame in a walk, and read as planted it pushed the body back (up to 18 cm); None: no limit.
PLANTED_SPEED = 0.07
#: Steps over which :func:`skating` sums the glide (half a second at 20 fps).
SKATING_WINDOW = 10


def planted_feet(joints: np.ndarray, skeleton: str | Skeleton, height: float = PLANTED_HEIGHT, *,
                 window: int | None = PLANTED_WINDOW, speed: float | None = PLANTED_SPEED) -> np.ndarray:
    """``(..., T, F)`` bool: which foot is planted in which frame of joints ``(..., T, J, 3)`` metres: within
    ``height`` of its lowest point over ``window`` frames centred there, moving under ``speed`` metres per frame
    in the steps to and from the frame."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)[..., list(foot_joints(skel)), :]
    h = heights(x, skel)  # (..., T, F)
    low = h.min(-2, keepdims=True) if window is None else minimum_filter1d(h, size=int(window), axis=-2, mode="nearest")
    planted = (h - low) < height
    if speed is not None and x.shape[-3] > 1:
        v = np.linalg.norm(np.diff(x, axis=-3), axis=-1)  # (..., T-1, F)
        planted &= np.maximum(np.concatenate([v[..., :1, :], v], -2), np.concatenate([v, v[..., -1:, :]], -2)) < speed
    return planted


def planted_slip(joints: np.ndarray, skeleton: str | Skeleton, height: float = PLANTED_HEIGHT) -> np.ndarray:
    """``(..., T - 1, 3)`` metres: the mean horizontal displacement of the feet planted in both frames of
    each step of joints ``(..., T, J, 3)``; zero where no foot is planted."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)
    feet = list(foot_joints(skel))
    planted = planted_feet(x, skel, height)
    both = (planted[..., 1:, :] & planted[..., :-1, :])[..., None]  # (..., T-1, F, 1)
    step = horizontal(np.diff(x[..., feet, :], axis=-3), skel)
    n = both.sum(-2)
    return np.where(n > 0, (step * both).sum(-2) / np.maximum(n, 1), 0.0)


def glide_steps(joints: np.ndarray, skeleton: str | Skeleton) -> np.ndarray:
    """``(..., T - 1, 3)`` metres: the part of each step's planted slip (:func:`planted_slip`) that the root shares.

    Along the slip, the smaller of the slip's and the root's horizontal step, times the cosine between them (none
    when they part): a body that glides moves root and planted feet alike, while a wrong pose, a pivot or a
    shuffle moves the feet against the root.
    """
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)
    slip = planted_slip(x, skel)
    step = horizontal(np.diff(x[..., skel.root, :], axis=-2), skel)
    s_norm, r_norm = np.linalg.norm(slip, axis=-1), np.linalg.norm(step, axis=-1)
    cos = (slip * step).sum(-1) / np.maximum(s_norm * r_norm, 1e-12)
    return slip / np.maximum(s_norm, 1e-12)[..., None] * (np.minimum(s_norm, r_norm) * np.clip(cos, 0.0, 1.0))[..., None]


def skating(joints: np.ndarray, skeleton: str | Skeleton, window: int = SKATING_WINDOW) -> np.ndarray:
    """``(..., T - 1)`` metres: how far the body glides over its planted feet in the ``window`` steps centred on
    each step (the length of the summed :func:`glide_steps`). Real clips: under 9-11 cm in 99 % of them."""
    g = glide_steps(joints, skeleton)
    return np.linalg.norm(uniform_filter1d(g, int(window), axis=-2, mode="constant") * int(window), axis=-1)


def on_ground_as(joints: np.ndarray, like: np.ndarray, skeleton: str | Skeleton) -> np.ndarray:
    """``joints (..., T, J, 3)`` metres moved along the up axis, frame by frame, so that each frame's lowest
    ground-contact joint (:func:`contact_joints`) is as high as in ``like`` (same shape): a pose edited about the
    root (its motion scaled, say) keeps the feet where they met the ground, neither lifted nor pushed into it."""
    skel = get_skeleton(skeleton)
    feet = list(contact_joints(skel))
    lift = heights(np.asarray(joints)[..., feet, :], skel).min(-1) - heights(np.asarray(like)[..., feet, :], skel).min(-1)
    return (joints - lift[..., None, None] * skel.up_vector).astype(np.asarray(joints).dtype)


def horizontal(v: np.ndarray, skeleton: str | Skeleton) -> np.ndarray:
    """``v (..., 3)`` without its component along the skeleton's up axis."""
    up = get_skeleton(skeleton).up_vector
    return v - (v @ up)[..., None] * up
