"""BVH (Biovision Hierarchy) export and import of joint-position motions.

A :class:`~refiner.core.motion.Motion` holds joint *positions*; BVH stores fixed bone offsets and
per-frame joint *rotations*. :func:`save_bvh` therefore

1. turns the skeleton's frame into the BVH convention (Y up, subject facing +Z, right-handed;
   for HumanAct12 / UESTC, y-down and facing -z, that is a half turn about x), units stay metres;
2. takes the rest offsets from the first frame's bone vectors, scaled to each bone's mean length
   over the clip (so the rest pose is the first frame and its rotations are all zero);
3. solves each joint's rotation so that forward kinematics hits its children: the minimal (swing)
   rotation for a joint with one child, the best-fit (Kabsch) rotation of all child offsets for a
   joint with several (the SMPL pelvis and spine3); a leaf joint keeps its parent's rotation.

This is exact when every bone keeps its length and the children of a branching joint move as one
rigid body, which holds for real HumanAct12 clips (reloaded positions agree to about 1e-5 m).
Motions whose bone lengths drift, as many generated ones do, cannot be stored exactly with fixed
offsets (Action2Motion's xyz-VAE samples: 86 mm median error): :func:`save_bvh` returns the
round-trip error and warns when it exceeds ``tol``; ``translations=True`` adds per-joint position
channels holding each bone vector, which makes any motion exact.

No comment syntax is part of BVH, so the skeleton is not written as a note: the joint names are the
skeleton's own, and :func:`load_bvh` recognises a registered skeleton from them, reorders the joints
to its order and turns them back into its frame.
"""
from __future__ import annotations

import io
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton, list_skeletons

__all__ = ["save_bvh", "load_bvh", "load_bvh_motion", "bvh_frame"]

_ROT_ORDER = "ZXY"  # channel order written for every joint (as in the CMU BVH release)
_FMT = "%.6f"  # 1e-6 m and 1e-6 degree: far below the 1 mm round-trip target
_MIN_LEN = 1e-9


def bvh_frame(skeleton: str | Skeleton) -> np.ndarray:
    """Rotation from a skeleton's frame to the BVH frame (Y up, facing +Z).

    Parameters
    ----------
    skeleton : str or Skeleton

    Returns
    -------
    ndarray of shape (3, 3), float64
        Proper rotation ``C`` with ``p_bvh = C @ p``; its rows are the skeleton-frame directions
        of the BVH X, Y and Z axes (``X = up x forward``).

    Raises
    ------
    ValueError
        If the skeleton's up and forward axes are not perpendicular.
    """
    skel = get_skeleton(skeleton)
    up, fwd = skel.up_vector, skel.forward_vector
    if abs(float(up @ fwd)) > 1e-9:
        raise ValueError(
            f"skeleton {skel.name!r}: `up` ({skel.up}) and `forward` ({skel.forward}) must be different axes."
        )
    return np.stack([np.cross(up, fwd), up, fwd])


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
    parsed = _parse(text, source="the written BVH")
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


def load_bvh(path: str | os.PathLike, *, skeleton: str | Skeleton | None = "auto") -> tuple[np.ndarray, list[str]]:
    """Read joint positions from a BVH file by forward kinematics.

    Parameters
    ----------
    path : str or path-like
    skeleton : str, Skeleton, "auto" or None, default="auto"
        ``"auto"``: if the file's joint names are exactly those of one registered skeleton (as
        :func:`save_bvh` writes them), return the joints in that skeleton's order and frame;
        otherwise in the file's order and frame. A name: require that skeleton. ``None``: always
        the file's order and its BVH frame.

    Returns
    -------
    joints : ndarray of shape (T, J, 3), float32
        Joint positions in the file's units (metres for files from :func:`save_bvh`). ``End Site``
        points are not joints and are left out.
    names : list of str, length J

    Raises
    ------
    ValueError
        Missing file, malformed BVH (naming the problem), or joint names not matching a
        requested skeleton.

    Notes
    -----
    Position channels give a joint's translation from its parent and replace its ``OFFSET``
    (the usual convention for the root); rotation channels compose in the order listed.
    """
    parsed = _read(path)
    skel = _match_skeleton(parsed.names, skeleton, path)
    pos = parsed.positions()
    if skel is None:
        return pos.astype(np.float32), list(parsed.names)
    idx = [parsed.names.index(n) for n in skel.joint_names]
    pos = pos[:, idx] @ bvh_frame(skel)  # back from the BVH frame: C is orthogonal
    return pos.astype(np.float32), list(skel.joint_names)


def load_bvh_motion(path: str | os.PathLike, *, skeleton: str | Skeleton = "auto") -> Motion:
    """Read a BVH file written by :func:`save_bvh` (or with a registered skeleton's joints) as a Motion.

    Parameters
    ----------
    path : str or path-like
    skeleton : str, Skeleton or "auto", default="auto"
        As in :func:`load_bvh`, but the joint names must match a registered skeleton.

    Returns
    -------
    Motion
        Joints in the skeleton's frame; ``fps`` from ``Frame Time`` (rounded to 1e-3).

    Raises
    ------
    ValueError
        As :func:`load_bvh`, or when no registered skeleton matches the joint names.
    """
    parsed = _read(path)
    skel = _match_skeleton(parsed.names, skeleton, path)
    if skel is None:
        raise ValueError(
            f"{path}: joint names match no registered skeleton ({', '.join(list_skeletons())}); "
            "pass `skeleton=` or use load_bvh for raw joints."
        )
    joints, _ = load_bvh(path, skeleton=skel)
    return Motion(joints, skeleton=skel.name, fps=round(1.0 / parsed.frame_time, 3))


# ----------------------------------------------------------------------------------------------
# writing


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


# ----------------------------------------------------------------------------------------------
# reading


@dataclass
class _Parsed:
    """A parsed BVH file: named joints (end sites dropped) in file order and their channel data."""

    names: list[str]
    parents: list[int]
    offsets: np.ndarray  # (J, 3)
    channels: list[list[str]]
    columns: list[int]  # first data column of each joint
    data: np.ndarray  # (T, C)
    frame_time: float

    def positions(self) -> np.ndarray:
        """``(T, J, 3)`` float64 world positions by forward kinematics."""
        n_frames = self.data.shape[0]
        pos = np.zeros((n_frames, len(self.names), 3))
        glob = np.zeros((n_frames, len(self.names), 3, 3))
        for j, chans in enumerate(self.channels):
            trans = np.broadcast_to(self.offsets[j], (n_frames, 3)).copy()
            rot = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
            rot_axes, rot_cols = "", []
            for k, ch in enumerate(chans):
                col = self.data[:, self.columns[j] + k]
                axis = "xyz".index(ch[0])
                if ch.endswith("position"):
                    trans[:, axis] = col
                else:
                    rot_axes += "XYZ"[axis]
                    rot_cols.append(col)
            if rot_axes:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    rot = Rotation.from_euler(rot_axes, np.stack(rot_cols, -1), degrees=True).as_matrix()
            p = self.parents[j]
            if p < 0:
                pos[:, j] = trans
                glob[:, j] = rot
            else:
                pos[:, j] = pos[:, p] + np.einsum("tij,tj->ti", glob[:, p], trans)
                glob[:, j] = glob[:, p] @ rot
        return pos


_CHANNEL_NAMES = {f"{a}{k}" for a in "xyz" for k in ("position", "rotation")}


def _read(path: str | os.PathLike) -> _Parsed:
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"BVH file not found: {path}.")
    try:
        text = path.read_text()
    except UnicodeDecodeError as e:
        raise ValueError(f"{path} is not a text BVH file: {e}") from e
    return _parse(text, source=str(path))


def _parse(text: str, *, source: str) -> _Parsed:
    """Parse BVH text; every format problem is a ValueError naming ``source``."""

    def fail(msg: str) -> ValueError:
        return ValueError(f"{source}: malformed BVH: {msg}.")

    parts = re.split(r"^[ \t]*MOTION[ \t]*\r?$", text, maxsplit=1, flags=re.MULTILINE | re.IGNORECASE)
    if len(parts) != 2:
        raise fail("no MOTION section")
    head, body = parts
    tokens = head.split()
    if not tokens or tokens[0].upper() != "HIERARCHY":
        raise fail("it must start with HIERARCHY")
    names, parents, offsets, channels, columns = [], [], [], [], []
    stack: list[int] = []  # open blocks: joint index, or -2 for an End Site
    n_cols = 0
    i = 1

    def take_floats(n: int) -> list[float]:
        nonlocal i
        try:
            vals = [float(t) for t in tokens[i : i + n]]
        except ValueError:
            raise fail(f"expected {n} numbers after token {i}; got {tokens[i:i + n]}") from None
        if len(vals) != n:
            raise fail("the hierarchy ends early")
        i += n
        return vals

    while i < len(tokens):
        tok = tokens[i]
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            if i + 2 >= len(tokens) or tokens[i + 2] != "{":
                raise fail(f"{tok} must be followed by a name and '{{'")
            if (key == "ROOT") != (not stack):
                raise fail(f"{tok} {tokens[i + 1]} is in the wrong place")
            if stack and stack[-1] < 0:
                raise fail("an End Site cannot have children")
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            columns.append(n_cols)
            stack.append(len(names) - 1)
            i += 3
        elif key == "END":
            if i + 2 >= len(tokens) or tokens[i + 1].upper() != "SITE" or tokens[i + 2] != "{":
                raise fail("expected 'End Site {'")
            stack.append(-2)
            i += 3
        elif key == "OFFSET":
            i += 1
            vals = take_floats(3)
            if not stack:
                raise fail("OFFSET outside a joint")
            if stack[-1] >= 0:
                offsets[stack[-1]] = vals
        elif key == "CHANNELS":
            if not stack or stack[-1] < 0:
                raise fail("CHANNELS outside a joint")
            try:
                n = int(tokens[i + 1])
            except (IndexError, ValueError):
                raise fail("CHANNELS must be followed by a count") from None
            chans = [t.lower() for t in tokens[i + 2 : i + 2 + n]]
            if len(chans) != n or any(c not in _CHANNEL_NAMES for c in chans):
                raise fail(f"bad channel list for joint {names[stack[-1]]!r}: {tokens[i + 2:i + 2 + n]}")
            channels[stack[-1]] = chans
            n_cols += n
            i += 2 + n
        elif tok == "}":
            if not stack:
                raise fail("unbalanced '}'")
            stack.pop()
            i += 1
        else:
            raise fail(f"unexpected token {tok!r}")
    if stack:
        raise fail("unclosed '{'")
    if not names:
        raise fail("no joints")
    if len(set(names)) != len(names):
        raise fail("joint names must be unique")

    lines = body.strip().split("\n", 2)
    if len(lines) < 2:
        raise fail("the MOTION section needs 'Frames:' and 'Frame Time:' lines")
    f_tok, t_tok = lines[0].split(), lines[1].split()
    try:
        if f_tok[0].lower() != "frames:" or [t.lower() for t in t_tok[:2]] != ["frame", "time:"]:
            raise ValueError
        n_frames, frame_time = int(f_tok[1]), float(t_tok[2])
    except (IndexError, ValueError):
        raise fail(f"the MOTION section must start with 'Frames: N' and 'Frame Time: dt'; got {lines[:2]}") from None
    if n_frames < 1 or not (np.isfinite(frame_time) and frame_time > 0):
        raise fail(f"need Frames >= 1 and Frame Time > 0; got {n_frames} and {frame_time}")
    try:
        values = np.array(lines[2].split() if len(lines) > 2 else [], dtype=np.float64)
    except ValueError:
        raise fail("the frame data must be numbers") from None
    if values.size != n_frames * n_cols:
        raise fail(f"expected {n_frames} frames x {n_cols} channels = {n_frames * n_cols} values; got {values.size}")
    if not np.isfinite(values).all():
        raise fail("the frame data contain NaN or Inf")
    return _Parsed(
        names=names,
        parents=parents,
        offsets=np.array(offsets, dtype=np.float64),
        channels=channels,
        columns=columns,
        data=values.reshape(n_frames, n_cols),
        frame_time=frame_time,
    )


def _match_skeleton(names: list[str], skeleton, path) -> Skeleton | None:
    """The skeleton whose joint names are exactly ``names`` (any order), per :func:`load_bvh`'s rule."""
    if skeleton is None:
        return None
    if isinstance(skeleton, str) and skeleton == "auto":
        found = [s for s in map(get_skeleton, list_skeletons()) if sorted(s.joint_names) == sorted(names)]
        if len(found) > 1:
            raise ValueError(
                f"{path}: joint names match several skeletons ({', '.join(s.name for s in found)}); pass `skeleton=`."
            )
        return found[0] if found else None
    skel = get_skeleton(skeleton)
    if sorted(skel.joint_names) != sorted(names):
        missing = sorted(set(skel.joint_names) - set(names))
        extra = sorted(set(names) - set(skel.joint_names))
        raise ValueError(
            f"{path}: joints do not match skeleton {skel.name!r}; missing {missing}, unexpected {extra}."
        )
    return skel
