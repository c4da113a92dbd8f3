"""Physical plausibility metrics on joint positions: smoothness, foot skating, ground contact, bones, splices.

Every function takes a :class:`~refiner.core.motion.Motion`, or joint positions ``(T, J, 3)`` / ``(B, T, J, 3)``
in metres in a registered skeleton's frame, and returns SI units (m, m/s, m/s², m/s³); a batch gives
one value per clip. The vertical comes from :attr:`Skeleton.up` (HumanAct12 and UESTC are y **down**,
HumanML3D and CMU y up); *height* is the coordinate along it.

This module has smoothness (acceleration, jerk, acceleration error), bone-length variation and the
velocity jump at splices; the feet-and-ground metrics (ground estimate, foot skating, penetration,
floating) are :mod:`refiner.evaluation.ground_metrics` and the contact joints
:mod:`refiner.core.contact`, all of them importable from here too. How inputs are read:
:mod:`refiner.evaluation.clip_batch`.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from refiner.core.contact import contact_joints, foot_joints, heights
from refiner.core.skeletons import Skeleton
from refiner.evaluation.clip_batch import as_clip_batch, per_clip
from refiner.evaluation.ground_metrics import (
    floating,
    foot_skate_distance,
    foot_skating_ratio,
    ground_height,
    penetration,
)

__all__ = [
    "heights",
    "contact_joints",
    "foot_joints",
    "ground_height",
    "acceleration",
    "jerk",
    "acceleration_error",
    "foot_skating_ratio",
    "foot_skate_distance",
    "penetration",
    "floating",
    "bone_length_variation",
    "VelocityJump",
    "boundary_velocity_jump",
]


def acceleration(motion, *, skeleton: str | Skeleton = "humanact12", fps: float | None = None):
    """Mean joint acceleration magnitude.

    ``|x[t+1] - 2 x[t] + x[t-1]| * fps²`` averaged over interior frames and joints.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Metres, T >= 3.
    skeleton : str or Skeleton, default="humanact12"
        Ignored for a Motion.
    fps : float, optional
        Frames per second; default the Motion's, else the skeleton's (20).

    Returns
    -------
    float, or ndarray of shape (B,)
        m/s².
    """
    return _mean_difference(motion, 2, skeleton, fps)


def jerk(motion, *, skeleton: str | Skeleton = "humanact12", fps: float | None = None):
    """Mean joint jerk magnitude: third finite difference times fps³, averaged (T >= 4).

    Returns
    -------
    float, or ndarray of shape (B,)
        m/s³.
    """
    return _mean_difference(motion, 3, skeleton, fps)


def _mean_difference(motion, order: int, skeleton, fps):
    """Mean joint magnitude of the ``order``-th finite difference times ``fps**order`` (T > order)."""
    x, _, rate, single = as_clip_batch(motion, skeleton, fps, min_frames=order + 1)
    d = np.linalg.norm(np.diff(x, order, axis=1), axis=-1) * rate**order
    return per_clip(d.mean(axis=(1, 2)), single)


def acceleration_error(pred, target, *, skeleton: str | Skeleton = "humanact12", fps: float | None = None):
    """Acceleration error (SmoothNet, MEVA): mean ``|acc_pred - acc_target|`` over frames and joints.

    Parameters
    ----------
    pred, target : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Same shape, metres, T >= 3.
    fps : float, optional
        Default ``pred``'s (Motion) or the skeleton's.

    Returns
    -------
    float, or ndarray of shape (B,)
        m/s².
    """
    a, _, rate, single = as_clip_batch(pred, skeleton, fps, min_frames=3)
    b, _, _, _ = as_clip_batch(target, skeleton, rate, min_frames=3)
    if a.shape != b.shape:
        raise ValueError(f"`pred` and `target` must share a shape; got {a.shape[1:]} and {b.shape[1:]}.")
    err = np.linalg.norm(np.diff(a, 2, axis=1) - np.diff(b, 2, axis=1), axis=-1) * rate**2
    return per_clip(err.mean(axis=(1, 2)), single)


def bone_length_variation(motion, *, skeleton: str | Skeleton = "humanact12", per_bone: bool = False):
    """Bone-length variation: per bone, the standard deviation of its length over time over its mean.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
    per_bone : bool, default=False
        Return every bone's value instead of the mean over bones.

    Returns
    -------
    float or ndarray of shape (B,), or with ``per_bone`` ndarray of shape (J-1,) or (B, J-1)
        Dimensionless (0 for a rigid skeleton; 0.05 = lengths vary by 5 %). Bones of zero mean length
        give NaN.
    """
    x, skel, _, single = as_clip_batch(motion, skeleton, None, min_frames=1)
    lengths = skel.bone_lengths(x)  # (B, T, J-1)
    mean = lengths.mean(1)
    cv = np.divide(lengths.std(1), mean, out=np.full_like(mean, np.nan), where=mean > 1e-9)
    if per_bone:
        return cv[0] if single else cv
    return per_clip(cv.mean(-1), single)


class VelocityJump(NamedTuple):
    """Velocity discontinuity at the boundaries of edited frames (see :func:`boundary_velocity_jump`).

    Attributes
    ----------
    jump : float
        Largest velocity change at a boundary, m/s.
    reference : float
        The clip's own velocity changes away from the boundaries (their ``quantile``), m/s.
    ratio : float
        ``jump / reference``; above 1 means the splice is rougher than that share of the clip.
    """

    jump: float
    reference: float
    ratio: float


def boundary_velocity_jump(
    motion,
    mask,
    *,
    skeleton: str | Skeleton = "humanact12",
    fps: float | None = None,
    quantile: float = 0.95,
) -> VelocityJump:
    """Velocity jump where edited frames meet unedited ones, against the clip's own velocity changes.

    The velocity change at frame ``t`` is ``s(t) = max_j |x[t+1,j] - 2 x[t,j] + x[t-1,j]| * fps``: how
    much the fastest-changing joint's velocity (m/s) changes across that frame. A boundary lies
    between frames ``b`` and ``b+1`` where ``mask[b] != mask[b+1]``; a splice there shows up in
    ``s(b)`` and ``s(b+1)``. ``jump`` is the largest ``s`` at any boundary frame, ``reference`` the
    ``quantile`` of ``s`` over all other interior frames.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3)
        One clip, metres, T >= 3.
    mask : array-like of bool, shape (T,)
        True at frames that were changed (e.g. by a refiner or a corruption).
    skeleton : str or Skeleton, default="humanact12"
    fps : float, optional
    quantile : float in [0, 1], default=0.95

    Returns
    -------
    VelocityJump
        All NaN when the mask has no boundary; ``reference`` (and ``ratio``) NaN when every interior
        frame touches a boundary. ``ratio`` is inf for a jump in an otherwise unaccelerated clip.
    """
    x, _, rate, single = as_clip_batch(motion, skeleton, fps, min_frames=3)
    if not single:
        raise ValueError(f"`motion` must be one clip (T, J, 3); got a batch of {len(x)}.")
    if not 0.0 <= quantile <= 1.0:
        raise ValueError(f"`quantile` must be in [0, 1]; got {quantile!r}.")
    n_frames = x.shape[1]
    m = np.asarray(mask)
    if m.shape != (n_frames,) or m.dtype != bool:
        raise ValueError(f"`mask` must be a boolean array of shape ({n_frames},); got {m.dtype} {m.shape}.")
    s = np.zeros(n_frames)
    s[1:-1] = np.linalg.norm(np.diff(x[0], 2, axis=0), axis=-1).max(-1) * rate
    boundaries = np.flatnonzero(m[1:] != m[:-1])
    if boundaries.size == 0:
        return VelocityJump(float("nan"), float("nan"), float("nan"))
    near = np.zeros(n_frames, dtype=bool)
    near[boundaries] = near[boundaries + 1] = True
    near[[0, -1]] = False
    interior = np.zeros(n_frames, dtype=bool)
    interior[1:-1] = True
    jump = float(s[near].max()) if near.any() else 0.0
    others = s[interior & ~near]
    if others.size == 0:
        return VelocityJump(jump, float("nan"), float("nan"))
    reference = float(np.quantile(others, quantile))
    ratio = jump / reference if reference > 0 else (float("inf") if jump > 0 else 0.0)
    return VelocityJump(jump, reference, float(ratio))
