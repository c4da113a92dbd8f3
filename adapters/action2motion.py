"""Action2Motion adapter: Lie-algebra VAE output and xyz samples to canonical joints (generator_formats.md §2).

The Lie VAE emits per frame the root position followed by one axis-angle vector per non-root
joint; joints come from forward kinematics with Action2Motion's raw offsets and the bone lengths
of a reference skeleton (§2.2). The xyz VAE emits joint positions directly.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from refiner.adapters.conversion import call_with_options, check_raw, recenter as _recenter
from refiner.adapters.lie_kinematics import (
    continuous_lie_inverse_kinematics,
    get_lie_kinematics,
    lie_forward_kinematics,
    lie_inverse_kinematics,
    reference_bone_lengths,
)
from refiner.core.motion import Motion
from refiner.plugins import AdapterInfo, hookimpl

__all__ = ["INFO", "from_motions", "joints_to_lie", "lie_to_joints", "to_motions", "xyz_to_joints"]

INFO = AdapterInfo(
    name="action2motion",
    format=(
        "Lie VAE (N, 60, 72|54): root xyz + axis-angle per joint, decoded by FK with reference bone "
        "lengths; or xyz VAE joints (N, 60, 72|54) / (60, J, 3) (pass representation='lie'|'xyz')"
    ),
    skeletons=("humanact12", "uestc"),
    fps=20.0,
    up="-y",
    description="Action2Motion (Guo et al. 2020): HumanAct12 24 joints, NTU-VIBE 18 joints (skeleton 'uestc').",
)

_DATASET_OF_SKELETON = {"humanact12": "humanact12", "uestc": "ntu13"}


def lie_to_joints(lie, reference=None, dataset: str = "humanact12", *, recenter: bool = True) -> np.ndarray:
    """Decode Action2Motion Lie output into joint positions by forward kinematics (§2.2).

    Parameters
    ----------
    lie : array-like of shape (T, D) or (N, T, D), D = 72 (humanact12) or 54 (ntu13)
        Raw Lie VAE output: ``[0:3]`` root position in metres, then the axis-angle vector (rad)
        of every non-root joint in joint order.
    reference : array-like of shape (J, 3) or (N, J, 3), or Motion, optional
        Pose(s) whose bone *lengths* are used: a real clip's first frame (Action2Motion draws
        one per sample), or a :class:`~refiner.Motion` (its first frame). Default: the fallback
        length table of generator_formats.md §1.
    dataset : {"humanact12", "ntu13"}, default="humanact12"
        ``"uestc"`` is accepted for ``"ntu13"`` (same 18-joint layout).
    recenter : bool, default=True
        Subtract the frame-0 root, as Action2Motion does before saving (§2.3).

    Returns
    -------
    ndarray of shape (T, J, 3) or (N, T, J, 3), float32
        Metres, y-down camera frame of the training data.

    Examples
    --------
    >>> import numpy as np
    >>> joints = lie_to_joints(np.zeros((60, 72)))
    >>> joints.shape, round(float(joints[0, 15, 1]), 3)  # all-zero rotations: spine along +y
    ((60, 24, 3), 0.519)
    """
    kin = get_lie_kinematics(dataset)
    dim = 3 * kin.n_joints
    x = check_raw(lie, name="lie", ndims=(2, 3), what=f"(T, {dim}) or (N, T, {dim}) for dataset {dataset!r}")
    if x.shape[-1] != dim:
        hint = " (54 values per frame is ntu13)" if x.shape[-1] == 54 else " (72 values per frame is humanact12)" \
            if x.shape[-1] == 72 else ""
        raise ValueError(
            f"`lie` must have shape (T, {dim}) or (N, T, {dim}) for dataset {dataset!r}; "
            f"got {tuple(x.shape)}{hint}."
        )
    lie3 = x.reshape(x.shape[:-1] + (kin.n_joints, 3))
    lengths = _bone_lengths(reference, kin, x)
    joints = lie_forward_kinematics(lie3, lengths, kin)
    if recenter:
        joints = _recenter(joints)
    return joints.astype(np.float32)


def joints_to_lie(joints, dataset: str = "humanact12", *, continuous: bool = False) -> np.ndarray:
    """Action2Motion Lie parameters of joint positions (inverse kinematics, §2.2).

    Parameters
    ----------
    joints : array-like of shape (T, J, 3) or (N, T, J, 3)
        Metres; J = 24 (humanact12) or 18 (ntu13).
    dataset : {"humanact12", "ntu13"}, default="humanact12"
    continuous : bool, default=False
        False: Action2Motion's own inverse kinematics (angles in [0, pi], which jump where a bone
        turns through pi). True: parameters that change smoothly over time, with norms up to
        2 pi (:func:`~refiner.adapters.lie_kinematics.continuous_lie_inverse_kinematics`; regression
        targets for a Lie VAE); they decode to the same joints.

    Returns
    -------
    ndarray of shape (T, 3 * J) or (N, T, 3 * J), float32
        Same layout as the Lie VAE output. ``lie_to_joints(lie, reference=joints[..., 0, :, :],
        recenter=False)`` reproduces ``joints`` when their bone lengths are constant over time.
    """
    kin = get_lie_kinematics(dataset)
    x = check_raw(joints, name="joints", ndims=(3, 4), last=(3,), what=f"(T, {kin.n_joints}, 3) or (N, T, {kin.n_joints}, 3)")
    if x.shape[-2] != kin.n_joints:
        raise ValueError(
            f"`joints` must have {kin.n_joints} joints for dataset {dataset!r}; got shape {tuple(x.shape)}."
        )
    if continuous:  # clip by clip: the choice of each frame's rotation vector follows the previous frame
        return np.stack([continuous_lie_inverse_kinematics(clip, kin) for clip in x.reshape((-1,) + x.shape[-3:])]
                        ).reshape(x.shape[:-2] + (3 * kin.n_joints,))
    lie = lie_inverse_kinematics(x, kin)
    return lie.reshape(x.shape[:-2] + (3 * kin.n_joints,)).astype(np.float32)


def xyz_to_joints(xyz, dataset: str | None = None) -> np.ndarray:
    """Action2Motion xyz VAE output as ``(..., T, J, 3)`` float32: a reshape, values unchanged.

    Parameters
    ----------
    xyz : array-like of shape (T, 3J), (N, T, 3J), (T, J, 3) or (N, T, J, 3)
        J = 24 (humanact12) or 18 (ntu13).
    dataset : {"humanact12", "ntu13"}, optional
        Checks J when given; otherwise J is inferred (24 or 18).
    """
    x = check_raw(xyz, name="xyz", ndims=(2, 3, 4), what="(T, 3J), (N, T, 3J), (T, J, 3) or (N, T, J, 3)")
    allowed = (get_lie_kinematics(dataset).n_joints,) if dataset is not None else (24, 18)
    if x.ndim in (2, 3) and x.shape[-1] in tuple(3 * j for j in allowed):
        x = x.reshape(x.shape[:-1] + (x.shape[-1] // 3, 3))
    elif not (x.ndim in (3, 4) and x.shape[-1] == 3 and x.shape[-2] in allowed):
        raise ValueError(
            f"`xyz` must have shape (T, 3J), (N, T, 3J), (T, J, 3) or (N, T, J, 3) with J in {allowed}; "
            f"got {tuple(x.shape)}."
        )
    return x.astype(np.float32)


def to_motions(
    output: Any,
    *,
    representation: str | None = None,
    reference=None,
    skeleton: str | None = None,
    recenter: bool | None = None,
    actions: Sequence[int | None] | None = None,
    fps: float = 20.0,
) -> list[Motion]:
    """Action2Motion output to canonical motions.

    Parameters
    ----------
    output : array-like
        Lie output ``(N, T, 72|54)`` / ``(T, 72|54)``, or xyz output of the same shapes or
        ``(T, J, 3)`` / ``(N, T, J, 3)``.
    representation : {"lie", "xyz"}, optional
        Required for ``(..., 72|54)`` arrays, which look the same for both VAEs; ``(..., J, 3)``
        arrays are xyz.
    reference : optional
        Bone-length reference for the Lie path, see :func:`lie_to_joints`.
    skeleton : {"humanact12", "uestc"}, optional
        Inferred from the joint count when omitted.
    recenter : bool, optional
        Subtract the frame-0 root. Default: True for Lie output (§2.4), False for xyz output,
        which is passed through unchanged (Action2Motion's evaluation does not re-centre it).
    actions : sequence of int or None, optional
        Class label per clip.
    fps : float, default=20.0
    """
    arr = check_raw(output, name="output", ndims=(2, 3, 4), what="(N, T, 72|54), (T, 72|54), (T, J, 3) or (N, T, J, 3)")
    if arr.shape[-1] == 3 and arr.ndim >= 3:
        representation = representation or "xyz"
    if representation not in ("lie", "xyz"):
        raise ValueError(
            f"`representation` must be 'lie' or 'xyz' for Action2Motion output of shape {tuple(arr.shape)} "
            f"(both VAEs emit 72|54 values per frame); got {representation!r}."
        )
    if skeleton is not None and skeleton not in _DATASET_OF_SKELETON:
        raise ValueError(f"`skeleton` must be one of {sorted(_DATASET_OF_SKELETON)} for action2motion; got {skeleton!r}.")
    if representation == "lie":
        if skeleton is None:
            skeleton = {72: "humanact12", 54: "uestc"}.get(arr.shape[-1], "humanact12")
        joints = lie_to_joints(arr, reference, _DATASET_OF_SKELETON[skeleton], recenter=True if recenter is None else recenter)
    else:
        joints = xyz_to_joints(arr, None if skeleton is None else _DATASET_OF_SKELETON[skeleton])
        skeleton = skeleton or ("humanact12" if joints.shape[-2] == 24 else "uestc")
        if recenter:
            joints = _recenter(joints).astype(np.float32)
    batch = joints if joints.ndim == 4 else joints[None]
    actions = list(actions) if actions is not None else [None] * len(batch)
    if len(actions) != len(batch):
        raise ValueError(f"`actions` must have one entry per clip ({len(batch)}); got {len(actions)}.")
    return [Motion(j, skeleton=skeleton, fps=fps, action=None if a is None else int(a)) for j, a in zip(batch, actions)]


def from_motions(motions: Sequence[Motion], *, representation: str = "lie", continuous: bool = False) -> list[np.ndarray]:
    """Canonical motions to Action2Motion's raw per-clip output: the inverse of :func:`to_motions`.

    Parameters
    ----------
    motions : sequence of Motion
        On skeleton ``"humanact12"`` (24 joints) or ``"uestc"`` (the 18 ntu13 joints), metres.
    representation : {"lie", "xyz"}, default="lie"
        ``"lie"``: Lie VAE parameters (:func:`joints_to_lie`); ``"xyz"``: xyz VAE joints, flattened.
    continuous : bool, default=False
        For ``"lie"``: parameters that change smoothly over time (see :func:`joints_to_lie`).

    Returns
    -------
    list of ndarray of shape (T_i, 3 * J), float32
        One per motion. ``to_motions(out, representation=..., reference=motion.joints[0],
        recenter=False)`` gives the motion back (Lie: when its bone lengths are constant).
    """
    if representation not in ("lie", "xyz"):
        raise ValueError(f"`representation` must be 'lie' or 'xyz'; got {representation!r}.")
    out = []
    for m in motions:
        if m.skeleton not in _DATASET_OF_SKELETON:
            raise ValueError(f"action2motion encodes skeletons {sorted(_DATASET_OF_SKELETON)}; got {m.skeleton!r}.")
        if representation == "lie":
            out.append(joints_to_lie(m.joints, _DATASET_OF_SKELETON[m.skeleton], continuous=continuous))
        else:
            out.append(m.joints.reshape(m.n_frames, -1).astype(np.float32))
    return out


def _bone_lengths(reference, kin, lie: np.ndarray) -> np.ndarray:
    """Per-joint bone lengths ``(J,)`` or ``(N, 1, J)`` from a reference pose, Motion or the default table."""
    if reference is None:
        return kin.default_bone_lengths
    if isinstance(reference, Motion):
        reference = reference.joints[0]
    ref = check_raw(reference, name="reference", ndims=(2, 3), last=(3,), what=f"({kin.n_joints}, 3) or (N, {kin.n_joints}, 3)")
    if ref.shape[-2] != kin.n_joints:
        raise ValueError(f"`reference` must have {kin.n_joints} joints; got shape {tuple(ref.shape)}.")
    lengths = reference_bone_lengths(ref, kin)
    if ref.ndim == 3:
        if lie.ndim != 3 or len(ref) != len(lie):
            raise ValueError(
                f"`reference` of shape {tuple(ref.shape)} needs one pose per sample of `lie` {tuple(lie.shape)}."
            )
        lengths = lengths[:, None, :]
    if (lengths[..., 1:] < 1e-4).any():
        raise ValueError("`reference` has a zero-length bone; pass a real pose (e.g. a clip's first frame).")
    return lengths


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_convert_output(output: Any, skeleton: str | None, options: Mapping[str, Any]) -> list[Motion]:
    return call_with_options(to_motions, output, options, adapter=INFO.name, skeleton=skeleton)


@hookimpl
def refiner_encode_motions(motions: list[Motion], options: Mapping[str, Any]) -> list[np.ndarray]:
    return call_with_options(from_motions, motions, options, adapter=INFO.name)
