"""Rotation maths shared by the adapters and the reference generators (generator_formats.md §0.1, §2.2, §3.1).

Names follow roma (``rotvec``, ``rotmat``, ``rot6d``). Every function takes any number of leading
batch dimensions, computes in float64 numpy and returns a new array.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "rot6d_to_rotmat",
    "rotation_between",
    "rotmat_to_rot6d",
    "rotmat_to_rotvec",
    "rotvec_to_rotmat",
    "unwrap_rotvecs",
    "yup_to_ydown",
]


def rot6d_to_rotmat(d6) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from 6D vectors ``(..., 6)``, pytorch3d ROW convention.

    The 6 numbers are the first two *rows* of the matrix; Gram-Schmidt gives rows b1, b2 and
    b3 = b1 x b2 (generator_formats.md §3.1; not the column convention of Zhou et al.'s text).
    Raises ``ValueError`` for degenerate (zero or parallel) inputs, e.g. padded frames.
    """
    d6 = np.asarray(d6, dtype=np.float64)
    a1, a2 = d6[..., :3], d6[..., 3:6]
    n1 = np.linalg.norm(a1, axis=-1, keepdims=True)
    b1 = a1 / np.maximum(n1, 1e-300)
    a2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    n2 = np.linalg.norm(a2, axis=-1, keepdims=True)
    if (n1 < 1e-8).any() or (n2 < 1e-8).any():
        raise ValueError(
            "6D rotation has a zero or degenerate vector (padded frame?); decode only the valid frames."
        )
    b2 = a2 / n2
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-2)


def rotmat_to_rot6d(rotmat) -> np.ndarray:
    """6D vectors ``(..., 6)``: the first two rows of ``rotmat (..., 3, 3)`` (inverse of :func:`rot6d_to_rotmat`)."""
    rotmat = np.asarray(rotmat, dtype=np.float64)
    return rotmat[..., :2, :].reshape(rotmat.shape[:-2] + (6,))


def rotvec_to_rotmat(rotvec, *, min_angle: float = 0.0) -> np.ndarray:
    """Rodrigues' formula: rotation matrices ``(..., 3, 3)`` from axis-angle vectors ``(..., 3)`` (rad).

    ``min_angle`` floors the angle inside the two coefficients, as Action2Motion's ``lie_exp_map``
    does with 0.01 rad (generator_formats.md §2.2 step 2); 0 gives the exact map.
    """
    w = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    if min_angle > 0:
        t = np.maximum(theta, min_angle)
        a, b = np.sin(t) / t, (1.0 - np.cos(t)) / t**2
    else:
        small = theta < 1e-6
        t = np.where(small, 1.0, theta)  # avoids 0/0; the series below is used there
        a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t) / t)
        b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    k = _hat(w)
    return np.eye(3) + a * k + b * (k @ k)


def rotmat_to_rotvec(rotmat) -> np.ndarray:
    """Axis-angle vectors ``(..., 3)`` (angle in [0, pi]) from rotation matrices ``(..., 3, 3)``.

    Goes through a unit quaternion (largest-component method), so it is stable at 0 and at pi,
    where Action2Motion's ``arccos`` log map divides 0 by 0 (generator_formats.md §2.2).
    """
    r = np.asarray(rotmat, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([
        np.stack([1 + tr, r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1),
        np.stack([r[..., 2, 1] - r[..., 1, 2], 1 + m00 - m11 - m22, r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0]], -1),
        np.stack([r[..., 0, 2] - r[..., 2, 0], r[..., 0, 1] + r[..., 1, 0], 1 - m00 + m11 - m22, r[..., 1, 2] + r[..., 2, 1]], -1),
        np.stack([r[..., 1, 0] - r[..., 0, 1], r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1], 1 - m00 - m11 + m22], -1),
    ], axis=-2)  # (..., 4 candidates, wxyz), candidate i is 4*q_i*q
    best = np.argmax(np.stack([1 + tr, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1), -1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(q[..., :1] < 0, -q, q)
    vec_norm = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(vec_norm, q[..., :1])
    scale = np.where(vec_norm < 1e-12, 2.0, angle / np.maximum(vec_norm, 1e-300))
    return q[..., 1:] * scale


def rotation_between(u, v) -> np.ndarray:
    """Axis-angle ``(..., 3)`` of the shortest rotation taking unit vectors ``u`` to ``v`` (``(..., 3)``).

    Action2Motion's ``lie_u_v``; antiparallel pairs get a rotation by pi about an axis
    perpendicular to ``u`` instead of the original's undefined axis.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u, v = np.broadcast_arrays(u, v)
    cross = np.cross(u, v)
    sin = np.linalg.norm(cross, axis=-1, keepdims=True)
    cos = np.sum(u * v, axis=-1, keepdims=True)
    angle = np.arctan2(sin, cos)
    axis = cross / np.maximum(sin, 1e-300)
    # antiparallel: any axis perpendicular to u
    helper = np.where(np.abs(u[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    perp = np.cross(u, helper)
    perp = perp / np.linalg.norm(perp, axis=-1, keepdims=True)
    axis = np.where((sin < 1e-12) & (cos < 0), perp, axis)
    return np.where(sin < 1e-12, np.where(cos < 0, perp * np.pi, 0.0), axis * angle)


def unwrap_rotvecs(lie: np.ndarray) -> np.ndarray:
    """Make Lie parameters continuous over time: each axis-angle ``w`` may become ``w - 2 pi w / |w|``.

    Inverse kinematics returns angles in [0, pi], so a joint rotating through pi flips its
    axis-angle vector to the opposite side (3 % of HumanAct12 frame steps jump by more than
    1 rad). Both vectors are the same rotation; per frame we keep the one closer to the previous
    frame's, so regression targets are smooth and forward kinematics gives the same joints.

    Parameters
    ----------
    lie : ndarray of shape (T, 3 + 3K)
        Root position, then K axis-angle vectors (rad).

    Returns
    -------
    ndarray of shape (T, 3 + 3K), float32
        Same rotations, with norms up to 2 pi.
    """
    lie = np.asarray(lie, dtype=np.float64)
    canonical = lie[:, 3:].reshape(len(lie), -1, 3)
    theta = np.linalg.norm(canonical, axis=-1, keepdims=True)
    flipped = canonical - 2 * np.pi * canonical / np.maximum(theta, 1e-8)
    rot = canonical.copy()
    for t in range(1, len(rot)):
        closer = np.linalg.norm(flipped[t] - rot[t - 1], axis=-1) < np.linalg.norm(canonical[t] - rot[t - 1], axis=-1)
        rot[t, closer] = flipped[t, closer]
    return np.concatenate([lie[:, :3], rot.reshape(len(lie), -1)], axis=1).astype(np.float32)


def yup_to_ydown(joints) -> np.ndarray:
    """Rotate 180 degrees about x, ``(x, y, z) -> (x, -y, -z)``: HumanML3D (y up, facing +z) to the
    HumanAct12 camera frame (y down, facing -z), keeping left = +x (generator_formats.md §0.1).

    Its own inverse. ``joints`` is ``(..., 3)`` in any unit; returns a float64 copy.
    """
    out = np.array(joints, dtype=np.float64, copy=True)
    out[..., 1:] *= -1.0
    return out


def _hat(w: np.ndarray) -> np.ndarray:
    """Skew matrices ``(..., 3, 3)`` with ``hat(w) @ v == w x v``."""
    z = np.zeros(w.shape[:-1])
    x, y, zz = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [np.stack([z, -zz, y], -1), np.stack([zz, z, -x], -1), np.stack([-y, x, z], -1)], axis=-2
    )
