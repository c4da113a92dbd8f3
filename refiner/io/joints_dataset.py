"""Your own joint clips as a training set (``motion-refiner train --dataset joints --data PATH``).

Two layouts, for any registered skeleton (:func:`refiner.list_skeletons`):

* **a folder** of ``<name>.npy`` clips, each ``(T, J, 3)`` float metres in the skeleton's frame,
  and ``labels.csv`` with a header row and the columns ``name,action`` (optionally ``subject``):
  ``name`` is the file's stem, ``action`` an index 0..C-1 or an action name. An optional
  ``meta.json`` may give ``{"skeleton": "uestc", "action_names": [...], "fps": 20}``.
* **one ``.npz``** with ``clips`` (an object array of ``(T_i, J, 3)`` arrays, or a padded
  ``(N, T, J, 3)`` array plus ``lengths`` ``(N,)``), ``actions`` ``(N,)`` int, and optionally
  ``subjects`` ``(N,)`` int, ``action_names`` ``(C,)`` str, ``skeleton`` (str) and ``fps``.

Without a skeleton name the joint count picks it when exactly one registered skeleton has it
(24 humanact12, 22 humanml3d, 18 uestc, 20 cmu_mocap). Object arrays are read with the
restricted unpickler of :mod:`refiner.core.safe_pickle` (arrays only, no code).
"""
from __future__ import annotations

import csv
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from refiner.core.motion import Motion
from refiner.core.safe_pickle import load_npy
from refiner.core.skeletons import get_skeleton, list_skeletons
from refiner.io.datasets import MotionDataset

__all__ = ["load_joints_dataset"]


def load_joints_dataset(path: str | os.PathLike, *, skeleton: str | None = None) -> MotionDataset:
    """Load a folder of ``.npy`` clips plus ``labels.csv``, or one ``.npz`` (module docstring).

    Parameters
    ----------
    path : path
        The folder or the ``.npz`` file.
    skeleton : str, optional
        Registered skeleton name; overrides the file's. Default: the file's, else the only
        registered skeleton with the clips' joint count.

    Returns
    -------
    MotionDataset
        Named ``"joints"``; clips sorted by name (folder) or in file order (``.npz``), float32,
        coordinates as stored; subjects 0 where not given (then no subject split).

    Raises
    ------
    ValueError
        Missing files or keys, a clip not ``(T, J, 3)`` with T >= 2, NaN or Inf, joint counts that
        differ or fit no skeleton, an unknown skeleton, label or subject counts not matching the
        clips, action indices outside the action names.
    """
    path = Path(path)
    if path.is_dir():
        names, clips, actions, subjects, meta = _read_folder(path)
    elif path.is_file() and path.suffix == ".npz":
        names, clips, actions, subjects, meta = _read_npz(path)
    else:
        raise ValueError(f"`--data` {str(path)!r} must be a folder of .npy clips with labels.csv, or a .npz file.")
    if not clips:
        raise ValueError(f"{str(path)!r} holds no clips.")
    for i, c in enumerate(clips):
        if c.ndim != 3 or c.shape[-1] != 3 or len(c) < 2:
            raise ValueError(f"clip {names[i]!r} must have shape (T, J, 3) with T >= 2; got {tuple(c.shape)}.")
    counts = sorted({c.shape[1] for c in clips})
    if len(counts) != 1:
        raise ValueError(f"all clips must have the same joint count; got {counts}.")
    skel = get_skeleton(skeleton or meta.get("skeleton") or _skeleton_for(counts[0]))
    if skel.n_joints != counts[0]:
        raise ValueError(f"skeleton {skel.name!r} has {skel.n_joints} joints but the clips have {counts[0]}.")
    actions, action_names = _actions(actions, meta.get("action_names"), len(clips))
    fps = float(meta.get("fps", skel.fps))
    motions = []
    for name, clip, action in zip(names, clips, actions):
        try:
            motions.append(Motion(clip, skeleton=skel.name, fps=fps, action=int(action)))
        except ValueError as e:
            raise ValueError(f"clip {name!r}: {e}") from e
    subj = np.zeros(len(clips), dtype=np.int64) if subjects is None else _ints(subjects, "subjects", len(clips))
    return MotionDataset("joints", motions, list(names), subj, action_names)


def _skeleton_for(n_joints: int) -> str:
    fits = [s for s in list_skeletons() if get_skeleton(s).n_joints == n_joints]
    if len(fits) != 1:
        known = ", ".join(f"{s} ({get_skeleton(s).n_joints})" for s in list_skeletons())
        raise ValueError(f"clips have {n_joints} joints, which names no single skeleton; give the skeleton name "
                         f"(`skeleton` in the file, or --skeleton); known: {known}.")
    return fits[0]


def _ints(values, name: str, n: int) -> np.ndarray:
    arr = np.asarray(values).reshape(-1)
    if len(arr) != n:
        raise ValueError(f"`{name}` must have one entry per clip ({n}); got {len(arr)}.")
    try:
        return arr.astype(np.int64)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}` must be integers; got {arr[:3].tolist()}...") from None


def _actions(actions, names, n: int) -> tuple[np.ndarray, tuple[str, ...]]:
    """Action indices ``(N,)`` and the action names, from indices or names."""
    raw = np.asarray(actions).reshape(-1)
    if len(raw) != n:
        raise ValueError(f"labels must have one action per clip ({n} clips); got {len(raw)}.")
    names = tuple(str(a) for a in names) if names is not None else None
    as_int = [_maybe_int(a) for a in raw]
    if all(a is not None for a in as_int):
        idx = np.array(as_int, dtype=np.int64)
        names = names or tuple(f"action_{k}" for k in range(int(idx.max()) + 1))
    else:
        labels = [str(a) for a in raw]
        names = names or tuple(sorted(set(labels)))
        unknown = sorted(set(labels) - set(names))
        if unknown:
            raise ValueError(f"actions {unknown} are not in `action_names` {list(names)}.")
        idx = np.array([names.index(a) for a in labels], dtype=np.int64)
    if idx.min() < 0 or idx.max() >= len(names):
        raise ValueError(f"action indices must be in 0..{len(names) - 1} ({len(names)} action names); "
                         f"got {int(idx.min())}..{int(idx.max())}.")
    return idx, names


def _maybe_int(value):
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return int(f) if f.is_integer() else None


def _read_folder(path: Path):
    files = sorted(path.glob("*.npy"))
    labels_path = path / "labels.csv"
    if not labels_path.is_file():
        raise ValueError(f"folder {str(path)!r} has no labels.csv (columns name,action[,subject]).")
    with open(labels_path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or not {"name", "action"} <= set(rows[0]):
        raise ValueError(f"{str(labels_path)!r} needs a header with the columns name,action[,subject].")
    by_name = {r["name"].strip(): r for r in rows}
    stems = [f.stem for f in files]
    missing = sorted(set(stems) - set(by_name))[:5]
    extra = sorted(set(by_name) - set(stems))[:5]
    if missing or extra or len(rows) != len(stems):
        raise ValueError(f"labels.csv has {len(rows)} rows for {len(stems)} .npy clips in {str(path)!r}"
                         f" (clips without a label: {missing}; labels without a clip: {extra}).")
    clips = [np.load(f, allow_pickle=False) for f in files]
    actions = [by_name[s]["action"].strip() for s in stems]
    subjects = [by_name[s]["subject"] for s in stems] if "subject" in rows[0] else None
    meta_path = path / "meta.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    if not isinstance(meta, dict):
        raise ValueError(f"{str(meta_path)!r} must hold a JSON object.")
    return stems, clips, actions, subjects, meta


def _read_npz(path: Path):
    with zipfile.ZipFile(path) as z:
        members = {Path(n).stem: n for n in z.namelist()}
        for key in ("clips", "actions"):
            if key not in members:
                raise ValueError(f"{str(path)!r} lacks the key {key!r} (keys: {sorted(members)}).")
        data = {k: _read_member(z, n, path) for k, n in members.items()}
    clips = data["clips"]
    if clips.dtype == object:
        clips = [np.asarray(c, dtype=np.float64) for c in clips.reshape(-1)]
    elif clips.ndim == 4:
        lengths = data.get("lengths")
        if lengths is None:
            lengths = np.full(len(clips), clips.shape[1])
        lengths = _ints(lengths, "lengths", len(clips))
        if lengths.min() < 2 or lengths.max() > clips.shape[1]:
            raise ValueError(f"`lengths` must be in 2..{clips.shape[1]} (the padded frames); "
                             f"got {int(lengths.min())}..{int(lengths.max())}.")
        clips = [c[:n] for c, n in zip(clips, lengths)]
    else:
        raise ValueError(f"`clips` must be an object array of (T, J, 3) clips or a padded (N, T, J, 3) array; "
                         f"got shape {tuple(clips.shape)} of {clips.dtype}.")
    meta = {k: data[k].item() if data[k].ndim == 0 else data[k].tolist()
            for k in ("skeleton", "fps", "action_names") if k in data}
    names = [f"clip_{i:05d}" for i in range(len(clips))]
    return names, clips, data["actions"], data.get("subjects"), meta


def _read_member(z: zipfile.ZipFile, member: str, path: Path) -> np.ndarray:
    """One ``.npy`` member; object arrays go through the restricted unpickler."""
    with z.open(member) as f:
        return load_npy(f, what=f"an array or an object array of clips ({path.name}:{member})")
