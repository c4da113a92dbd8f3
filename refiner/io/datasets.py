"""Real motion datasets: HumanAct12 (three source formats) and Action2Motion's CMU-Mocap subset.

Data are never shipped with the package (licences); pass a path, set ``MOTION_REFINER_DATA`` to the
folder holding ``humanact12/`` and ``cmu_mocap/``, or keep them in ``../shared/data`` beside the
working directory. Where the files come from: :mod:`refiner.io.data_sources`.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from refiner.core.motion import Motion
from refiner.core.safe_pickle import load_pickle
from refiner.io.data_sources import missing_message

__all__ = [
    "HUMANACT12_ACTIONS",
    "CMU_ACTIONS",
    "SPLITS",
    "CMU_TEST_SUBJECTS",
    "MotionDataset",
    "load_humanact12",
    "load_cmu_mocap",
    "load_dataset",
    "default_data_dir",
    "parse_humanact12_name",
]

HUMANACT12_ACTIONS = (
    "warm_up", "walk", "run", "jump", "drink", "lift_dumbbell", "sit", "eat",
    "turn_steering_wheel", "phone", "boxing", "throw",
)
CMU_ACTIONS = ("walk", "wash", "run", "jump", "animal_behavior", "dance", "step", "climb")

#: The held-out protocol used by every benchmark: subjects 1-10 train, 11-12 test.
SPLITS = {"train": tuple(range(1, 11)), "test": (11, 12)}

#: The CMU subset's held-out subjects: 273 of 1,088 clips (25 %), 21-29 % of every action's clips but
#: "step", whose 68 clips all come from subject 83 (so it is in training only). Chosen greedily from the
#: highest subject number down, adding a subject while some action it has stayed under 15 % held out
#: and no action passed 30 %. Train = every other subject.
CMU_TEST_SUBJECTS = (40, 41, 55, 93, 103, 104, 106, 118, 128, 132, 133, 136)

# CMU ASF "length" units: 1 unit = (1 / 0.45) inch.
_CMU_UNIT_METRES = 0.0254 / 0.45

_NAME_RE = re.compile(r"^P(\d+)G(\d+)R(\d+)F(\d+)T(\d+)A(\d{2})(\d{2})$")


@dataclass
class MotionDataset:
    """A list of clips with their metadata.

    Attributes
    ----------
    name : str
        ``"humanact12"``, ``"cmu_mocap"`` or ``"joints"`` (user clips, :mod:`refiner.io.joints_dataset`).
    motions : list of Motion
    names : list of str
        Clip names (empty strings where the source has none).
    subjects : ndarray of int, shape (N,)
        Performer id per clip (0 where unknown).
    action_names : tuple of str
    fine_codes : list of str
    """

    name: str
    motions: list[Motion]
    names: list[str]
    subjects: np.ndarray
    action_names: tuple[str, ...]
    fine_codes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.motions)

    def __getitem__(self, i: int) -> Motion:
        return self.motions[i]

    def __iter__(self) -> Iterator[Motion]:
        return iter(self.motions)

    @property
    def actions(self) -> np.ndarray:
        return np.array([m.action for m in self.motions], dtype=np.int64)

    @property
    def n_frames(self) -> int:
        return sum(m.n_frames for m in self.motions)

    def subset(self, indices: Sequence[int]) -> "MotionDataset":
        idx = [int(i) for i in indices]
        return MotionDataset(
            self.name,
            [self.motions[i] for i in idx],
            [self.names[i] for i in idx],
            self.subjects[idx],
            self.action_names,
            [self.fine_codes[i] for i in idx] if self.fine_codes else [],
        )

    def split(self, split: str) -> "MotionDataset":
        """Clips of the named split: ``"train"``, ``"test"`` or ``"all"``. HumanAct12 (and any other
        dataset with subject ids): subjects 1-10 / 11-12; CMU: every subject but
        :data:`CMU_TEST_SUBJECTS` / those."""
        if split == "all":
            return self
        if split not in SPLITS:
            raise ValueError(f"unknown split {split!r}; known: all, {', '.join(SPLITS)}.")
        if not self.subjects.any():
            raise ValueError(f"dataset {self.name!r} has no subject ids, so it cannot be split by subject.")
        if self.name == "cmu_mocap":
            test = np.isin(self.subjects, CMU_TEST_SUBJECTS)
            return self.subset(np.flatnonzero(test if split == "test" else ~test))
        return self.subset(np.flatnonzero(np.isin(self.subjects, SPLITS[split])))

    def __repr__(self) -> str:
        return f"MotionDataset({self.name!r}, clips={len(self)}, frames={self.n_frames})"


def default_data_dir() -> Path:
    """The folder holding ``humanact12/`` and ``cmu_mocap/``.

    ``$MOTION_REFINER_DATA`` if set, else the first ``shared/data`` found beside the working
    directory or any of its parents, else beside the source checkout.
    """
    env = os.environ.get("MOTION_REFINER_DATA")
    if env:
        return Path(env)
    starts = [Path.cwd(), Path(__file__).resolve().parents[1]]
    for start in starts:
        for folder in (start, *start.parents):
            candidate = folder.parent / "shared" / "data"
            if (candidate / "humanact12").is_dir():
                return candidate
    return Path.cwd().parent / "shared" / "data"


def parse_humanact12_name(name: str) -> dict:
    """Fields of a clip name ``P{subject}G{group}R{rep}F{start}T{end}A{coarse}{fine}``."""
    m = _NAME_RE.match(name)
    if not m:
        raise ValueError(f"{name!r} is not a HumanAct12 clip name (P..G..R..F..T..A....).")
    subject, group, rep, start, end, coarse, fine = m.groups()
    return {
        "subject": int(subject), "group": int(group), "repetition": int(rep), "start": int(start),
        "end": int(end), "action": int(coarse) - 1, "fine_code": coarse + fine,
    }


def load_humanact12(path: str | os.PathLike | None = None, *, names: Sequence[str] | None = None) -> MotionDataset:
    """Load HumanAct12 as canonical motions (24 joints, metres, y down, native camera frame).

    Parameters
    ----------
    path : path, optional
        One of: the packed ``humanact12_joints.npz``; a folder of Action2Motion ``<name>.npy``
        clips ``(T, 24, 3)``; ACTOR's ``humanact12poses.pkl`` (keys ``joints3D``, ``y``).
        Default: ``default_data_dir() / "humanact12" / "humanact12_joints.npz"``.
    names : sequence of str, optional
        Clip names for a ``.pkl`` source (which has none); ACTOR's clips are in sorted-name order,
        so the names of the packed ``.npz`` fit. Without them the clips carry no subject ids.

    Returns
    -------
    MotionDataset
        Clips sorted by name (``.npz`` and folder sources), each a :class:`Motion` with its
        coarse action (0..11) at 20 fps, coordinates exactly as stored.
    """
    path = Path(path) if path is not None else default_data_dir() / "humanact12" / "humanact12_joints.npz"
    if path.is_dir():
        return _humanact12_from_folder(path)
    if not path.is_file():
        raise ValueError(missing_message("humanact12", path))
    if path.suffix == ".npz":
        return _humanact12_from_npz(path)
    if path.suffix == ".pkl":
        return _humanact12_from_pkl(path, names)
    raise ValueError(f"unsupported HumanAct12 source {str(path)!r}: expected .npz, .pkl or a folder of .npy clips.")


def load_cmu_mocap(path: str | os.PathLike | None = None, *, units: str = "m") -> MotionDataset:
    """Load Action2Motion's labelled CMU-Mocap subset (1,088 clips, 20 joints, y up).

    Parameters
    ----------
    path : path, optional
        ``cmu_mocap_labeled_joints.npz``; default under :func:`default_data_dir`.
    units : {"m", "raw"}, default="m"
        ``"m"`` converts CMU units to metres (x 0.0564); ``"raw"`` keeps the stored values
        (the CMU evaluator wants raw / 20).
    """
    if units not in ("m", "raw"):
        raise ValueError(f"`units` must be 'm' or 'raw'; got {units!r}.")
    path = Path(path) if path is not None else default_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz"
    if not path.is_file():
        raise ValueError(missing_message("cmu_mocap", path))
    with np.load(path) as d:
        _check_keys(path, d, ("names", "offsets", "joints", "label"))
        joints, offsets, labels = d["joints"], d["offsets"], d["label"]
        names = [str(n) for n in d["names"]]
    scale = _CMU_UNIT_METRES if units == "m" else 1.0
    motions = [
        Motion(joints[offsets[i] : offsets[i + 1]] * scale, skeleton="cmu_mocap", fps=20.0, action=int(labels[i]))
        for i in range(len(names))
    ]
    subjects = np.array([int(n.split("_")[0]) for n in names], dtype=np.int64)
    return MotionDataset("cmu_mocap", motions, names, subjects, CMU_ACTIONS)


def load_dataset(name: str, path: str | os.PathLike | None = None, *, skeleton: str | None = None) -> MotionDataset:
    """Load a dataset by name: ``"humanact12"``, ``"cmu_mocap"`` or ``"joints"`` (your own clips at
    ``path``, any registered ``skeleton``: :func:`refiner.io.joints_dataset.load_joints_dataset`)."""
    if name == "joints":
        from refiner.io.joints_dataset import load_joints_dataset  # here: joints_dataset imports this module

        if path is None:
            raise ValueError("the 'joints' dataset needs a path (--data): a folder of .npy clips with labels.csv, or a .npz.")
        return load_joints_dataset(path, skeleton=skeleton)
    if skeleton is not None:
        raise ValueError(f"`skeleton` applies to the 'joints' dataset only; {name!r} has its own.")
    loaders = {"humanact12": load_humanact12, "cmu_mocap": load_cmu_mocap}
    if name not in loaders:
        raise ValueError(f"unknown dataset {name!r}; known: {', '.join(loaders)}, joints.")
    return loaders[name](path)


def _check_keys(path, data, keys) -> None:
    missing = [k for k in keys if k not in data]
    if missing:
        raise ValueError(f"{str(path)!r} lacks the keys {missing}.")


def _make_dataset(names: list[str], clips: list[np.ndarray], labels: list[int] | None) -> MotionDataset:
    motions, subjects, fine = [], [], []
    for i, (name, clip) in enumerate(zip(names, clips)):
        info = parse_humanact12_name(name) if name else None
        action = int(labels[i]) if labels is not None else info["action"]
        try:
            motions.append(Motion(clip, skeleton="humanact12", fps=20.0, action=action))
        except ValueError as e:
            raise ValueError(f"HumanAct12 clip {i} ({name or 'unnamed'}): {e}") from e
        subjects.append(info["subject"] if info else 0)
        fine.append(info["fine_code"] if info else "")
    return MotionDataset("humanact12", motions, list(names), np.array(subjects, dtype=np.int64), HUMANACT12_ACTIONS, fine)


def _humanact12_from_npz(path: Path) -> MotionDataset:
    with np.load(path) as d:
        _check_keys(path, d, ("names", "offsets", "joints", "coarse_label"))
        joints, offsets = d["joints"], d["offsets"]
        names = [str(n) for n in d["names"]]
        labels = [int(v) for v in d["coarse_label"]]
    order = np.argsort(names, kind="stable")
    clips = [joints[offsets[i] : offsets[i + 1]] for i in order]
    return _make_dataset([names[i] for i in order], clips, [labels[i] for i in order])


def _humanact12_from_folder(path: Path) -> MotionDataset:
    files = sorted(path.glob("*.npy"))
    if not files:
        raise ValueError(f"folder {str(path)!r} holds no .npy clips.")
    names = [f.stem for f in files]
    for n in names:
        parse_humanact12_name(n)
    clips = [np.load(f, allow_pickle=False) for f in files]
    return _make_dataset(names, clips, None)


def _humanact12_from_pkl(path: Path, names: Sequence[str] | None) -> MotionDataset:
    data = load_pickle(path, what="an ACTOR humanact12poses.pkl of arrays")
    if not isinstance(data, dict) or "joints3D" not in data or "y" not in data:
        raise ValueError(f"{str(path)!r} must hold a dict with keys 'joints3D' and 'y'.")
    clips, labels = list(data["joints3D"]), [int(v) for v in data["y"]]
    if len(clips) != len(labels):
        raise ValueError(f"{str(path)!r}: {len(clips)} clips but {len(labels)} labels.")
    if names is not None and len(names) != len(clips):
        raise ValueError(f"`names` has {len(names)} entries for {len(clips)} clips in {str(path)!r}.")
    return _make_dataset(list(names) if names is not None else [""] * len(clips), clips, labels)
