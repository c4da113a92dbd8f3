"""Rigid motion: a root trajectory plus one unit direction per bone, so no edit can stretch a bone.

A clip ``(..., T, J, 3)`` is split into its root ``(..., T, 3)``, its bone directions ``(..., T, B, 3)``
(unit vectors, parent to child, in :attr:`Skeleton.bones` order) and its bone lengths ``(..., T, B)``;
:func:`from_bone_directions` puts them back together by forward kinematics. Round trips are exact to float error.
"""
from __future__ import annotations

import numpy as np

from refiner.core.skeletons import Skeleton, get_skeleton

__all__ = ["to_bone_directions", "from_bone_directions", "subtree_bones", "blend_directions", "retimed"]

_EPS = 1e-9


def to_bone_directions(joints, skeleton: Skeleton | str):
    """``joints (..., T, J, 3)`` metres -> ``root (..., T, 3)``, ``directions (..., T, B, 3)`` unit, ``lengths (..., T, B)`` metres."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float64)
    b = skel.bones
    vec = x[..., b[:, 1], :] - x[..., b[:, 0], :]
    lengths = np.linalg.norm(vec, axis=-1)
    directions = vec / np.maximum(lengths, _EPS)[..., None]
    return x[..., skel.root, :], directions, lengths


def from_bone_directions(root, directions, lengths, skeleton: Skeleton | str) -> np.ndarray:
    """Forward kinematics: ``root (..., T, 3)``, ``directions (..., T, B, 3)`` (normalised here), ``lengths (..., T, B)``
    or ``(B,)`` -> ``joints (..., T, J, 3)`` float64 metres."""
    skel = get_skeleton(skeleton)
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), _EPS)
    vec = d * np.broadcast_to(np.asarray(lengths, dtype=np.float64), d.shape[:-1])[..., None]
    out = np.empty(d.shape[:-2] + (skel.n_joints, 3))
    out[..., skel.root, :] = root
    for i, (p, c) in enumerate(skel.bones):  # parents come before children
        out[..., c, :] = out[..., p, :] + vec[..., i, :]
    return out


def subtree_bones(skeleton: Skeleton | str, joint: int) -> np.ndarray:
    """Indices of the bones below ``joint`` (those whose parent is ``joint`` or one of its descendants)."""
    skel = get_skeleton(skeleton)
    inside = np.zeros(skel.n_joints, bool)
    inside[joint] = True
    for j, p in enumerate(skel.parents):
        if p >= 0 and inside[p]:
            inside[j] = True
    return np.flatnonzero(inside[skel.bones[:, 0]])


def blend_directions(a, b, weight) -> np.ndarray:
    """Normalised blend of unit directions ``a`` and ``b`` (``(..., 3)``) with ``weight`` in [0, 1] toward ``b``
    (broadcast over the trailing axis)."""
    w = np.asarray(weight, dtype=np.float64)[..., None]
    d = (1.0 - w) * a + w * b
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), _EPS)


def retimed(joints, times, skeleton: Skeleton | str) -> np.ndarray:
    """Frames of ``joints (T, J, 3)`` metres at fractional ``times (T',)`` (clipped to the clip): root linear, bone
    directions blended, bone lengths of the earlier frame, so no bone stretches -> ``(T', J, 3)`` float64."""
    x = np.asarray(joints, dtype=np.float64)
    t = np.clip(np.asarray(times, dtype=np.float64), 0, len(x) - 1)
    lo = np.floor(t).astype(int)
    hi = np.minimum(lo + 1, len(x) - 1)
    f = t - lo
    root, dirs, lengths = to_bone_directions(x, skeleton)
    new_root = (1 - f)[:, None] * root[lo] + f[:, None] * root[hi]
    return from_bone_directions(new_root, blend_directions(dirs[lo], dirs[hi], f[:, None]), lengths[lo], skeleton)
