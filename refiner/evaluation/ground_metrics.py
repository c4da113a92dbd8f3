"""Feet and ground: the ground estimate, foot skating, ground penetration and floating.

The vertical comes from :attr:`Skeleton.up` (HumanAct12 and UESTC are y **down**, HumanML3D and CMU y
up); *height* is the coordinate along it (:func:`refiner.core.contact.heights`). Inputs and outputs as
in :mod:`refiner.evaluation.physics`.

**Ground.** HumanAct12 gives no floor. Unless a ``ground`` height is passed, it is estimated per clip
as the lowest height any contact joint (ankles, feet, toes, heels) reaches over the clip,
:func:`ground_height` - the HumanML3D convention of putting the floor under the lowest foot. With that
estimate penetration is zero by construction for the feet, so to judge an edited clip pass the ground
of its source (``ground=ground_height(source)``), as ``motion-refiner bench flaws`` does.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d

from refiner.core.contact import contact_joints, foot_joints, heights
from refiner.core.skeletons import Skeleton
from refiner.evaluation.clip_batch import as_clip_batch, horizontal, per_clip

__all__ = [
    "ground_height",
    "foot_skating_ratio",
    "foot_skate_distance",
    "penetration",
    "floating",
]


def ground_height(motion, *, skeleton: str | Skeleton = "humanact12", quantile: float = 0.0):
    """Per-clip ground estimate: the lowest height the contact joints reach.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Metres.
    skeleton : str or Skeleton, default="humanact12"
        Ignored for a Motion.
    quantile : float in [0, 1], default=0.0
        Quantile over frames of each frame's lowest contact-joint height; 0 is the minimum (the
        HumanML3D floor convention), a small positive value ignores a few outlier frames.

    Returns
    -------
    float, or ndarray of shape (B,)
        Height of the ground in metres along the up axis (see :func:`heights`).
    """
    if not 0.0 <= quantile <= 1.0:
        raise ValueError(f"`quantile` must be in [0, 1]; got {quantile!r}.")
    x, skel, _, single = as_clip_batch(motion, skeleton, None, min_frames=1)
    low = heights(x[..., list(contact_joints(skel)), :], skel).min(-1)  # (B, T)
    return per_clip(np.quantile(low, quantile, axis=1), single)


def _ground(x, skel, ground) -> np.ndarray:
    """``(B,)`` ground heights: the given one(s) or the per-clip estimate."""
    if ground is None:
        return heights(x[..., list(contact_joints(skel)), :], skel).min(axis=(1, 2))
    g = np.asarray(ground, dtype=np.float64)
    if g.ndim == 0:
        g = np.full(len(x), float(g))
    if g.shape != (len(x),) or not np.isfinite(g).all():
        raise ValueError(f"`ground` must be a finite float or one per clip ({len(x)},); got {ground!r}.")
    return g


def _foot_contact(x, skel, feet, ground, height_threshold):
    """Foot indices, per-pair contact (B, F, T-1) and horizontal foot speed per frame (B, F, T-1), m/frame."""
    feet = list(foot_joints(skel) if feet is None else feet)
    if not feet or any(not 0 <= f < skel.n_joints for f in feet):
        raise ValueError(f"`feet` must be joint indices in 0..{skel.n_joints - 1}; got {feet!r}.")
    g = _ground(x, skel, ground)
    h = heights(x[:, :, feet], skel) - g[:, None, None]  # (B, T, F)
    low = h < height_threshold
    contact = (low[:, 1:] & low[:, :-1]).transpose(0, 2, 1)
    step = np.linalg.norm(horizontal(np.diff(x[:, :, feet], axis=1), skel), axis=-1).transpose(0, 2, 1)
    return contact, step


def foot_skating_ratio(
    motion,
    *,
    skeleton: str | Skeleton = "humanact12",
    fps: float | None = None,
    height_threshold: float = 0.05,
    speed_threshold: float = 0.5,
    window: int = 5,
    feet: Sequence[int] | None = None,
    ground=None,
):
    """Foot-skating ratio (GMD): the fraction of frame pairs in which a foot on the ground slides.

    For each pair of adjacent frames and each foot: the foot is *in contact* when its height above the
    ground is below ``height_threshold`` in both frames; it *skates* when, in contact, its horizontal
    speed exceeds ``speed_threshold`` both in that pair and averaged over ``window`` pairs (centred,
    zero-padded at the ends as GMD). A pair counts when either foot skates; the ratio divides by T - 1.
    GMD's numbers: 5 cm, 0.5 m/s (2.5 cm per frame at 20 fps), 5 frames; real HumanML3D clips score
    about 0.05, not 0.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
        Metres.
    skeleton : str or Skeleton, default="humanact12"
    fps : float, optional
    height_threshold : float, default=0.05
        Metres above the ground.
    speed_threshold : float, default=0.5
        m/s.
    window : int, default=5
        Frames of the speed average.
    feet : sequence of int, optional
        Foot joints; default :func:`foot_joints`.
    ground : float or array of shape (B,), optional
        Ground height along the up axis; default :func:`ground_height` of each clip.

    Returns
    -------
    float, or ndarray of shape (B,)
        In [0, 1].
    """
    if not isinstance(window, (int, np.integer)) or window < 1:
        raise ValueError(f"`window` must be a positive int; got {window!r}.")
    x, skel, rate, single = as_clip_batch(motion, skeleton, fps)
    contact, step = _foot_contact(x, skel, feet, ground, height_threshold)
    speed = step * rate
    mean_speed = uniform_filter1d(speed, size=int(window), axis=-1, mode="constant")
    skating = contact & (speed > speed_threshold) & (mean_speed > speed_threshold)
    return per_clip(skating.any(axis=1).mean(axis=-1), single)


def foot_skate_distance(
    motion,
    *,
    skeleton: str | Skeleton = "humanact12",
    height_threshold: float = 0.05,
    feet: Sequence[int] | None = None,
    ground=None,
):
    """PhysDiff's *Skate*: mean horizontal displacement of a foot between two frames it touches the ground in.

    Averaged over every (foot, adjacent-frame pair) in contact (both heights below
    ``height_threshold``); 0 when no foot is ever in contact.

    Returns
    -------
    float, or ndarray of shape (B,)
        Metres per frame.
    """
    x, skel, _, single = as_clip_batch(motion, skeleton, None)
    contact, step = _foot_contact(x, skel, feet, ground, height_threshold)
    total = (step * contact).sum(axis=(1, 2))
    count = contact.sum(axis=(1, 2))
    return per_clip(np.divide(total, count, out=np.zeros_like(total), where=count > 0), single)


def penetration(motion, *, skeleton: str | Skeleton = "humanact12", ground=None):
    """Ground penetration (PhysDiff's *Penetrate*, on joints): how far the lowest joint is below the ground.

    Per frame ``max(0, ground - min_j height)``, averaged over frames.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
    ground : float or array of shape (B,), optional
        Ground height along the up axis. Default :func:`ground_height` of the clip itself, which makes
        the feet's penetration 0 by construction: pass the source clip's ground to judge an edit.

    Returns
    -------
    float, or ndarray of shape (B,)
        Metres.
    """
    clearance, single = _clearance(motion, skeleton, ground)
    return per_clip(np.maximum(-clearance, 0.0).mean(-1), single)


def floating(motion, *, skeleton: str | Skeleton = "humanact12", ground=None, tolerance: float = 0.005):
    """Floating (PhysDiff's *Float*, on joints): how far the lowest joint is above the ground.

    Per frame ``max(0, min_j height - ground - tolerance)``, averaged over frames. Jumps count, as in
    PhysDiff.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3) or (B, T, J, 3)
    ground : float or array of shape (B,), optional
        As for :func:`penetration`.
    tolerance : float, default=0.005
        Metres (PhysDiff: 5 mm).

    Returns
    -------
    float, or ndarray of shape (B,)
        Metres.
    """
    clearance, single = _clearance(motion, skeleton, ground)
    return per_clip(np.maximum(clearance - tolerance, 0.0).mean(-1), single)


def _clearance(motion, skeleton, ground) -> tuple[np.ndarray, bool]:
    """``(B, T)`` height in metres of each frame's lowest joint above the ground, and whether one clip was given."""
    x, skel, _, single = as_clip_batch(motion, skeleton, None, min_frames=1)
    return heights(x, skel).min(-1) - _ground(x, skel, ground)[:, None], single
