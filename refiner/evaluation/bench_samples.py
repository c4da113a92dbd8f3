"""``motion-refiner bench samples``: real generator output before and after refinement.

The real Action2Motion xyz-VAE samples in ``../shared/samples/action2motion`` (20 clips of 60
frames with their labels) are converted by the ``action2motion`` adapter, refined with their
labels by the default refiner (``MotionRefiner.pretrained``, as :class:`~refiner.refinement.refined_generator.RefinedGenerator`
refines), and scored: the HumanAct12 recogniser's accuracy (mean over
20 random GRU hidden states, the Action2Motion protocol), bone-length variation, frames changed,
and what each clip's report says changed and why.

The record (``samples.json``): :func:`sample_records` of the HumanAct12 samples plus ``snapped`` (the refined
figures and ``frames_changed`` of the concepts method with its concept-snap option, ``concept_snap=1``, subject-1-10
weights), with ``ntu13`` (the same for the 18-joint NTU13 samples, refined through HumanAct12's model, and the NTU13
recogniser, plus ``clips``) or ``ntu13_skipped`` (why not). Without the samples the suite returns ``{"skipped": why}``
and writes nothing.
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from refiner.evaluation.bench_setup import Progress, load_humanact12_and_recognizer, write_record
from refiner.evaluation.physics import acceleration, bone_length_variation
from refiner.io.data_sources import missing_message
from refiner.io.datasets import default_data_dir
from refiner.plugins.manager import convert

__all__ = ["bench_samples", "sample_records"]


def sample_records(before, labels, recognizer, refiner, *, n_hidden: int = 20, actions=None) -> dict:
    """Accuracy, bone-length variation and changes of ``before`` (Motions) and their refinement;
    the refiner gets ``actions`` (default ``labels``; None each: unknown, e.g. NTU13 labels)."""
    actions = list(labels) if actions is None else list(actions)
    after, reports = refiner.refine(np.stack([m.joints for m in before]), action=actions, return_report=True)
    after = [m.with_joints(a) for m, a in zip(before, after)]
    out = {}
    for label, motions in (("generated", before), ("refined", after)):
        acc = [float(np.mean(recognizer.predict(motions, crop="start", random_state=seed) == labels))
               for seed in range(n_hidden)]
        out[label] = {
            "accuracy": float(np.mean(acc)), "accuracy_std": float(np.std(acc)),
            "bone_length_variation": float(np.mean([bone_length_variation(m) for m in motions])),
            "acceleration": float(np.mean([np.mean(acceleration(m)) for m in motions])),
        }
    changed = [np.abs(a.joints - b.joints).max(-1).max(-1) > 0 for a, b in zip(after, before)]
    out["frames_changed"] = float(np.mean([c.mean() for c in changed]))
    steps = Counter(c["step"] for r in reports for c in r.changes)
    out["changes_by_step"] = dict(steps)
    out["repaired_frames"] = float(np.mean([_repaired(r).mean() for r in reports]))
    out["reports"] = [{"label": int(a), "changes": r.changes} for a, r in zip(labels, reports)]
    return out


def _repaired(report) -> np.ndarray:
    """``(T,)`` bool: the frames of a report's changes but for the concept snap, which takes every frame of a clip;
    frames two changes share count once."""
    frames = np.zeros(report.n_frames, bool)
    for c in report.changes:
        if c["step"] != "concept_snap":
            frames[c["start"]:c["stop"]] = True
    return frames


def bench_samples(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                  progress: Progress | None = None) -> dict:
    """Real Action2Motion samples before / after (see the module docstring); ``quick``: the first 5.

    ``weights``: a folder of weight sets looked in before the shipped ones; ``progress`` is accepted like every suite's
    and not called.
    """
    # these import torch: here, so that importing the suites stays cheap
    from refiner.refinement.motion_refiner import MotionRefiner
    from refiner.refinement.pipeline import Refiner

    _, recognizer = load_humanact12_and_recognizer(data, hidden="random")
    folder = (default_data_dir() if data is None else Path(data)).parent / "samples" / "action2motion"
    path, labels_path = folder / "humanact12_xyz_vae_samples.npy", folder / "humanact12_xyz_vae_labels.npy"
    if not path.is_file():
        return {"skipped": missing_message("samples", path)}
    labels = np.load(labels_path).astype(np.int64).ravel()
    before = convert("action2motion", np.load(path), representation="xyz", recenter=True)
    if quick:
        before, labels = before[:5], labels[:5]
    # generator output, refined as RefinedGenerator refines it: the default refiner
    refiner = MotionRefiner.pretrained("humanact12", weights=weights)
    rec = sample_records(before, labels, recognizer, refiner, n_hidden=5 if quick else 20)
    snapper = Refiner.pretrained("humanact12", split="train", weights=weights, concept_snap=1.0)
    snapped = sample_records(before, labels, recognizer, snapper, n_hidden=5 if quick else 20)
    rec["snapped"] = {**snapped["refined"], "frames_changed": snapped["frames_changed"]}
    ntu = _ntu13_records(data, folder, quick, weights)
    if isinstance(ntu, str):
        rec["ntu13_skipped"] = ntu
    else:
        rec["ntu13"] = ntu
    return write_record(out, "samples", rec)


def _ntu13_records(data, folder: Path, quick: bool, weights: Path | None = None):
    """:func:`sample_records` of the 18-joint NTU13 samples with the NTU13 recogniser, or why not."""
    # these import torch: here, so that importing the suites stays cheap
    from refiner.evaluation.evaluators import load_recognizer
    from refiner.refinement.motion_refiner import MotionRefiner

    path, labels_path = folder / "ntu13_xyz_vae_samples.npy", folder / "ntu13_xyz_vae_labels.npy"
    if not (path.is_file() and labels_path.is_file()):
        return f"{missing_message('samples', path)}; NTU13 samples skipped"
    try:
        evaluators = None if data is None else Path(data).parent / "evaluators"
        recognizer = load_recognizer("ntu13", hidden="random", directory=evaluators)
    except ValueError as e:
        return f"NTU13 samples skipped: {e}"
    labels = np.load(labels_path).astype(np.int64).ravel()
    before = convert("action2motion", np.load(path), representation="xyz", recenter=True, skeleton="uestc")
    if quick:
        before, labels = before[:5], labels[:5]
    rec = sample_records(before, labels, recognizer, MotionRefiner.pretrained("uestc", weights=weights),
                         n_hidden=5 if quick else 20, actions=[None] * len(before))
    rec["clips"] = len(before)
    return rec
