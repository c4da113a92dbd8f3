"""MDM adapter: the ``results.npy`` of MDM's ``sample/generate.py``, read safely and written back in its own layout.

generate.py saves ``np.save(path, dict)``, a pickled 0-d object array (read here with the restricted
unpickler only) holding ``motion`` (N, J, 3, T) float32 joint positions, ``lengths`` (N,) int64 valid
frames (the rest is padding the model produced too), ``text`` (N str), ``num_samples`` and
``num_repetitions`` (int; row ``r * num_samples + i`` is sample i of repetition r). J = 22: text-to-motion,
HumanML3D joints (metres, y up, facing +z in frame 0, floor at y = 0); J = 24: action-to-motion, SMPL
joints in the HumanAct12 (ACTOR) frame, y down. KIT's 21 joints are refused. A plain array
(N, J, 3, T) or one sample (J, 3, T) (``results["motion"][i]`` saved alone) is read too. MDM writes no
per-sample joint file: its ``sample##_rep##_smpl_params.npy`` (render_mesh.py) is an SMPLify fit made from
``results.npy``, refused with a message saying to refine ``results.npy`` and render that.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from refiner.adapters.conversion import call_with_options
from refiner.adapters.humanml3d import to_humanact12
from refiner.core.motion import Motion
from refiner.core.rotations import yup_to_ydown
from refiner.core.safe_pickle import load_npy
from refiner.plugins import AdapterInfo, hookimpl

__all__ = ["INFO", "put_back", "read_results", "to_motions"]

INFO = AdapterInfo(
    name="mdm",
    format=(
        "results.npy of MDM's generate.py: dict with motion (N, 22, 3, T) HumanML3D joints (24 SMPL joints for "
        "action-to-motion), lengths (N,), text, num_samples, num_repetitions; or an array (N, J, 3, T) / (J, 3, T)"
    ),
    skeletons=("humanact12", "humanml3d"),
    fps=20.0,
    up="+y",
    description="MDM (Tevet et al. 2023); `refine --adapter mdm` writes results.npy back in MDM's layout.",
)

_NATIVE = {22: "humanml3d", 24: "humanact12"}  # joints per frame -> the skeleton MDM's joints are on
_SMPL_PARAMS_KEYS = {"thetas", "root_translation", "vertices"}  # render_mesh.py's per-sample file


def read_results(path) -> dict | np.ndarray:
    """MDM's ``results.npy`` as its dict (or a plain joint array as saved), unpickled with arrays only allowed.

    Raises ``ValueError`` for a file that is not ``.npy``, names anything but arrays in its pickle, or holds
    neither a dict nor an array.
    """
    arr = load_npy(path, what="MDM's results.npy (a dict saved with np.save) or a joint array")
    if arr.dtype != object:
        return arr
    value = arr.item() if arr.ndim == 0 else None
    if not isinstance(value, dict):
        raise ValueError(f"{str(path)!r}: an object array of shape {arr.shape} is not MDM's results.npy (a dict).")
    return value


def _clips(output: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(motion (N, J, 3, T) as given, lengths (N,) int)`` of MDM output; ``ValueError`` naming any problem."""
    if isinstance(output, Mapping):
        if _SMPL_PARAMS_KEYS <= set(output):
            raise ValueError("this is MDM's per-sample SMPL fit (render_mesh.py's sample##_rep##_smpl_params.npy), "
                             "made from results.npy: refine results.npy with --adapter mdm, then render the refined "
                             "file.")
        if "motion" not in output:
            raise ValueError(f"MDM results must hold the key 'motion' (N, 22, 3, T); keys: {sorted(map(str, output))}.")
        motion, lengths = output["motion"], output.get("lengths")
    else:
        motion, lengths = output, None
    motion = np.asarray(motion)
    if motion.ndim == 3:
        motion = motion[None]
    if motion.ndim != 4 or motion.shape[1] not in _NATIVE or motion.shape[2] != 3 or motion.shape[3] < 2:
        kit = " (KIT-ML's 21 joints are not supported)" if motion.ndim == 4 and motion.shape[1] == 21 else ""
        raise ValueError(f"MDM `motion` must have shape (N, 22, 3, T) or (N, 24, 3, T) with T >= 2 (or one sample "
                         f"(J, 3, T)); got {tuple(motion.shape)}{kit}.")
    if not np.issubdtype(motion.dtype, np.floating):
        raise ValueError(f"MDM `motion` must hold floats; got {motion.dtype}.")
    n, t = len(motion), motion.shape[3]
    if n == 0:
        raise ValueError("MDM `motion` holds no clips; got shape (0, J, 3, T).")
    lengths = np.full(n, t) if lengths is None else np.asarray(lengths)
    if lengths.shape != (n,) or not np.issubdtype(lengths.dtype, np.integer):
        raise ValueError(f"MDM `lengths` must be {n} integers, one per clip; got {lengths.dtype} "
                         f"{tuple(lengths.shape)}.")
    if lengths.min() < 2 or lengths.max() > t:
        raise ValueError(f"MDM `lengths` must be in 2..{t} (the frames of `motion`); got "
                         f"{lengths.min()}..{lengths.max()}.")
    for i, k in enumerate(lengths):  # padding is never read, so only valid frames must be finite
        if not np.isfinite(motion[i, ..., :k]).all():
            raise ValueError(f"MDM `motion` clip {i} holds NaN or Inf in its {k} valid frames.")
    return motion, lengths.astype(int)


def to_motions(output: Any, *, skeleton: str | None = None, fps: float = 20.0) -> list[Motion]:
    """MDM output to one :class:`~refiner.Motion` per clip, its valid frames only.

    Parameters
    ----------
    output : dict or array-like
        ``results.npy``'s dict (:func:`read_results`) or ``motion`` itself: (N, J, 3, T) or (J, 3, T) float,
        metres; J = 22 HumanML3D joints (y up), J = 24 SMPL joints in the HumanAct12 frame (y down).
    skeleton : {"humanact12", "humanml3d"}, optional
        Default (None): ``"humanact12"``: 22 joints get hands along the forearms, a 180-degree turn about x
        and frame 0's root at the origin (as the ``motiondiffuse`` adapter); ``"humanml3d"`` keeps them as
        given (22-joint files only).
    fps : float, default=20.0

    Returns
    -------
    list of Motion
        ``(lengths[i], J', 3)`` float32 metres each, on ``skeleton``.
    """
    motion, lengths = _clips(output)
    native = _NATIVE[motion.shape[1]]
    skeleton = skeleton or "humanact12"
    if skeleton not in (native, "humanact12"):
        raise ValueError(f"MDM's {motion.shape[1]}-joint output converts to skeleton 'humanact12'"
                         f"{'' if native == 'humanact12' else ' or humanml3d'}; got {skeleton!r}.")
    clips = [motion[i, ..., :k].transpose(2, 0, 1) for i, k in enumerate(lengths)]  # (T, J, 3) each
    if skeleton != native:
        clips = [to_humanact12(c) for c in clips]
    return [Motion(c, skeleton=skeleton, fps=fps) for c in clips]


def put_back(output: Any, before: list[Motion], after: list[Motion]) -> Any:
    """MDM output with the refined frames put back in its own layout: the inverse of :func:`to_motions` on the change.

    Parameters
    ----------
    output : dict or array-like
        What :func:`to_motions` converted; not modified.
    before, after : list of Motion
        :func:`to_motions` of ``output`` and the refined motions (same skeleton, frames and order).

    Returns
    -------
    dict or ndarray
        A new dict with every key of ``output`` (values shared, ``motion`` a new array of its shape and dtype),
        or a new array. Only frames where ``after`` differs from ``before`` are written: ``output``'s frame plus
        the difference, turned back into MDM's frame (hands dropped); every other value, padding included, is
        bit-identical to ``output``.
    """
    motion, lengths = _clips(output)
    if len(before) != len(motion) or len(after) != len(motion):
        raise ValueError(f"`before` and `after` must hold one motion per MDM clip ({len(motion)}); "
                         f"got {len(before)} and {len(after)}.")
    new = np.array(motion, copy=True)
    native = _NATIVE[motion.shape[1]]
    for i, (b, a, k) in enumerate(zip(before, after, lengths)):
        if a.joints.shape != b.joints.shape or b.n_frames != k or a.skeleton != b.skeleton:
            raise ValueError(f"clip {i}: `after` {a.skeleton} {a.joints.shape} does not match `before` "
                             f"{b.skeleton} {b.joints.shape} of {k} valid frames.")
        changed = np.flatnonzero((a.joints != b.joints).any(axis=(1, 2)))
        if not len(changed):
            continue
        delta = a.joints[changed].astype(np.float64) - b.joints[changed]  # (C, J', 3); exact where nothing moved
        if b.skeleton != native:  # converted in: the hands are estimates (dropped), frame 0's shift cancels
            delta = yup_to_ydown(delta[:, :22])
        frames = motion[i][..., changed].transpose(2, 0, 1) + delta
        new[i][..., changed] = frames.transpose(1, 2, 0).astype(new.dtype)  # (C, J, 3) -> MDM's (J, 3, C)
    if not isinstance(output, Mapping):
        return new if np.ndim(output) == 4 else new[0]
    return {**output, "motion": new}


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_convert_output(output: Any, skeleton: str | None, options: Mapping[str, Any]) -> list[Motion]:
    return call_with_options(to_motions, output, options, skeleton=skeleton, adapter=INFO.name)


@hookimpl
def refiner_read_file(path: Path) -> dict | np.ndarray:
    return read_results(path)


@hookimpl
def refiner_write_refined(path: Path, output: Any, before: list[Motion], after: list[Motion]) -> Path:
    path, refined = Path(path), put_back(output, before, after)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as f:  # a file object: np.save would append .npy to a name without it
        # pickled exactly as MDM's generate.py does, so MDM's own loaders read it
        np.save(f, refined, allow_pickle=True)
    os.replace(tmp, path)  # whole or not at all: an earlier results.npy is never left half-overwritten
    return path
