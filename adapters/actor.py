"""ACTOR adapter: SMPL rot6d output through the SMPL body model to canonical joints (generator_formats.md §3).

ACTOR's ``output`` (B, 25, 6, T) holds 24 SMPL rotations as 6D vectors (pytorch3d ROW convention)
and the root translation in row 24. Joints are the SMPL-neutral LBS skeleton joints (``jointstype
"smpl"``) or ACTOR's 18-joint ``"a2m"`` layout, pinned at the root every frame and then moved by the
translation relative to frame 0 (``vertstrans=True``), exactly as ACTOR's ``Rotation2xyz`` does.
The SMPL model file is not shipped (licence): pass ``smpl_path`` or set ``$MOTION_REFINER_SMPL``.
"""
from __future__ import annotations

import contextlib
import functools
import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from refiner.adapters.conversion import call_with_options, check_raw, resolve_path
from refiner.core.motion import Motion
from refiner.core.rotations import rot6d_to_rotmat
from refiner.core.safe_pickle import load_pickle
from refiner.core.validation import to_numpy
from refiner.plugins import AdapterInfo, hookimpl

__all__ = [
    "A2M_JOINTS",
    "INFO",
    "J_REGRESSOR_EXTRA_ENV",
    "SMPL_ENV",
    "load_smpl",
    "rot6d_to_joints",
    "to_motions",
]

SMPL_ENV = "MOTION_REFINER_SMPL"
J_REGRESSOR_EXTRA_ENV = "MOTION_REFINER_J_REGRESSOR_EXTRA"
#: Where the SMPL neutral model comes from (it is not shipped: SMPL's licence).
SMPL_ORIGIN = ("the SMPL neutral model basicModel_neutral_lbs_10_207_0_v1.0.0.pkl (SMPLify release, "
               "https://smplify.is.tue.mpg.de, free registration; ACTOR and MLD call it models/smpl/SMPL_NEUTRAL.pkl)")
#: ACTOR's ``a2m`` joints: indices into 24 LBS joints + 21 smplx vertex keypoints + 9
#: ``J_regressor_extra`` rows (nose = vertex 332 at 24, heels = vertices 3387 / 6787 at 31 / 34,
#: head top = extra row 3 at 48), generator_formats.md §1.2.
A2M_JOINTS = (0, 12, 17, 19, 21, 16, 18, 20, 24, 2, 5, 8, 1, 4, 7, 31, 34, 48)

INFO = AdapterInfo(
    name="actor",
    format=(
        "batch dict or tensor: 'output' (B, 25, 6, T) rot6d (pytorch3d rows; row 24 = root translation), "
        "'mask' (B, T) bool; needs the SMPL neutral model (smpl_path or $MOTION_REFINER_SMPL)"
    ),
    skeletons=("humanact12", "uestc"),
    fps=20.0,
    up="-y",
    description="ACTOR (Petrovich et al. 2021) through SMPL: 'smpl' joints for HumanAct12, 'a2m' for UESTC.",
)

_CHUNK = 512  # frames per SMPL call: bounds the (frames, 6890, 3) vertex buffers


def load_smpl(smpl_path=None):
    """The ``smplx.SMPLLayer`` of the SMPL neutral model file (cached per file and modification time).

    Parameters
    ----------
    smpl_path : path, optional
        ``SMPL_NEUTRAL.pkl`` (or an ``.npz`` of the same arrays) or a folder holding it; default
        ``$MOTION_REFINER_SMPL``. The file is read without running code from it: a ``.pkl`` may hold
        only numpy arrays, scipy sparse matrices and chumpy arrays (read as their values, chumpy is
        not needed), an ``.npz`` is read with ``allow_pickle=False``.

    Raises
    ------
    ValueError
        No path given, file missing, a pickle naming anything else (nothing it names is called), or
        not a usable SMPL model file.
    """
    path = resolve_path(smpl_path, param="smpl_path", env=SMPL_ENV, what="the SMPL neutral model file",
                        default_name="SMPL_NEUTRAL.pkl", origin=SMPL_ORIGIN)
    stat = path.stat()
    return _load_smpl_cached(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=4)
def _load_smpl_cached(path: str, mtime_ns: int, size: int):
    """Build the layer once per file version (the cache key includes mtime and size)."""
    import smplx  # only when an SMPL file is used: smplx (and torch under it) stay out of plugin discovery
    from smplx.utils import Struct

    data = _read_smpl_arrays(path)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # smplx prints a notice about 10 betas
            layer = smplx.SMPLLayer(model_path=path, data_struct=Struct(**data))
    except Exception as e:  # noqa: BLE001 -- smplx raises KeyError/AttributeError/IndexError on missing arrays
        raise ValueError(f"{path!r} is not a usable SMPL model file: {type(e).__name__}: {e}") from e
    return layer.eval()


def _read_smpl_arrays(path: str) -> dict:
    """The arrays of an SMPL model file, never running code from it (smplx itself would ``pickle.load`` it).

    A ``.npz`` is read with ``allow_pickle=False``; a ``.pkl`` through the restricted unpickler (numpy
    arrays, scipy sparse matrices, chumpy arrays as their values).
    """
    if path.endswith(".npz"):
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except Exception as e:  # noqa: BLE001 -- a bad zip or an object array
            raise ValueError(f"{path!r} is not a usable SMPL model file: {type(e).__name__}: {e}") from e
    else:
        data = load_pickle(path, what="a usable SMPL model file", sparse=True, chumpy=True)
    if not isinstance(data, dict):
        raise ValueError(f"{path!r} is not a usable SMPL model file: it holds a {type(data).__name__}, not a dict.")
    return data


def rot6d_to_joints(
    output,
    mask=None,
    *,
    lengths: Sequence[int] | None = None,
    skeleton: str = "humanact12",
    smpl_path=None,
    j_regressor_extra=None,
    vertstrans: bool = True,
) -> list[np.ndarray]:
    """Joint positions of ACTOR's rot6d output (generator_formats.md §3.2).

    Parameters
    ----------
    output : array-like of shape (B, 25, 6, T) or (25, 6, T)
        Rows 0-23: SMPL global orientation and body rotations as 6D (first two rows of each
        matrix); row 24, values 0-2: root translation in metres. ``(B, 24, 6, T)`` (a model
        trained without translation) is accepted and gives no translation.
    mask : array-like of shape (B, T), bool, optional
        Valid frames (a prefix of each clip); padded frames are dropped, never decoded.
    lengths : sequence of int, optional
        Valid frames per clip, instead of ``mask``.
    skeleton : {"humanact12", "uestc"}, default="humanact12"
        ``"humanact12"``: the 24 SMPL joints (ACTOR ``jointstype="smpl"``); ``"uestc"``: the 18
        NTU-VIBE joints (``"a2m"``), which needs ``j_regressor_extra``.
    smpl_path : path, optional
        SMPL neutral model (``SMPL_NEUTRAL.pkl`` or its folder); default ``$MOTION_REFINER_SMPL``.
    j_regressor_extra : array-like of shape (9, V) or path, optional
        ACTOR's ``J_regressor_extra.npy``; default ``$MOTION_REFINER_J_REGRESSOR_EXTRA`` or the
        file of that name beside the SMPL model. Only for ``"uestc"``.
    vertstrans : bool, default=True
        Add the translation relative to frame 0 (ACTOR's evaluation setting for HumanAct12).

    Returns
    -------
    list of ndarray of shape (T_b, J, 3), float32
        One per clip, metres, HumanAct12 camera frame (y down), frame-0 root at the origin.
    """
    if skeleton not in ("humanact12", "uestc"):
        raise ValueError(f"`skeleton` must be 'humanact12' or 'uestc' for ACTOR output; got {skeleton!r}.")
    x = check_raw(output, name="output", ndims=(3, 4), what="(B, 25, 6, T) or (25, 6, T)")
    if x.ndim == 3:
        x = x[None]
    if x.shape[1] not in (24, 25) or x.shape[2] != 6:
        raise ValueError(
            f"`output` must have shape (B, 25, 6, T) (24 rot6d rows + translation); got {tuple(x.shape)}."
        )
    n_valid = _valid_frames(mask, lengths, x.shape[0], x.shape[3])
    layer = load_smpl(smpl_path)
    extra = _load_j_regressor_extra(j_regressor_extra, smpl_path, layer) if skeleton == "uestc" else None
    frames = np.concatenate([x[b, :, :, :n].transpose(2, 0, 1) for b, n in enumerate(n_valid)])  # (F, 25, 6)
    rotmats = rot6d_to_rotmat(frames[:, :24])
    joints = _smpl_joints(layer, rotmats, extra)
    joints = joints - joints[:, :1]  # root pinned every frame (ACTOR subtracts it for all joint types)
    out, start = [], 0
    for n in n_valid:
        clip = joints[start : start + n]
        if vertstrans and x.shape[1] == 25:
            trans = frames[start : start + n, 24, :3]
            clip = clip + (trans - trans[:1])[:, None, :]
        out.append(clip.astype(np.float32))
        start += n
    return out


def to_motions(
    output: Any,
    *,
    mask=None,
    lengths: Sequence[int] | None = None,
    skeleton: str | None = None,
    smpl_path=None,
    j_regressor_extra=None,
    vertstrans: bool = True,
    actions: Sequence[int | None] | None = None,
    fps: float = 20.0,
) -> list[Motion]:
    """ACTOR output (the ``generate`` batch dict or the bare ``output`` tensor) to canonical motions.

    A dict supplies ``output`` and, unless given here, ``mask``, ``lengths`` and the labels ``y``.
    Other parameters as in :func:`rot6d_to_joints`; ``skeleton`` defaults to ``"humanact12"``.
    """
    if isinstance(output, Mapping):
        if "output" not in output:
            raise ValueError(f"ACTOR batch dict must hold 'output' (B, 25, 6, T); got keys {sorted(output)}.")
        if mask is None and lengths is None:
            mask = output.get("mask")
            lengths = output.get("lengths") if mask is None else None
        actions = output.get("y") if actions is None else actions
        output = output["output"]
    skeleton = skeleton or "humanact12"
    clips = rot6d_to_joints(output, mask, lengths=lengths, skeleton=skeleton, smpl_path=smpl_path,
                            j_regressor_extra=j_regressor_extra, vertstrans=vertstrans)
    labels = [None] * len(clips) if actions is None else [int(a) for a in to_numpy(actions, name="actions").reshape(-1)]
    if len(labels) != len(clips):
        raise ValueError(f"`actions` must have one entry per clip ({len(clips)}); got {len(labels)}.")
    return [Motion(c, skeleton=skeleton, fps=fps, action=a) for c, a in zip(clips, labels)]


def _valid_frames(mask, lengths, n_clips: int, n_frames: int) -> list[int]:
    """Valid frame count per clip from a prefix ``mask`` (B, T) or ``lengths`` (B,)."""
    if mask is not None:
        m = to_numpy(mask, name="mask")
        if m.shape != (n_clips, n_frames):
            raise ValueError(f"`mask` must have shape (B, T) = {(n_clips, n_frames)}; got {tuple(m.shape)}.")
        m = m.astype(bool)
        counts = m.sum(axis=1)
        prefix = np.arange(n_frames)[None, :] < counts[:, None]
        if not np.array_equal(m, prefix):
            raise ValueError("`mask` must mark a prefix of valid frames in every clip (ACTOR pads at the end).")
    elif lengths is not None:
        counts = to_numpy(lengths, name="lengths").reshape(-1).astype(np.int64)
        if counts.shape != (n_clips,):
            raise ValueError(f"`lengths` must have one entry per clip ({n_clips}); got shape {tuple(counts.shape)}.")
        if (counts > n_frames).any():
            raise ValueError(f"`lengths` must be at most T={n_frames}; got {counts.tolist()}.")
    else:
        counts = np.full(n_clips, n_frames)
    if (counts < 2).any():
        raise ValueError(f"every clip needs at least 2 valid frames; got {counts.tolist()}.")
    return [int(c) for c in counts]


def _load_j_regressor_extra(value, smpl_path, layer) -> np.ndarray:
    """ACTOR's 9-row extra joint regressor, from an array, a path, the env var or beside the SMPL file."""
    smpl_location = smpl_path or os.environ.get(SMPL_ENV)
    if value is None and not os.environ.get(J_REGRESSOR_EXTRA_ENV) and smpl_location:
        base = Path(smpl_location).expanduser()
        beside = (base if base.is_dir() else base.parent) / "J_regressor_extra.npy"
        if beside.is_file():
            value = beside
    if value is None or isinstance(value, (str, os.PathLike)):
        path = resolve_path(value, param="j_regressor_extra", env=J_REGRESSOR_EXTRA_ENV,
                            what="ACTOR's J_regressor_extra.npy (for the 18-joint UESTC layout)",
                            origin="ACTOR's SMPL files, models/smpl/J_regressor_extra.npy (https://github.com/Mathux/ACTOR)")
        value = np.load(path)
    arr = check_raw(value, name="j_regressor_extra", ndims=(2,), what="(9, V)")
    n_verts = layer.v_template.shape[0]
    if arr.shape != (9, n_verts):
        raise ValueError(f"`j_regressor_extra` must have shape (9, {n_verts}); got {tuple(arr.shape)}.")
    return arr


def _smpl_joints(layer, rotmats: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
    """SMPL joints ``(F, 24, 3)``, or the 18 ``a2m`` joints when ``extra`` is given, for ``(F, 24, 3, 3)`` rotations."""
    import torch  # here, not at the top: registering the built-in plugins must not import torch

    out = []
    with torch.no_grad():
        for s in range(0, len(rotmats), _CHUNK):
            r = torch.as_tensor(rotmats[s : s + _CHUNK], dtype=layer.shapedirs.dtype)
            res = layer(global_orient=r[:, :1], body_pose=r[:, 1:24])
            if extra is None:
                out.append(res.joints[:, :24].double().numpy())
            else:
                reg = torch.as_tensor(extra, dtype=res.vertices.dtype)
                all_joints = torch.cat([res.joints, torch.einsum("jv,bvc->bjc", reg, res.vertices)], dim=1)
                out.append(all_joints[:, list(A2M_JOINTS)].double().numpy())
    return np.concatenate(out)


def _is_actor_model(generator: Any) -> bool:
    """Duck-typed ACTOR ``CAE``: a ``generate(classes, durations, ...)`` method plus SMPL settings."""
    return callable(getattr(generator, "generate", None)) and hasattr(generator, "param2xyz") \
        and hasattr(generator, "rotation2xyz")


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_recognize_generator(generator: Any) -> str | None:
    return INFO.name if _is_actor_model(generator) else None


@hookimpl
def refiner_sample_generator(generator: Any, action: Any, n: int, options: Mapping[str, Any]):
    if not _is_actor_model(generator):
        return None  # RefinedGenerator then calls generator.sample / generator itself
    import torch  # an ACTOR model was passed, so torch is loaded already; not imported at plugin discovery

    if isinstance(action, bool) or not isinstance(action, (int, np.integer)):
        raise ValueError(f"ACTOR needs an integer action index; got {action!r}.")
    opts = dict(options)
    n_frames = int(opts.pop("n_frames", 60))
    classes = torch.full((n,), int(action), dtype=torch.long)
    durations = torch.full((n,), n_frames, dtype=torch.long)
    with torch.no_grad():
        return generator.generate(classes, durations, **opts)


@hookimpl
def refiner_convert_output(output: Any, skeleton: str | None, options: Mapping[str, Any]) -> list[Motion]:
    return call_with_options(to_motions, output, options, adapter=INFO.name, skeleton=skeleton)
