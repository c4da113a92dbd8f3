"""Train the concepts method's refiner on a dataset, module by module (appendix E.2), resumable per module."""
from __future__ import annotations

import logging
import subprocess
import time
from pathlib import Path

import numpy as np

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.learning import learn_concepts
from refiner.concepts.segmentation import segment
from refiner.concepts.transitions import TransitionGenerator
from refiner.io.datasets import MotionDataset
from refiner.nn.training import TrainSchedule
from refiner.refinement.anchor_quality import AnchorQuality
from refiner.refinement.anchor_recognition import AnchorRecognizer
from refiner.refinement.anchor_refinement import AnchorRefiner
from refiner.refinement.pipeline import Refiner
from refiner.refinement.transition_refinement import TransitionRefiner

__all__ = ["CONFIGS", "train_refiner", "fit_anchor_quality", "held_out_clips"]

log = logging.getLogger(__name__)

#: Network sizes and schedules. "default" is the paper's (appendix A) with early stopping;
#: "tiny" trains in seconds on a CPU for tests; "fast" stops the networks early.
CONFIGS = {
    "default": {
        "encoder": dict(d_model=128, n_layers=2, n_heads=4, ffn_dim=128),
        "schedule": dict(n_epochs=600, patience=40, batch_size=128),
        "cvae": dict(latent_dim=32, hidden=256),
        "n_clusters": 8,
    },
    "tiny": {
        "encoder": dict(d_model=32, n_layers=1, n_heads=2, ffn_dim=32),
        "schedule": dict(n_epochs=3, patience=3, batch_size=16, steps_per_epoch=2),
        "cvae": dict(latent_dim=4, hidden=32),
        "n_clusters": 2,
    },
}
#: The fast configuration stops the paper's networks after 40 epochs (patience 10): on one CPU core an epoch of the anchor
#: recogniser takes about 5 s and "default" ran it past 70 (on subjects 1-10 its validation loss was 0.46 at epoch 40,
#: 0.44 at 60); they serve the ``method="concepts"`` option only.
CONFIGS["fast"] = {**CONFIGS["default"], "schedule": dict(n_epochs=40, patience=10, batch_size=128)}

LICENCE = ("Trained on HumanAct12 (derived from PHSPD): academic, non-commercial use only. "
           "Cite Action2Motion (Guo et al. 2020) and PHSPD (Zou et al. 2020).")


USER_DATA_LICENCE = "Trained on user-supplied joint clips: the licence of those data applies to these weights."

CMU_LICENCE = ("Trained only on the CMU Graphics Lab Motion Capture Database (Action2Motion's labelled subset, "
               "mocap.cs.cmu.edu): free for all uses, including commercial products; the data may not be resold.")

#: Licence of weights trained on each dataset (any other: :data:`USER_DATA_LICENCE`).
LICENCES = {"humanact12": LICENCE, "cmu_mocap": CMU_LICENCE}


def train_refiner(
    dataset: MotionDataset,
    out: str | Path,
    *,
    split: str = "all",
    config: str = "default",
    device: str = "auto",
    random_state: int = 0,
    progress: bool = False,
    half: bool = True,
    max_seconds: float | None = None,
    only: str | None = None,
) -> Refiner | None:
    """Learn concepts and train the four networks; save the refiner to ``out``.

    Each trained part is kept in ``out/parts/``; a rerun with the same ``out`` loads finished parts
    instead of training them again. ``only`` trains that one part and returns None, so the parts
    can train in parallel processes; a final run without it assembles them.
    """
    if only is not None and only not in _PART_NAMES:
        raise ValueError(f"unknown part {only!r}; known: {', '.join(_PART_NAMES)}.")
    if config not in CONFIGS:
        raise ValueError(f"unknown config {config!r}; known: {', '.join(CONFIGS)}.")
    cfg = CONFIGS[config]
    out = Path(out)
    parts_dir = out / "parts"
    parts_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    concepts = learn_concepts(dataset, split=split, n_clusters=cfg["n_clusters"], random_state=random_state,
                              progress=progress)
    data = dataset.split(split)
    clips = [m.joints for m in data]
    actions = data.actions
    segs = [segment(c, penalty=concepts.config["penalty"]) for c in clips]
    anchors = [s.anchors for s in segs]
    common = dict(schedule=TrainSchedule(device=device, progress=progress, max_seconds=max_seconds, **cfg["schedule"]),
                  random_state=random_state)
    seconds = {}

    def part(name, cls, train):
        path = parts_dir / f"{name}.safetensors"
        if only is not None and name not in (only, "anchor_concepts", "anchor_quality"):
            return None
        if path.is_file():
            log.info("%s: loaded finished part %s", name, path)
            return cls.load(path) if cls in (AnchorConcepts, AnchorQuality) else cls.load(path, device="cpu")
        t = time.perf_counter()
        obj = train()
        seconds[name] = round(time.perf_counter() - t, 1)
        obj.save(path)
        return obj.to("cpu") if hasattr(obj, "to") else obj

    anchor_concepts = part("anchor_concepts", AnchorConcepts, lambda: concepts.anchor_concepts)
    subjects = data.subjects if data.subjects.any() else None
    anchor_quality = part("anchor_quality", AnchorQuality, lambda: fit_anchor_quality(
        clips, anchors, actions, n_actions=len(dataset.action_names), random_state=random_state, subjects=subjects,
        skeleton=data.motions[0].skeleton))
    recognizer = part("recognizer", AnchorRecognizer, lambda: AnchorRecognizer(**cfg["encoder"], **common).fit(
        clips, anchors, actions, n_actions=len(dataset.action_names)))
    anchor_refiner = part("anchor_refiner", AnchorRefiner, lambda: AnchorRefiner(**cfg["encoder"], **common).fit(
        clips, anchors, actions, anchor_concepts))
    generator = part("transition_generator", TransitionGenerator, lambda: TransitionGenerator(**cfg["cvae"], **common).fit(
        concepts.transitions))
    transition_refiner = part("transition_refiner", TransitionRefiner, lambda: TransitionRefiner(**cfg["encoder"], **common).fit(
        clips, anchors, [s.coeffs for s in segs]))
    if only is not None:
        return None
    manifest = {
        "dataset": dataset.name, "split": split, "config": config, "clips": len(clips),
        "subjects": sorted(set(int(s) for s in data.subjects)), "penalty": concepts.config["penalty"],
        "licence": LICENCES.get(dataset.name, USER_DATA_LICENCE), "commit": _commit(), "train_seconds": seconds,
        "total_seconds": round(time.perf_counter() - t0, 1),
    }
    refiner = Refiner(recognizer, anchor_refiner, generator, transition_refiner, anchor_concepts, anchor_quality,
                      skeleton=data.motions[0].skeleton, action_names=dataset.action_names, manifest=manifest)
    held = held_out_clips(actions, random_state, subjects)
    refiner.calibrate([clips[i] for i in np.flatnonzero(held)], np.asarray(actions)[held], transition_clips=clips)
    refiner.save(out, half=half)
    return refiner


def held_out_clips(actions, random_state=0, subjects=None) -> np.ndarray:
    """Boolean mask of the clips held out for thresholds.

    With ``subjects``, the clips of the two highest-numbered subjects: flaw thresholds must hold for
    people the models have not seen (calibrated on the training subjects' own clips, 7 % of new
    subjects' real anchors fell below the 1 % threshold). Otherwise 10 % of every action's clips.
    """
    if subjects is not None and len(np.unique(subjects)) > 2:
        subjects = np.asarray(subjects)
        return np.isin(subjects, np.unique(subjects)[-2:])
    rng = np.random.default_rng(random_state)
    held = np.zeros(len(actions), dtype=bool)
    for a in np.unique(actions):
        idx = np.flatnonzero(np.asarray(actions) == a)
        held[rng.choice(idx, size=max(1, len(idx) // 10), replace=False)] = True
    return held


def fit_anchor_quality(clips, anchors, actions, *, n_actions: int, random_state=0, n_components: int = 2,
                       subjects=None, skeleton: str = "humanact12") -> AnchorQuality:
    """Per-action pose GMM on the clips' anchors but those of :func:`held_out_clips`, which set the
    flaw threshold (and also calibrate the refiner)."""
    held = held_out_clips(actions, random_state, subjects)

    def gather(mask):
        sel = np.flatnonzero(mask)
        poses = np.concatenate([clips[i][anchors[i]] for i in sel])
        acts = np.concatenate([np.full(len(anchors[i]), actions[i]) for i in sel])
        return poses, acts

    return AnchorQuality(n_components, skeleton=skeleton, random_state=random_state).fit(*gather(~held), validation=gather(held),
                                                                     n_actions=n_actions)


_PART_NAMES = ("anchor_concepts", "anchor_quality", "recognizer", "anchor_refiner", "transition_generator", "transition_refiner")


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).parent, timeout=5).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"
