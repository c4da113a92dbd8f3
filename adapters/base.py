"""Pieces shared by the generator adapters: AdapterInfo, rotation maths, Lie kinematics, frame changes.

Every piece of maths used by more than one adapter lives here once (generator_formats.md §1-§3).
Rotations follow roma's naming (``rotvec``, ``rotmat``, ``rot6d``), take any number of leading
batch dimensions and compute in float64 numpy.
"""
from __future__ import annotations

import inspect
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from refiner.core.validation import to_numpy

__all__ = [
    "AdapterInfo",
    "LieKinematics",
    "LIE_KINEMATICS",
    "check_raw",
    "call_with_options",
    "get_lie_kinematics",
    "lie_forward_kinematics",
    "lie_inverse_kinematics",
    "recenter",
    "reference_bone_lengths",
    "resolve_path",
    "rot6d_to_rotmat",
    "rotation_between",
    "rotmat_to_rot6d",
    "rotmat_to_rotvec",
    "rotvec_to_rotmat",
    "yup_to_ydown",
]

_AXES = {"+x", "-x", "+y", "-y", "+z", "-z"}


@dataclass(frozen=True)
class AdapterInfo:
    """What an adapter plugin converts, returned by its ``refiner_adapter_info`` hook.

    Parameters
    ----------
    name : str
        Adapter name: the generator's short name, also the plugin and entry-point name
        (``"action2motion"``, ``"actor"``, ...). Lower-case letters, digits, ``_`` and ``-``.
    format : str
        One-line description of the raw generator output the adapter accepts, with shapes.
    skeletons : tuple of str
        Registered skeletons (:func:`refiner.get_skeleton`) it can produce; the first is the default.
    fps : float, default=20.0
        Frame rate of the generator's output (and of the produced motions).
    up : str, default="-y"
        Up axis of the generator's *native* output, with sign (``"+y"`` for HumanML3D generators).
        Converted motions are always in the target skeleton's own frame.
    description : str, default=""
    source : str, default=""
        Where the plugin came from; filled in by the plugin manager (``"built-in"`` or the
        distribution name and version), plugins leave it empty.
    """

    name: str
    format: str
    skeletons: tuple[str, ...]
    fps: float = 20.0
    up: str = "-y"
    description: str = ""
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or not all(
            c.isalnum() or c in "_-" for c in self.name
        ) or self.name.lower() != self.name:
            raise ValueError(f"AdapterInfo `name` must be a lower-case identifier like 'actor'; got {self.name!r}.")
        if not isinstance(self.format, str) or not self.format.strip():
            raise ValueError(f"AdapterInfo {self.name!r}: `format` must describe the raw output; got {self.format!r}.")
        skeletons = (self.skeletons,) if isinstance(self.skeletons, str) else tuple(self.skeletons)
        if not skeletons or not all(isinstance(s, str) and s for s in skeletons):
            raise ValueError(
                f"AdapterInfo {self.name!r}: `skeletons` must be a non-empty tuple of skeleton names; "
                f"got {self.skeletons!r}."
            )
        object.__setattr__(self, "skeletons", skeletons)
        if isinstance(self.fps, bool) or not isinstance(self.fps, (int, float)) or not np.isfinite(self.fps) or self.fps <= 0:
            raise ValueError(f"AdapterInfo {self.name!r}: `fps` must be a positive number; got {self.fps!r}.")
        object.__setattr__(self, "fps", float(self.fps))
        if self.up not in _AXES:
            raise ValueError(f"AdapterInfo {self.name!r}: `up` must be one of {sorted(_AXES)}; got {self.up!r}.")


# --- input handling ---------------------------------------------------------------------------


def check_raw(x, *, name: str, ndims: tuple[int, ...], last: tuple[int, ...] | None = None, what: str = "") -> np.ndarray:
    """Float64 copy of a raw generator tensor, checking its rank, last axis and finiteness.

    Raises ``ValueError`` naming ``name``, the expected shape ``what`` and the shape found.
    """
    arr = to_numpy(x, name=name).astype(np.float64, copy=False)
    expected = what or f"{' or '.join(f'{d}-D' for d in ndims)} with last axis in {last}"
    if arr.ndim not in ndims or (last is not None and arr.shape[-1] not in last):
        raise ValueError(f"`{name}` must have shape {expected}; got {tuple(arr.shape)}.")
    if arr.size == 0:
        raise ValueError(f"`{name}` is empty; got shape {tuple(arr.shape)}.")
    if not np.isfinite(arr).all():
        raise ValueError(f"`{name}` contains {int((~np.isfinite(arr)).sum())} NaN or Inf values.")
    return arr


def call_with_options(fn: Callable[..., Any], output: Any, options: Mapping[str, Any], *, adapter: str) -> Any:
    """Call ``fn(output, **options)``, turning unknown option names into a ``ValueError`` listing the valid ones."""
    params = inspect.signature(fn).parameters
    accepted = [p for p, v in params.items() if v.kind is inspect.Parameter.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise ValueError(
            f"unknown option(s) {', '.join(map(repr, unknown))} for adapter {adapter!r}; "
            f"accepted: {', '.join(accepted)}."
        )
    return fn(output, **options)


def resolve_path(value, *, param: str, env: str, what: str, default_name: str | None = None,
                 origin: str = "") -> Path:
    """The file given by ``value``, else by ``$env``; a folder is searched for ``default_name``.

    Raises ``ValueError`` naming the parameter, the environment variable, the expected file name and
    where the file comes from (``origin``) when neither points to an existing file.
    """
    source = f"`{param}`"
    if value is None:
        value = os.environ.get(env)
        source = f"${env}"
    where = f" Get it from {origin}." if origin else ""
    if value is None or str(value) == "":
        raise ValueError(f"{what} is needed: pass `{param}=` (a file path) or set the environment variable {env}"
                         + (f" (a file, or a folder holding {default_name})." if default_name else ".") + where)
    path = Path(value).expanduser()
    if path.is_dir() and default_name is not None:
        path = path / default_name
    if not path.is_file():
        raise ValueError(f"{what} not found: {source} points to {str(path)!r}, which is not a file.{where}")
    return path


# --- rotations (float64 numpy, any leading batch dims) ----------------------------------------


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


def _hat(w: np.ndarray) -> np.ndarray:
    """Skew matrices ``(..., 3, 3)`` with ``hat(w) @ v == w x v``."""
    z = np.zeros(w.shape[:-1])
    x, y, zz = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [np.stack([z, -zz, y], -1), np.stack([zz, z, -x], -1), np.stack([-y, x, z], -1)], axis=-2
    )


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


# --- Action2Motion Lie kinematics (generator_formats.md §1.1, §1.2, §2.2) ---------------------


@dataclass(frozen=True)
class LieKinematics:
    """Tables for Action2Motion's Lie parametrisation of one joint layout.

    Attributes
    ----------
    skeleton : str
        Registered skeleton the joints follow.
    chains : tuple of tuple of int
        Kinematic chains in processing order; each starts at an already placed joint.
    raw_offsets : ndarray of shape (J, 3)
        Unit reference bone directions (zero for the root). Not a rest pose.
    default_bone_lengths : ndarray of shape (J,)
        Fallback bone length of every joint to its parent in metres (0 for the root): means over
        Action2Motion's shipped xyz samples; use a real clip's first frame when you have one.
    """

    skeleton: str
    chains: tuple[tuple[int, ...], ...]
    raw_offsets: np.ndarray
    default_bone_lengths: np.ndarray

    @property
    def n_joints(self) -> int:
        return len(self.raw_offsets)

    @property
    def parents(self) -> tuple[int, ...]:
        parents = [-1] * self.n_joints
        for chain in self.chains:
            for p, c in zip(chain[:-1], chain[1:]):
                parents[c] = p
        return tuple(parents)


_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def _neg(v):
    return tuple(-c for c in v)


LIE_KINEMATICS: dict[str, LieKinematics] = {
    "humanact12": LieKinematics(
        skeleton="humanact12",
        chains=((0, 1, 4, 7, 10), (0, 2, 5, 8, 11), (0, 3, 6, 9, 12, 15), (9, 13, 16, 18, 20, 22), (9, 14, 17, 19, 21, 23)),
        raw_offsets=np.array([
            (0, 0, 0), _X, _neg(_X), _Y, _neg(_Y), _neg(_Y), _Y, _neg(_Y), _neg(_Y), _Y, _Z, _Z,
            _Y, _X, _neg(_X), _Z, _neg(_Y), _neg(_Y), _neg(_Y), _neg(_Y), _neg(_Y), _neg(_Y), _neg(_Y), _neg(_Y),
        ], dtype=np.float64),
        default_bone_lengths=np.array([
            0.0, 0.104, 0.110, 0.120, 0.356, 0.354, 0.132, 0.389, 0.382, 0.054, 0.130, 0.139,
            0.213, 0.134, 0.140, 0.102, 0.123, 0.116, 0.243, 0.250, 0.241, 0.251, 0.076, 0.081,
        ]),
    ),
    "uestc": LieKinematics(
        skeleton="uestc",
        chains=((0, 12, 13, 14, 15), (0, 9, 10, 11, 16), (0, 1, 8, 17), (1, 5, 6, 7), (1, 2, 3, 4)),
        raw_offsets=np.array([
            (0, 0, 0), _neg(_Y), _neg(_Y), _neg(_X), _neg(_Z), _neg(_Y), _neg(_Y), _neg(_Z), _neg(_Y),
            _Y, _Y, _Y, _Y, _Y, _Y, _Y, _Y, _neg(_Y),
        ], dtype=np.float64),
        default_bone_lengths=np.array([
            0.0, 0.521, 0.203, 0.242, 0.247, 0.199, 0.250, 0.242, 0.203, 0.106, 0.373, 0.382,
            0.109, 0.363, 0.381, 0.067, 0.070, 0.191,
        ]),
    ),
}
_LIE_ALIASES = {"humanact12": "humanact12", "ntu13": "uestc", "ntu_rgbd_vibe": "uestc", "uestc": "uestc"}


def get_lie_kinematics(dataset: str) -> LieKinematics:
    """Lie tables for ``"humanact12"`` (24 joints) or ``"ntu13"`` (alias ``"uestc"``, 18 NTU-VIBE joints)."""
    try:
        return LIE_KINEMATICS[_LIE_ALIASES[dataset]]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown `dataset` {dataset!r} for Lie kinematics; known: humanact12, ntu13 (alias uestc)."
        ) from None


def reference_bone_lengths(reference, kin: LieKinematics) -> np.ndarray:
    """Bone lengths ``(..., J)`` (0 at the root) of reference poses ``(..., J, 3)`` in metres."""
    ref = np.asarray(reference, dtype=np.float64)
    parents = np.array(kin.parents)
    lengths = np.linalg.norm(ref[..., 1:, :] - ref[..., parents[1:], :], axis=-1)
    return np.concatenate([np.zeros(lengths.shape[:-1] + (1,)), lengths], axis=-1)


def lie_forward_kinematics(lie, bone_lengths, kin: LieKinematics, *, min_angle: float = 0.01) -> np.ndarray:
    """Joint positions ``(..., J, 3)`` from Lie parameters ``(..., J, 3)`` (generator_formats.md §2.2).

    ``lie[..., 0, :]`` is the root position; ``lie[..., j, :]`` (j >= 1) the axis-angle of joint j.
    Every chain restarts from the identity rotation (also the arm chains); bone j is
    ``raw_offsets[j] * bone_lengths[..., j]`` rotated by the chain's accumulated rotation.
    ``bone_lengths`` ``(..., J)`` broadcasts against the batch dims of ``lie``.
    """
    lie = np.asarray(lie, dtype=np.float64)
    lengths = np.asarray(bone_lengths, dtype=np.float64)
    rot = rotvec_to_rotmat(lie, min_angle=min_angle)  # (..., J, 3, 3); slot 0 unused
    offsets = kin.raw_offsets * lengths[..., :, None]  # (..., J, 3)
    offsets = np.broadcast_to(offsets, lie.shape)
    joints = np.zeros_like(lie)
    joints[..., 0, :] = lie[..., 0, :]
    eye = np.broadcast_to(np.eye(3), lie.shape[:-2] + (3, 3))
    for chain in kin.chains:
        acc = eye
        for p, c in zip(chain[:-1], chain[1:]):
            acc = acc @ rot[..., c, :, :]
            joints[..., c, :] = joints[..., p, :] + np.einsum("...ij,...j->...i", acc, offsets[..., c, :])
    return joints


def lie_inverse_kinematics(joints, kin: LieKinematics) -> np.ndarray:
    """Lie parameters ``(..., J, 3)`` (slot 0 = root position) of joint positions ``(..., J, 3)``.

    Action2Motion's ``inverse_kinemetics`` (generator_formats.md §2.2): per chain the global
    rotation taking each raw offset to the bone direction, expressed relative to the chain's
    accumulated rotation. :func:`lie_forward_kinematics` with the same bone lengths reproduces the
    joints (twist about a bone is not represented and not needed).
    """
    joints = np.asarray(joints, dtype=np.float64)
    lie = np.zeros_like(joints)
    lie[..., 0, :] = joints[..., 0, :]
    eye = np.broadcast_to(np.eye(3), joints.shape[:-2] + (3, 3))
    for chain in kin.chains:
        acc = eye
        for p, c in zip(chain[:-1], chain[1:]):
            bone = joints[..., c, :] - joints[..., p, :]
            v = bone / np.maximum(np.linalg.norm(bone, axis=-1, keepdims=True), 1e-12)
            target = rotvec_to_rotmat(rotation_between(kin.raw_offsets[c], v))
            local = np.swapaxes(acc, -1, -2) @ target
            lie[..., c, :] = rotmat_to_rotvec(local)
            acc = target
    return lie


# --- coordinate frames -----------------------------------------------------------------------


def yup_to_ydown(joints) -> np.ndarray:
    """Rotate 180 degrees about x, ``(x, y, z) -> (x, -y, -z)``: HumanML3D (y up, facing +z) to the
    HumanAct12 camera frame (y down, facing -z), keeping left = +x (generator_formats.md §0.1)."""
    out = np.array(joints, dtype=np.float64, copy=True)
    out[..., 1:] *= -1.0
    return out


def recenter(joints, root: int = 0) -> np.ndarray:
    """Translate ``(..., T, J, 3)`` so that the root of the first frame is at the origin (a new array)."""
    joints = np.asarray(joints, dtype=np.float64)
    return joints - joints[..., :1, root : root + 1, :]
