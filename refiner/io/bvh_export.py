"""Writing BVH files: rest offsets, joint rotations solved from positions, and the text of the file.

How a position motion becomes a BVH file, and how exact that is, is described in :mod:`refiner.io.bvh`.
"""
from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton
from refiner.io.bvh_import import bvh_frame, parse_bvh

__all__ = ["save_bvh"]

_ROT_ORDER = "ZXY"  # channel order written for every joint (as in the CMU BVH release)
_FMT = "%.6f"  # 1e-6 m and 1e-6 degree: far below the 1 mm round-trip target
_MIN_LEN = 1e-9


def save_bvh(
    motion,
    path: str | os.PathLike,
    *,
    skeleton: str | Skeleton = "humanact12",
    translations: bool = False,
    tol: float = 1e-3,
) -> float:
    """Write a joint-position motion as a BVH file.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3)
        Joint positions in metres, in the skeleton's frame. A bare array is validated as a
        ``Motion`` of ``skeleton`` at 20 fps.
    path : str or path-like
        Output file, usually ``*.bvh``. Parent folders must exist.
    skeleton : str or Skeleton, default="humanact12"
        Skeleton of a bare array; ignored for a ``Motion``.
    translations : bool, default=False
        Also give every joint ``Xposition Yposition Zposition`` channels holding its per-frame
        offset from the parent (in the parent's frame). This reproduces any joint positions
        exactly, also when bone lengths drift, at the cost of a less common file layout.
    tol : float, default=1e-3
        Round-trip error in metres above which a ``UserWarning`` is issued.

    Returns
    -------
    float
        Largest distance in metres between a joint in ``motion`` and the same joint recomputed
        by forward kinematics from the written file.

    Raises
    ------
    ValueError
        Wrong shape, NaN or Inf, unknown skeleton (via :class:`~refiner.core.motion.Motion`), or a
        negative ``tol``.

    Notes
    -----
    Rotation channels are ``Zrotation Xrotation Yrotation`` (degrees) on every joint; the root
    also has ``Xposition Yposition Zposition`` (metres) and a zero offset. Leaf joints are
    written as joints with zero rotations and a short ``End Site``, so every joint keeps its name.
    """
    if not isinstance(motion, Motion):
        motion = Motion(motion, skeleton=get_skeleton(skeleton).name)
    if not isinstance(translations, (bool, np.bool_)):
        raise ValueError(f"`translations` must be True or False; got {translations!r}.")
    if not (isinstance(tol, (int, float, np.number)) and tol >= 0):
        raise ValueError(f"`tol` must be a non-negative number of metres; got {tol!r}.")
    skel = motion.skeleton_info
    pos = motion.joints.astype(np.float64) @ bvh_frame(skel).T  # (T, J, 3) in the BVH frame
    offsets = _rest_offsets(pos, skel)
    local, glob = _local_rotations(pos, offsets, skel)  # (T, J, 3, 3) each

    order = _dfs_order(skel)
    with warnings.catch_warnings():
        # Gimbal lock only makes the angle split arbitrary; the composed rotation stays exact.
        warnings.simplefilter("ignore", UserWarning)
        euler = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_euler(_ROT_ORDER, degrees=True)
    euler = euler.reshape(motion.n_frames, skel.n_joints, 3)
    columns = []
    for j in order:
        parent = skel.parents[j]
        if parent < 0:
            columns.append(pos[:, j])
        elif translations:  # the bone vector in the parent's frame
            columns.append(np.einsum("tji,tj->ti", glob[:, parent], pos[:, j] - pos[:, parent]))
        columns.append(euler[:, j])
    data = np.concatenate(columns, axis=1)

    text = _hierarchy_text(skel, offsets, translations) + _motion_text(data, motion.fps)
    parsed = parse_bvh(text, source="the written BVH")
    back = parsed.positions()[:, [parsed.names.index(n) for n in skel.joint_names]]
    error = float(np.linalg.norm(back - pos, axis=-1).max())
    Path(path).write_text(text)
    if error > tol:
        lengths = skel.bone_lengths(pos)
        drift = float((lengths.max(0) - lengths.min(0)).max())
        warnings.warn(
            f"BVH stores fixed bone offsets: joint positions are reproduced only within {error * 1e3:.2f} mm "
            f"(bone lengths vary by up to {drift * 1e3:.2f} mm over the clip); pass translations=True for an "
            "exact file.",
            UserWarning,
            stacklevel=2,
        )
    return error


def _rest_offsets(pos: np.ndarray, skel: Skeleton) -> np.ndarray:
    """``(J, 3)`` rest offsets: first-frame bone directions times mean bone lengths (root: zero)."""
    offsets = np.zeros((skel.n_joints, 3))
    for p, j in skel.bones:
        vec = pos[:, j] - pos[:, p]
        length = np.linalg.norm(vec, axis=-1)
        valid = np.flatnonzero(length > _MIN_LEN)
        if valid.size:  # first frame where the bone has a direction
            offsets[j] = vec[valid[0]] / length[valid[0]] * length.mean()
    return offsets


def _local_rotations(pos: np.ndarray, offsets: np.ndarray, skel: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Local and global ``(T, J, 3, 3)`` joint rotations, solved so FK reaches the children."""
    n_frames = pos.shape[0]
    eye = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
    glob = np.empty((n_frames, skel.n_joints, 3, 3))
    local = np.empty_like(glob)
    for j in range(skel.n_joints):  # parents come first
        parent = skel.parents[j]
        g_parent = eye if parent < 0 else glob[:, parent]
        children = skel.children(j)
        if not children:
            g = g_parent
        elif len(children) == 1:
            c = children[0]
            target = np.einsum("tji,tj->ti", g_parent, pos[:, c] - pos[:, j])  # in the parent's frame
            g = g_parent @ _swing(offsets[c], target)
        else:
            g = _kabsch(offsets[list(children)], pos[:, list(children)] - pos[:, j : j + 1])
        glob[:, j] = g
        local[:, j] = np.swapaxes(g_parent, -1, -2) @ g
    return local, glob


def _swing(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` smallest rotations turning ``src`` (3,) towards each ``dst`` (T, 3)."""
    n_src = np.linalg.norm(src)
    n_dst = np.linalg.norm(dst, axis=-1)
    if n_src < _MIN_LEN:
        return np.broadcast_to(np.eye(3), (len(dst), 3, 3)).copy()
    a = src / n_src
    b = dst / np.maximum(n_dst, _MIN_LEN)[:, None]
    axis = np.cross(a, b)
    sin = np.linalg.norm(axis, axis=-1)
    cos = b @ a
    # Opposite directions: any axis perpendicular to `a` works.
    perp = np.cross(a, np.eye(3)[np.argmin(np.abs(a))])
    perp /= np.linalg.norm(perp)
    axis = np.where((sin < 1e-12)[:, None], perp * (cos < 0)[:, None], axis / np.maximum(sin, 1e-300)[:, None])
    angle = np.arctan2(sin, cos)
    angle[n_dst < _MIN_LEN] = 0.0
    return Rotation.from_rotvec(axis * angle[:, None]).as_matrix()


def _kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` rotations ``R`` minimising ``sum_k |R src_k - dst_tk|^2`` (src (K,3), dst (T,K,3))."""
    cov = np.einsum("kc,tkd->tdc", src, dst)  # sum_k dst_k src_k^T
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    d[d == 0] = 1.0
    u = u.copy()
    u[:, :, -1] *= d[:, None]
    return u @ vt


def _dfs_order(skel: Skeleton) -> list[int]:
    """Joint indices in the depth-first order a BVH hierarchy lists them."""
    order, stack = [], [skel.root]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(skel.children(j)))
    return order


def _hierarchy_text(skel: Skeleton, offsets: np.ndarray, translations: bool) -> str:
    lines = ["HIERARCHY"]
    rot = " ".join(f"{a}rotation" for a in _ROT_ORDER)

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        kind = "ROOT" if j == skel.root else "JOINT"
        lines.append(f"{pad}{kind} {skel.joint_names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {_vec(offsets[j])}")
        if j == skel.root:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {rot}")
        else:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {rot}" if translations
                         else f"{pad}  CHANNELS 3 {rot}")
        children = skel.children(j)
        for c in children:
            emit(c, depth + 1)
        if not children:
            # A short tip along the incoming bone gives viewers a bone to draw for the leaf.
            tip = 0.25 * offsets[j] if np.linalg.norm(offsets[j]) > _MIN_LEN else np.array([0.0, 0.05, 0.0])
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {_vec(tip)}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    emit(skel.root, 0)
    return "\n".join(lines) + "\n"


def _motion_text(data: np.ndarray, fps: float) -> str:
    buf = io.StringIO()
    np.savetxt(buf, data, fmt=_FMT, delimiter=" ")
    return f"MOTION\nFrames: {len(data)}\nFrame Time: {1.0 / fps:.8f}\n" + buf.getvalue()


def _vec(v: np.ndarray) -> str:
    return " ".join(_FMT % x for x in v)
