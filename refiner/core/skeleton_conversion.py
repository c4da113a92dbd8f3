"""Conversion of joint positions between the registered skeletons (generator_formats.md §1, §7).

Every conversion goes through the 24 SMPL joints (the HumanAct12 layout): the source joints are
mapped onto them in the source's frame, rotated into the target's frame, then mapped onto the
target's joints. Joints the target shares with the source are copied (rotated only); the others are
**estimates** placed from the shared ones with constants measured on HumanAct12 (subjects 1-10):

============  =========================================================================
source        estimated joints
============  =========================================================================
humanact12    none, except towards ``uestc``: nose, heels, head top (mesh points, §7.2)
humanml3d     the hands (forearm extrapolated by 0.08 m, §7.1), and as for humanact12
uestc         spine1-3, collars, head, feet (toes), hands — 10 of the 24 SMPL joints
cmu_mocap     spine1, spine2, collars — 4 of the 24 SMPL joints
============  =========================================================================

CMU's joints are matched to SMPL's by name (thorax = neck, spine = spine3, toe = foot): the marker
skeleton places them differently (e.g. its hips sit 0.14 m from the pelvis, SMPL's 0.10 m), and no
bone lengths are retargeted. Nothing is translated, so the roots keep their positions up to the
frame rotation.
"""
from __future__ import annotations

import numpy as np

from refiner.core.skeletons import Skeleton, get_skeleton

__all__ = ["HAND_LENGTH", "add_hands", "convert", "estimated_joints"]

#: Wrist-to-hand length for SMPL joints 22/23 (HumanAct12 mean 0.076 / 0.081 m, §7.1), metres.
HAND_LENGTH = 0.08
# NTU-VIBE mesh keypoints from SMPL joints (§7.2), metres. "up" is the torso axis (pelvis -> neck),
# "forward" the facing from hips and shoulders made orthogonal to it; SMPL's neck -> head bone leans
# ~45 degrees forward, so it is not the head's up axis. Chosen so that neck->nose, nose->head-top and
# ankle->heel land near the NTU-VIBE bone lengths of §1.2 (0.20, 0.19, 0.07 m) on real HumanAct12
# poses; not calibrated against SMPL vertices (no SMPL file here).
NOSE_FORWARD, NOSE_UP = 0.10, 0.05
HEAD_TOP_UP = 0.20
HEEL_BACK, HEEL_DOWN = 0.055, 0.04
# SMPL joints missing from the 18- and 20-joint layouts, as means over HumanAct12 subjects 1-10:
# spine k = pelvis + t (neck - pelvis) + f |neck - pelvis| forward;
_SPINE = {3: (0.213, -0.084), 6: (0.465, -0.031), 9: (0.564, 0.009)}
# collar = neck + t (shoulder - neck) + |shoulder - neck| (u up + f forward);
_COLLAR_T, _COLLAR_UP, _COLLAR_FORWARD = 0.518, -0.327, -0.034
# foot (toe base) = ankle + 0.095 m along the heel -> ankle direction (horizontal) - 0.091 m vertically.
_FOOT_AHEAD, _FOOT_DOWN = 0.095, 0.091

_SMPL_FACE = (2, 1, 17, 16)  # right hip, left hip, right shoulder, left shoulder
_SMPL_FEET = ((7, 10), (8, 11))  # (ankle, foot) left, right
# target joint k <- SMPL joint; None = estimated
_SMPL_TO = {
    "humanact12": tuple(range(24)),
    "humanml3d": tuple(range(22)),
    "uestc": (0, 12, 17, 19, 21, 16, 18, 20, None, 2, 5, 8, 1, 4, 7, None, None, None),
    "cmu_mocap": (0, 9, 12, 15, 16, 18, 20, 22, 17, 19, 21, 23, 1, 4, 7, 10, 2, 5, 8, 11),
}
_UESTC_FACE = (9, 12, 2, 5)
_UESTC_HEELS = ((14, 15), (11, 16))  # (ankle, heel) left, right


def estimated_joints(source: str | Skeleton, target: str | Skeleton) -> tuple[str, ...]:
    """Names of the ``target`` joints that :func:`convert` estimates rather than copies from ``source``."""
    src, tgt = get_skeleton(source), get_skeleton(target)
    _check_supported(src, tgt)
    if src.name == tgt.name:
        return ()
    have = {j for j in _SMPL_TO[src.name] if j is not None}
    return tuple(n for n, j in zip(tgt.joint_names, _SMPL_TO[tgt.name]) if j is None or j not in have)


def convert(joints, source: str | Skeleton, target: str | Skeleton) -> np.ndarray:
    """Joint positions of one skeleton expressed on another, in the target's frame.

    Parameters
    ----------
    joints : array-like of shape (..., J, 3)
        Metres, in the ``source`` skeleton's frame (its ``up`` / ``forward`` axes); any number of
        leading batch dimensions (frames, clips). Not modified.
    source, target : str or Skeleton
        Among ``"humanact12"`` (24), ``"humanml3d"`` (22), ``"uestc"`` (18, NTU-VIBE) and
        ``"cmu_mocap"`` (20).

    Returns
    -------
    ndarray of shape (..., J_target, 3), float64
        A new array. Shared joints are the source's, rotated from the source's frame into the
        target's (a proper rotation fixed by the two skeletons' ``up`` and ``forward`` axes, e.g.
        180 degrees about x from y-down HumanAct12 to y-up CMU); the joints named by
        :func:`estimated_joints` are estimates (see the module docstring). ``source == target``
        returns a float64 copy.

    Raises
    ------
    ValueError
        Unknown skeleton (the message names the known ones), a skeleton without a mapping, or
        ``joints`` not of shape ``(..., J_source, 3)`` or not finite.

    Examples
    --------
    >>> import numpy as np
    >>> convert(np.zeros((60, 24, 3)), "humanact12", "uestc").shape
    (60, 18, 3)
    """
    src, tgt = get_skeleton(source), get_skeleton(target)
    _check_supported(src, tgt)
    x = np.array(joints, dtype=np.float64, copy=True)
    if x.ndim < 2 or x.shape[-2:] != (src.n_joints, 3):
        raise ValueError(
            f"`joints` must have shape (..., {src.n_joints}, 3) for skeleton {src.name!r}; got {tuple(x.shape)}."
        )
    if not np.isfinite(x).all():
        raise ValueError("`joints` contains NaN or Inf values.")
    if src.name == tgt.name:
        return x
    smpl = _to_smpl(x, src)
    smpl = smpl @ _frame_rotation(src, tgt).T
    return _from_smpl(smpl, tgt)


def add_hands(joints: np.ndarray, hand_length: float = HAND_LENGTH) -> np.ndarray:
    """Append SMPL hands 22/23 to ``(..., 22, 3)`` joints by extending the forearms (elbow -> wrist)
    by ``hand_length`` metres; returns ``(..., 24, 3)``."""
    hands = []
    for wrist, elbow in ((20, 18), (21, 19)):
        hands.append(joints[..., wrist, :] + hand_length * _unit(joints[..., wrist, :] - joints[..., elbow, :]))
    return np.concatenate([joints, np.stack(hands, axis=-2)], axis=-2)


def _check_supported(src: Skeleton, tgt: Skeleton) -> None:
    for skel in (src, tgt):
        if skel.name not in _SMPL_TO and src.name != tgt.name:
            raise ValueError(
                f"no joint mapping for skeleton {skel.name!r}; convertible: {', '.join(sorted(_SMPL_TO))}."
            )


def _frame_rotation(src: Skeleton, tgt: Skeleton) -> np.ndarray:
    """``(3, 3)`` rotation taking the source's (left, up, forward) axes onto the target's."""
    def basis(s: Skeleton) -> np.ndarray:
        up, fwd = s.up_vector, s.forward_vector
        return np.stack([np.cross(up, fwd), up, fwd], axis=1)

    return basis(tgt) @ basis(src).T


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _body_axes(joints: np.ndarray, root: int, neck: int, face: tuple, vertical: np.ndarray):
    """Torso ``up`` (root -> neck) and ``forward`` (facing from hips and shoulders, orthogonal to up)."""
    up = _unit(joints[..., neck, :] - joints[..., root, :])
    r_hip, l_hip, r_sdr, l_sdr = face
    across = joints[..., r_hip, :] - joints[..., l_hip, :] + joints[..., r_sdr, :] - joints[..., l_sdr, :]
    forward = np.cross(vertical, across)
    return up, _unit(forward - np.sum(forward * up, axis=-1, keepdims=True) * up)


def _horizontal(v: np.ndarray, vertical: np.ndarray) -> np.ndarray:
    return v - np.sum(v * vertical, axis=-1, keepdims=True) * vertical


def _to_smpl(x: np.ndarray, src: Skeleton) -> np.ndarray:
    """Source joints ``(..., J, 3)`` to the 24 SMPL joints, in the source's frame."""
    if src.name == "humanact12":
        return x
    if src.name == "humanml3d":
        return add_hands(x)
    out = np.zeros(x.shape[:-2] + (24, 3))
    for k, j in enumerate(_SMPL_TO[src.name]):
        if j is not None:
            out[..., j, :] = x[..., k, :]
    vertical = src.up_vector
    up, forward = _body_axes(out, 0, 12, _SMPL_FACE, vertical)
    torso = np.linalg.norm(out[..., 12, :] - out[..., 0, :], axis=-1, keepdims=True)
    have = set(_SMPL_TO[src.name])
    for j, (t, f) in _SPINE.items():
        if j not in have:
            out[..., j, :] = out[..., 0, :] + t * (out[..., 12, :] - out[..., 0, :]) + f * torso * forward
    for collar, shoulder in ((13, 16), (14, 17)):
        arm = out[..., shoulder, :] - out[..., 12, :]
        length = np.linalg.norm(arm, axis=-1, keepdims=True)
        out[..., collar, :] = out[..., 12, :] + _COLLAR_T * arm + length * (_COLLAR_UP * up + _COLLAR_FORWARD * forward)
    if src.name == "uestc":
        # the inverses of the nose / head-top estimates of `_from_smpl`, averaged
        from_nose = x[..., 8, :] - NOSE_FORWARD * forward - NOSE_UP * up
        from_top = x[..., 17, :] - HEAD_TOP_UP * up
        out[..., 15, :] = 0.5 * (from_nose + from_top)
        for (ankle, heel), (_, foot) in zip(_UESTC_HEELS, _SMPL_FEET):
            ahead = _horizontal(x[..., ankle, :] - x[..., heel, :], vertical)
            norm = np.linalg.norm(ahead, axis=-1, keepdims=True)
            ahead = np.where(norm > 1e-6, ahead / np.maximum(norm, 1e-9), forward)
            out[..., foot, :] = x[..., ankle, :] + _FOOT_AHEAD * ahead - _FOOT_DOWN * vertical
        out = add_hands(out[..., :22, :])
    return out


def _from_smpl(smpl: np.ndarray, tgt: Skeleton) -> np.ndarray:
    """The 24 SMPL joints ``(..., 24, 3)``, in the target's frame, to the target's joints."""
    if tgt.name != "uestc":
        return smpl[..., list(_SMPL_TO[tgt.name]), :]
    vertical = tgt.up_vector
    up, forward = _body_axes(smpl, 0, 12, _SMPL_FACE, vertical)
    head = smpl[..., 15, :]
    extra = {8: head + NOSE_FORWARD * forward + NOSE_UP * up, 17: head + HEAD_TOP_UP * up}
    for out, (ankle, foot) in zip((15, 16), _SMPL_FEET):
        back = _horizontal(smpl[..., ankle, :] - smpl[..., foot, :], vertical)
        norm = np.linalg.norm(back, axis=-1, keepdims=True)
        back = np.where(norm > 1e-6, back / np.maximum(norm, 1e-9), -forward)
        extra[out] = smpl[..., ankle, :] + HEEL_BACK * back - HEEL_DOWN * vertical
    return np.stack([smpl[..., j, :] if j is not None else extra[k] for k, j in enumerate(_SMPL_TO["uestc"])], axis=-2)
