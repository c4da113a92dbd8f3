"""HumanML3D 263-d features to canonical joints, shared by the MotionDiffuse and MoGenTS adapters.

Not a plugin itself: ``recover_from_ric`` (generator_formats.md §5.2), a joints-to-features builder
for round trips, and the mappings of the 22 HumanML3D joints onto the 24-joint HumanAct12 (§7.1)
and 18-joint NTU-VIBE / UESTC (§7.2) skeletons.
"""
from __future__ import annotations

import os
from typing import Any, Mapping, Sequence

import numpy as np

from refiner.adapters.conversion import call_with_options, check_raw, recenter
from refiner.core.motion import Motion
from refiner.core.rotations import yup_to_ydown
from refiner.core.skeleton_conversion import HAND_LENGTH, add_hands, convert
from refiner.core.validation import to_numpy

__all__ = [
    "N_FEATURES",
    "N_JOINTS",
    "HAND_LENGTH",
    "canonicalize_humanml3d",
    "convert_output",
    "features_to_motions",
    "joints_to_features",
    "recover_from_ric",
    "to_humanact12",
    "to_uestc",
]

N_FEATURES = 263
N_JOINTS = 22
_FACE = (2, 1, 17, 16)  # r_hip, l_hip, r_shoulder, l_shoulder
_FEET = ((7, 10), (8, 11))  # left (ankle, foot), right (ankle, foot)
_FOOT_CONTACT_THRESHOLD = 0.002  # squared displacement per frame, m^2 (HumanML3D's `thres`)


def _rot_y(points: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotate ``points (..., 3)`` by ``angle`` (rad, broadcast over ``points[..., 0]``) about +y."""
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


def recover_from_ric(features, n_joints: int = N_JOINTS) -> np.ndarray:
    """Joint positions from de-normalised HumanML3D features (generator_formats.md §5.2).

    Parameters
    ----------
    features : array-like of shape (..., T, D), D >= 4 + 3 * (n_joints - 1)
        De-normalised features (``x * std + mean``); only dims 0-3 (root) and the RIC positions
        4-66 are read.
    n_joints : int, default=22

    Returns
    -------
    ndarray of shape (..., T, n_joints, 3), float64
        Metres, y up, frame-0 facing +z, frame-0 root at x = z = 0, 20 fps.
    """
    x = np.asarray(features, dtype=np.float64)
    # heading half-angle a(t) = sum_{s<t} x(s, 0); q(t) rotates by 2a about +y, q^-1 by -2a
    half = np.zeros(x.shape[:-1])
    half[..., 1:] = np.cumsum(x[..., :-1, 0], axis=-1)
    inv = -2.0 * half
    step = np.zeros(x.shape[:-1] + (3,))
    step[..., 1:, 0] = x[..., :-1, 1]
    step[..., 1:, 2] = x[..., :-1, 2]
    root = np.cumsum(_rot_y(step, inv), axis=-2)
    root[..., 1] = x[..., 3]
    local = x[..., 4 : 4 + 3 * (n_joints - 1)].reshape(x.shape[:-1] + (n_joints - 1, 3))
    local = _rot_y(local, inv[..., None])
    local[..., 0] += root[..., None, 0]
    local[..., 2] += root[..., None, 2]
    return np.concatenate([root[..., None, :], local], axis=-2)


def _heading(joints: np.ndarray) -> np.ndarray:
    """Facing angle ``(T,)`` about +y (0 = facing +z) from hips and shoulders of ``(T, 22, 3)`` y-up joints."""
    r_hip, l_hip, r_sdr, l_sdr = _FACE
    across = joints[:, r_hip] - joints[:, l_hip] + joints[:, r_sdr] - joints[:, l_sdr]
    forward = np.cross(np.array([0.0, 1.0, 0.0]), across)  # horizontal
    return np.arctan2(forward[:, 0], forward[:, 2])


def canonicalize_humanml3d(joints) -> np.ndarray:
    """Move ``(T, 22, 3)`` y-up joints so that frame 0 has its root at x = z = 0 and faces +z.

    This is the frame :func:`recover_from_ric` returns (height is kept, as HumanML3D keeps it).
    """
    j = np.array(joints, dtype=np.float64, copy=True)
    j[..., 0] -= j[0, 0, 0]
    j[..., 2] -= j[0, 0, 2]
    return _rot_y(j, -_heading(j[:1])[0])


def joints_to_features(joints) -> np.ndarray:
    """HumanML3D-style 263-d features of y-up joints, enough for an exact :func:`recover_from_ric`.

    Follows HumanML3D's ``process_file`` after its skeleton retargeting and floor placement:
    root yaw velocity (half-angle), root xz velocity in the heading frame, root height, RIC
    positions, joint velocities in the heading frame and foot contacts. Differences: the heading is
    not Gaussian-smoothed, the 6D local rotations (dims 67-192, unused by ``recover_from_ric``) are
    filled with the identity, and yaw steps are wrapped to (-pi, pi] before halving.

    Parameters
    ----------
    joints : array-like of shape (T, 22, 3), T >= 2
        Metres, y up.

    Returns
    -------
    ndarray of shape (T - 1, 263), float64
        ``recover_from_ric(features)`` equals ``canonicalize_humanml3d(joints)[:-1]``.
    """
    j = check_raw(joints, name="joints", ndims=(3,), what="(T, 22, 3)")
    if j.shape[1:] != (N_JOINTS, 3) or len(j) < 2:
        raise ValueError(f"`joints` must have shape (T, 22, 3) with T >= 2; got {tuple(j.shape)}.")
    j = canonicalize_humanml3d(j)
    n = len(j)
    theta = _heading(j)
    root = j[:, 0] * np.array([1.0, 0.0, 1.0])
    ric = _rot_y(j - root[:, None], -theta[:, None])
    dtheta = np.angle(np.exp(1j * (theta[1:] - theta[:-1])))
    root_vel = _rot_y(j[1:, 0] - j[:-1, 0], -theta[1:])
    local_vel = _rot_y(j[1:] - j[:-1], -theta[:-1, None])
    feats = np.zeros((n - 1, N_FEATURES))
    feats[:, 0] = -dtheta / 2.0
    feats[:, 1] = root_vel[:, 0]
    feats[:, 2] = root_vel[:, 2]
    feats[:, 3] = j[:-1, 0, 1]
    feats[:, 4:67] = ric[:-1, 1:].reshape(n - 1, -1)
    feats[:, 67:193] = np.tile([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], 21)
    feats[:, 193:259] = local_vel.reshape(n - 1, -1)
    for k, foot in enumerate(_FEET):
        disp = np.sum((j[1:, list(foot)] - j[:-1, list(foot)]) ** 2, axis=-1)
        feats[:, 259 + 2 * k : 261 + 2 * k] = disp < _FOOT_CONTACT_THRESHOLD
    return feats


def to_humanact12(joints, *, hand_length: float = HAND_LENGTH) -> np.ndarray:
    """HumanML3D joints ``(..., T, 22, 3)`` (y up) to the 24-joint HumanAct12 frame (generator_formats.md §7.1).

    Adds the hands along the forearms, rotates 180 degrees about x (y down, facing -z) and moves
    the frame-0 pelvis to the origin. Returns float64 ``(..., T, 24, 3)``.
    """
    j = np.asarray(joints, dtype=np.float64)
    return recenter(yup_to_ydown(add_hands(j, hand_length)))


def to_uestc(joints) -> np.ndarray:
    """HumanML3D joints ``(..., T, 22, 3)`` (y up) to the 18-joint NTU-VIBE / UESTC layout (§7.2).

    Fourteen joints correspond directly. Nose, heels and head top are mesh points without a
    skeleton equivalent and are *estimated* (:func:`refiner.core.skeletons.convert`): nose = head + 0.10 m forward +
    0.05 m up; head top = head + 0.20 m up; heel = ankle + 0.055 m backward along the foot
    (ankle - foot, horizontal) - 0.04 m vertically. "Up" is the torso axis pelvis -> neck and
    "forward" the facing from hips and shoulders. Then the same 180-degree x rotation and frame-0
    root subtraction as :func:`to_humanact12`. Returns float64 ``(..., T, 18, 3)``.
    """
    return recenter(convert(joints, "humanml3d", "uestc"))


def _load_stat(value, name: str) -> np.ndarray:
    """``mean`` / ``std`` from an array or a ``.npy`` path, checked to be ``(263,)``."""
    if value is None:
        raise ValueError(
            f"`{name}` is needed to de-normalise the generator's features: pass the checkpoint's "
            f"meta/{name}.npy (array or path), or denormalized=True for already de-normalised features."
        )
    if isinstance(value, (str, os.PathLike)):
        if not os.path.isfile(value):
            raise ValueError(f"`{name}` file {str(value)!r} does not exist.")
        value = np.load(value)
    arr = to_numpy(value, name=name).astype(np.float64)
    if arr.ndim == 2 and arr.shape[0] == 1:  # a (1, 263) row, as some checkpoints store it
        arr = arr[0]
    if arr.shape != (N_FEATURES,):
        raise ValueError(f"`{name}` must have shape ({N_FEATURES},) (HumanML3D); got {tuple(arr.shape)}.")
    if not np.isfinite(arr).all():
        raise ValueError(f"`{name}` contains NaN or Inf values.")
    return arr


def _split_clips(output: Any, lengths: Sequence[int] | None, name: str) -> list[np.ndarray]:
    """A list of ``(T_b, 263)`` clips from a list of clips, a ``(T, 263)`` clip or a ``(B, T, 263)`` batch."""
    if isinstance(output, (list, tuple)):
        clips = [check_raw(c, name=f"{name}[{i}]", ndims=(2,), last=(N_FEATURES,), what="(T, 263)")
                 for i, c in enumerate(output)]
    else:
        arr = check_raw(output, name=name, ndims=(2, 3), last=(N_FEATURES,), what="(T, 263) or (B, T, 263)")
        clips = [arr] if arr.ndim == 2 else list(arr)
    if not clips:
        raise ValueError(f"`{name}` holds no clips.")
    if any(c.shape[-1] == 251 for c in clips):
        raise ValueError("KIT-ML 251-d features are not supported; only HumanML3D 263-d.")
    if lengths is not None:
        lengths = [int(n) for n in np.asarray(to_numpy(lengths, name="lengths")).reshape(-1)]
        if len(lengths) != len(clips):
            raise ValueError(f"`lengths` must have one entry per clip ({len(clips)}); got {len(lengths)}.")
        for i, (c, n) in enumerate(zip(clips, lengths)):
            if not 2 <= n <= len(c):
                raise ValueError(f"`lengths[{i}]` must be in 2..{len(c)} (frames of clip {i}); got {n}.")
        clips = [c[:n] for c, n in zip(clips, lengths)]
    return clips


def features_to_motions(
    output: Any,
    *,
    mean=None,
    std=None,
    denormalized: bool = False,
    lengths: Sequence[int] | None = None,
    skeleton: str | None = None,
    hand_length: float = HAND_LENGTH,
    actions: Sequence[int | None] | None = None,
    fps: float = 20.0,
) -> list[Motion]:
    """HumanML3D features of a text-to-motion generator to canonical :class:`~refiner.Motion` s.

    The converter of the ``motiondiffuse`` and ``mogents`` adapters.

    Parameters
    ----------
    output : array-like of shape (T, 263) or (B, T, 263), or a list of (T_b, 263)
        Generator features, normalised unless ``denormalized``.
    mean, std : array-like of shape (263,) or path to .npy
        The checkpoint's ``meta/mean.npy`` and ``meta/std.npy``; required unless ``denormalized``.
    denormalized : bool, default=False
        The features are already ``x * std + mean`` (e.g. MoGenTS ``*_data.npy``).
    lengths : sequence of int, optional
        Valid frames per clip (padded batches).
    skeleton : {"humanact12", "uestc"}, optional
        Default (None): ``"humanact12"``.
    hand_length : float, default=0.08
        Metres, for the 24-joint hands.
    actions : sequence of int or None, optional
    fps : float, default=20.0

    Returns
    -------
    list of Motion
        y down, facing -z, frame-0 root at the origin.
    """
    skeleton = "humanact12" if skeleton is None else skeleton
    if skeleton not in ("humanact12", "uestc"):
        raise ValueError(f"`skeleton` must be 'humanact12' or 'uestc' for HumanML3D features; got {skeleton!r}.")
    clips = _split_clips(output, lengths, "output")
    if not denormalized:
        mean_arr, std_arr = _load_stat(mean, "mean"), _load_stat(std, "std")
        clips = [c * std_arr + mean_arr for c in clips]
    actions = list(actions) if actions is not None else [None] * len(clips)
    if len(actions) != len(clips):
        raise ValueError(f"`actions` must have one entry per clip ({len(clips)}); got {len(actions)}.")
    convert = to_humanact12 if skeleton == "humanact12" else to_uestc
    kwargs = {"hand_length": hand_length} if skeleton == "humanact12" else {}
    return [
        Motion(convert(recover_from_ric(c), **kwargs), skeleton=skeleton, fps=fps, action=a)
        for c, a in zip(clips, actions)
    ]


def convert_output(
    output: Any, *, adapter: str, generator: Any, skeleton: str | None, options: Mapping[str, Any]
) -> list[Motion]:
    """Body of the ``refiner_convert_output`` hooks of the HumanML3D adapters: :func:`features_to_motions`.

    Adds the target ``skeleton`` to the options and, unless given or ``denormalized``, takes
    ``mean`` / ``std`` from attributes of the same names on the generator (a wrapped sampler may
    carry its checkpoint statistics); unknown options raise ``ValueError`` naming ``adapter``.
    """
    opts = dict(options)
    if not opts.get("denormalized"):
        for stat in ("mean", "std"):
            if stat not in opts and getattr(generator, stat, None) is not None:
                opts[stat] = getattr(generator, stat)
    return call_with_options(features_to_motions, output, opts, adapter=adapter, skeleton=skeleton)
