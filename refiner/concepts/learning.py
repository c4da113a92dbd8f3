"""Motion concepts of a dataset: segmentation, anchor concepts and transition data (paper §3.1).

``learn_concepts`` runs the whole unsupervised pipeline over real clips; ``MotionConcepts`` holds
the result and saves it to a folder (safetensors plus a small JSON), round-trip exact.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.segmentation import DEFAULT_PENALTY, Segmentation, segment
from refiner.concepts.transitions import TransitionSet, collect_transitions
from refiner.core.serialization import load_state, save_state
from refiner.io.datasets import MotionDataset

__all__ = ["MotionConcepts", "learn_concepts", "segment_dataset"]


@dataclass
class MotionConcepts:
    """Everything learned from a dataset without labels beyond the action.

    Attributes
    ----------
    config : dict
        ``dataset``, ``split``, ``penalty``, ``n_clusters``, ``skeleton``, ``action_names``.
    anchors : list of ndarray of int
        Anchor frames of every clip.
    anchor_concepts : AnchorConcepts
    transitions : TransitionSet
    seconds : float
        Wall time of the learning.
    """

    config: dict
    anchors: list[np.ndarray]
    anchor_concepts: AnchorConcepts
    transitions: TransitionSet
    seconds: float = field(default=0.0)

    def summary(self) -> dict:
        n_anchors = sum(len(a) for a in self.anchors)
        return {
            "clips": len(self.anchors),
            "anchors": n_anchors,
            "transitions": len(self.transitions),
            "mean_transitions_per_clip": round(len(self.transitions) / max(len(self.anchors), 1), 3),
            "mean_transition_frames": round(float(self.transitions.durations.mean()), 3),
            "clusters_per_action": dict(zip(self.config["action_names"], self.anchor_concepts.n_concepts_)),
            "seconds": round(self.seconds, 2),
        }

    def save(self, folder: str | os.PathLike) -> None:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        self.anchor_concepts.save(folder / "anchor_concepts.safetensors")
        self.transitions.save(folder / "transitions.safetensors")
        lengths = np.array([len(a) for a in self.anchors], dtype=np.int64)
        save_state(
            folder / "segmentation.safetensors",
            {"anchors": np.concatenate(self.anchors).astype(np.int64), "lengths": lengths},
            {"refiner.class": "Segmentations"},
        )
        (folder / "concepts.json").write_text(
            json.dumps({"config": self.config, "summary": self.summary()}, indent=2) + "\n"
        )

    @classmethod
    def load(cls, folder: str | os.PathLike) -> "MotionConcepts":
        folder = Path(folder)
        meta_path = folder / "concepts.json"
        if not meta_path.is_file():
            raise ValueError(f"{str(folder)!r} holds no concepts.json; run `motion-refiner concepts` first.")
        meta = json.loads(meta_path.read_text())
        tensors, _ = load_state(folder / "segmentation.safetensors")
        anchors = np.split(tensors["anchors"], np.cumsum(tensors["lengths"])[:-1])
        return cls(
            config=meta["config"],
            anchors=anchors,
            anchor_concepts=AnchorConcepts.load(folder / "anchor_concepts.safetensors"),
            transitions=TransitionSet.load(folder / "transitions.safetensors"),
            seconds=float(meta["summary"].get("seconds", 0.0)),
        )


def segment_dataset(dataset: MotionDataset, *, penalty: float = DEFAULT_PENALTY, progress: bool = False) -> list[Segmentation]:
    """Segment every clip of a dataset (clips shorter than a transition give one anchor pair)."""
    return [segment(m.joints, penalty=penalty) for m in tqdm(dataset.motions, desc="segment", disable=not progress)]


def learn_concepts(
    dataset: MotionDataset,
    *,
    split: str = "all",
    penalty: float = DEFAULT_PENALTY,
    n_clusters: int = 8,
    random_state: int | None = 0,
    progress: bool = False,
) -> MotionConcepts:
    """Segment a dataset, cluster its anchors per action and collect its transitions.

    Parameters
    ----------
    dataset : MotionDataset
    split : {"all", "train", "test"}, default="all"
    penalty : float, default=200.0
        λ of the segmentation, cm² per joint.
    n_clusters : int, default=8
        Anchor concepts per action.
    random_state : int or None, default=0
    progress : bool, default=False
        Show progress bars.
    """
    t0 = time.perf_counter()
    data = dataset.split(split)
    segs = segment_dataset(data, penalty=penalty, progress=progress)
    clips = [m.joints for m in data]
    actions = data.actions
    poses = np.concatenate([c[s.anchors] for c, s in zip(clips, segs)])
    anchor_actions = np.concatenate([np.full(len(s.anchors), a) for s, a in zip(segs, actions)])
    concepts = AnchorConcepts(n_clusters, random_state=random_state).fit(
        poses, anchor_actions, n_actions=len(dataset.action_names)
    )
    transitions = collect_transitions(clips, segs, actions)
    config = {
        "dataset": dataset.name,
        "split": split,
        "penalty": float(penalty),
        "n_clusters": int(n_clusters),
        "skeleton": data.motions[0].skeleton,
        "action_names": list(dataset.action_names),
    }
    return MotionConcepts(config, [s.anchors for s in segs], concepts, transitions, time.perf_counter() - t0)
