"""The floor under a clip: a plane fitted under its feet, and each frame's gap to it.

Cameras and generators need not hold the floor level (HumanAct12's camera looks down at the people it films), so
the floor is a plane, not a height. Shapes are ``(..., T, J, 3)`` metres in the skeleton's frame; heights are along
its up axis (:func:`refiner.core.contact.heights`).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from refiner.core.contact import contact_joints, heights
from refiner.core.skeletons import get_skeleton

__all__ = ["floor_plane", "floor_gap", "plane_height", "levelled", "lowest_contact", "support_heights", "support_joints",
           "plane_basis"]


def lowest_contact(joints, skeleton) -> tuple[np.ndarray, np.ndarray]:
    """``joints (..., T, J, 3)`` -> the lowest contact joint's position ``(..., T, 3)`` and height ``(..., T)``, metres."""
    contact = np.array(contact_joints(skeleton))
    points = joints[..., contact, :]
    h = heights(points, skeleton)
    k = h.argmin(-1)
    return np.take_along_axis(points, k[..., None, None], -2)[..., 0, :], np.take_along_axis(h, k[..., None], -1)[..., 0]


def support_joints(skeleton) -> list[int]:
    """The root and the head (or neck): the body a limb does not carry, which moves when the whole body does."""
    skel = get_skeleton(skeleton)
    return [skel.root] + [skel.index(n) for n in ("head", "neck") if n in skel.joint_names][:1]


def support_heights(joints, skeleton) -> np.ndarray:
    """``(..., T, K)`` metres: heights of the :func:`support_joints`."""
    return heights(joints[..., support_joints(skeleton), :], skeleton)


def plane_basis(skeleton) -> np.ndarray:
    """``(2, 3)`` two orthonormal horizontal axes of the skeleton's frame (read-only)."""
    return _basis(get_skeleton(skeleton).name)


@lru_cache(maxsize=None)
def _basis(name: str) -> np.ndarray:
    up = get_skeleton(name).up_vector
    a = np.cross(up, [1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.cross(up, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    out = np.stack([a, np.cross(up, a)])
    out.flags.writeable = False
    return out


def floor_plane(joints, skeleton, *, bandwidth_m: float = 0.02, iterations: int = 6, ridge_m: float = 0.1) -> np.ndarray:
    """The floor of clips ``joints (..., T, J, 3)`` metres as ``(..., 3)`` coefficients: height = ``c0 + c1 u + c2 v``,
    with ``(u, v)`` metres along :func:`plane_basis`. Fitted to the lowest contact joint of every frame by least
    squares reweighted to frames near the plane (steps and jumps pull little); the tilt is shrunk toward level for
    clips that cover under ``ridge_m`` of floor, where it cannot be told."""
    point, h = lowest_contact(np.asarray(joints, np.float64), skeleton)
    uv = point @ plane_basis(skeleton).T  # (..., T, 2)
    center = uv.mean(-2, keepdims=True)
    design = np.concatenate([np.ones_like(h)[..., None], uv - center], -1)  # (..., T, 3)
    w = np.ones_like(h)
    ridge = np.diag([0.0, 1.0, 1.0]) * ridge_m ** 2
    for _ in range(iterations):
        weighted = np.swapaxes(design * w[..., None], -1, -2)  # (..., 3, T)
        a = weighted @ design + ridge * w.sum(-1)[..., None, None]
        coef = np.linalg.solve(a, weighted @ h[..., None])[..., 0]
        w = np.exp(-0.5 * ((h - (design @ coef[..., None])[..., 0]) / bandwidth_m) ** 2) + 1e-6
    offset = coef[..., 0] - np.einsum("...i,...i->...", coef[..., 1:], center[..., 0, :])
    return np.concatenate([offset[..., None], coef[..., 1:]], -1)


def plane_height(points, plane, skeleton) -> np.ndarray:
    """Height of the floor ``plane (..., 3)`` under ``points (..., T, 3)`` or ``(..., T, J, 3)``: ``(..., T[, J])``."""
    uv = np.asarray(points) @ plane_basis(skeleton).T
    plane = np.asarray(plane)
    extra = uv.ndim - plane.ndim  # the frame (and joint) axes the plane is broadcast over
    p = plane.reshape(plane.shape[:-1] + (1,) * extra + (3,))
    return p[..., 0] + (uv * p[..., 1:]).sum(-1)


def floor_gap(joints, skeleton, plane=None, **fit) -> np.ndarray:
    """``(..., T)`` metres: the lowest contact joint's height above the clips' floor (negative: below it)."""
    x = np.asarray(joints, np.float64)
    plane = floor_plane(x, skeleton, **fit) if plane is None else plane
    point, h = lowest_contact(x, skeleton)
    return h - plane_height(point, plane, skeleton)


def levelled(joints, plane, skeleton) -> np.ndarray:
    """``joints`` with the floor plane's height under each joint taken off along the vertical (floor at 0)."""
    up = get_skeleton(skeleton).up_vector
    return joints - plane_height(joints, plane, skeleton)[..., None] * up
