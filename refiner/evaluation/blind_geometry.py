"""Vector helpers the blind flaw mechanisms share: unit vectors, rotation about an axis, great-circle blends, and
the bones of a HumanAct12 clip."""
from __future__ import annotations

import numpy as np

from refiner.core.skeletons import get_skeleton

__all__ = ["unit", "rotate", "slerp", "bones", "PARENTS"]

#: HumanAct12's parent of each joint (-1 at the root).
PARENTS = np.array(get_skeleton("humanact12").parents)


def unit(v: np.ndarray) -> np.ndarray:
    """``v (..., 3)`` scaled to unit length (zero vectors stay near zero)."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of vectors ``v`` about unit ``axis`` by ``angle`` (all broadcast)."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + np.cross(axis, v) * s + axis * (axis * v).sum(-1, keepdims=True) * (1.0 - c)


def slerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Unit directions a fraction ``w`` of the way along the great circle from ``a`` to ``b``."""
    axis = np.cross(a, b)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    ortho = np.cross(a, np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
    axis = np.where(n > 1e-9, axis / np.maximum(n, 1e-12), unit(ortho))
    angle = np.arctan2(n[..., 0], (a * b).sum(-1))
    return rotate(a, axis, angle * w)


def bones(x: np.ndarray):
    """``x (T, 24, 3)`` -> unit bone directions ``(T, 24, 3)`` and lengths ``(T, 24)`` metres of the bone ending at each
    joint (0 at the root)."""
    v = x - x[:, np.maximum(PARENTS, 0)]
    v[:, PARENTS < 0] = 0.0
    n = np.linalg.norm(v, axis=-1)
    return v / np.maximum(n, 1e-12)[..., None], n
