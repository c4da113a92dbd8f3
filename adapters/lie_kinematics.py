"""Action2Motion's Lie parametrisation: kinematic tables, forward and inverse kinematics (generator_formats.md §1.1, §1.2, §2.2).

Per frame, the root position followed by one axis-angle vector per non-root joint, relative to the
accumulated rotation of its kinematic chain. Used by the ``action2motion`` adapter, which exposes
the conversions to the rest of the package through the plugin hooks.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from refiner.core.rotations import rotation_between, rotmat_to_rotvec, rotvec_to_rotmat, unwrap_rotvecs, yup_to_ydown

__all__ = [
    "LIE_KINEMATICS",
    "LieKinematics",
    "continuous_lie_inverse_kinematics",
    "get_lie_kinematics",
    "lie_forward_kinematics",
    "lie_inverse_kinematics",
    "reference_bone_lengths",
]


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


def continuous_lie_inverse_kinematics(joints, kin: LieKinematics) -> np.ndarray:
    """Lie parameters ``(T, 3 J)`` of one clip ``(T, J, 3)`` that change smoothly over time, float32.

    :func:`lie_inverse_kinematics` takes each bone's global rotation as the shortest rotation from
    its raw offset direction to the bone. Those directions point up (y up) while HumanAct12 is
    y down, so the spine and leg bones sit near a rotation by pi, where the shortest rotation's axis
    is undefined: frame-to-frame steps of real clips jump by more than 1 rad, which a
    regression network cannot follow. Here the same inverse kinematics runs on the clip turned
    upright (:func:`~refiner.core.rotations.yup_to_ydown`) and the half turn is folded back into the
    first bone of every chain; then :func:`~refiner.core.rotations.unwrap_rotvecs`. Only the twist
    about bones differs: :func:`lie_forward_kinematics` gives back the same joints and steps over 1 rad
    become rare (docs/decisions.md D14).
    """
    joints = np.asarray(joints, dtype=np.float64)
    lie = lie_inverse_kinematics(yup_to_ydown(joints), kin)
    firsts = sorted({chain[1] for chain in kin.chains})
    half_turn = np.diag([1.0, -1.0, -1.0])  # yup_to_ydown as a rotation; its own inverse
    lie[:, firsts] = rotmat_to_rotvec(half_turn @ rotvec_to_rotmat(lie[:, firsts]))
    lie[:, 0] = joints[:, 0]
    return unwrap_rotvecs(lie.reshape(len(joints), -1))
