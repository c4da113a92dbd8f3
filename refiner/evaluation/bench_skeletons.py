"""``motion-refiner bench skeletons``: the default refiner on every skeleton it serves, one row each.

The refiner is ``MotionRefiner.pretrained(skeleton)``. HumanAct12 has a motion model of its own; ``uestc`` and
``humanml3d`` are refined through it (converted in, only the change converted back); ``cmu_mocap`` gets a row once its
own model ships (``refiner/weights/cmu_mocap-motion/``), until then it is ``skipped``. Every held-out clip (subjects
11-12; every ``stride``-th) is converted to each layout by :func:`refiner.core.skeletons.convert`, clean
and with each seeded flaw family of :mod:`refiner.evaluation.flaws` (severity 2, made on the 24 joints, then
converted, seed = clip index), refined with the action unknown (the other layouts' datasets have
other labels), and scored against the converted clean clip: MPJPE change of clean clips and share
of clips touched; share of each flaw's added MPJPE removed.

A skeleton with a motion model of its own trained on another dataset (``cmu_mocap``: the CMU subset)
also gets a *native* row: its dataset's held-out subjects (:data:`refiner.io.datasets.CMU_TEST_SUBJECTS`;
every clip of at least :data:`NATIVE_FRAMES` frames, cut to its first :data:`NATIVE_FRAMES`), flaws
seeded in its own layout, refined with the action unknown, and the dataset's Action2Motion recogniser's
accuracy on the clean, flawed and refined clips (mean over families, 20 draws of its random hidden state).

The record (``skeletons.json``): ``clips``, ``stride`` (every how many held-out clips were kept),
``seconds``, ``skeletons`` (:func:`skeleton_records`), ``native`` (:func:`native_records`) and ``skipped`` (skeleton ->
why it has no row).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from refiner.concepts.segmentation import segment
from refiner.core.skeletons import convert
from refiner.evaluation.bench_setup import Progress, load_bench_humanact12, one_thread, write_record
from refiner.evaluation.flaws import FLAW_FAMILIES, corrupt

__all__ = ["bench_skeletons", "skeleton_records", "native_records", "SKELETONS", "NATIVE", "NATIVE_FRAMES"]

#: The skeletons a row is made for (HumanAct12 natively, the others through whatever model serves them).
SKELETONS = ("humanact12", "uestc", "cmu_mocap", "humanml3d")
#: Skeletons whose motion model may be trained on a dataset of their own layout, and that dataset.
NATIVE = {"cmu_mocap": "cmu_mocap"}
#: Frames each native held-out clip is cut to (the CMU recogniser reads 100-frame crops).
NATIVE_FRAMES = 120


def _flawed(clips, families) -> dict:
    """``{family: [joints (T, J, 3)]}``: every clip with each family seeded (severity 2, seed = clip index)."""
    segs = [segment(m.joints) for m in clips]
    donors = [[d for j, d in enumerate(clips) if j != i and d.action == m.action] for i, m in enumerate(clips)]
    return {f: [corrupt(m, f, 2, random_state=i, segmentation=segs[i], donors=donors[i]).motion.joints
                for i, m in enumerate(clips)] for f in families}


def _row(model, clean, flawed: dict) -> tuple[dict, dict]:
    """The clean clips' change and each family's share of added MPJPE removed; and the refined clips."""
    def mpjpe(a, b):
        return float(np.linalg.norm(a - b, axis=-1).mean())

    moved = [mpjpe(model.refine(c), c) for c in clean]
    row = {"clips": len(clean), "clean_mpjpe_change_cm": 100 * float(np.mean(moved)),
           "clean_clips_changed": float(np.mean(np.array(moved) > 0)), "removed_pct": {}}
    refined = {}
    for family, given in flawed.items():
        refined[family] = [model.refine(g) for g in given]
        before = np.mean([mpjpe(g, c) for g, c in zip(given, clean)])
        after = np.mean([mpjpe(r, c) for r, c in zip(refined[family], clean)])
        row["removed_pct"][family] = 100 * float(1 - after / before) if before > 0 else 0.0
    row["mean_removed_pct"] = float(np.mean(list(row["removed_pct"].values())))
    return row, refined


def _motion_refiner(name: str, weights: Path | None, skipped: dict | None):
    """``MotionRefiner.pretrained(name, weights=weights)``, or None with the reason in ``skipped``."""
    from refiner.refinement.motion_refiner import MotionRefiner  # imports torch: here, so that importing stays cheap

    try:
        return MotionRefiner.pretrained(name, weights=weights)
    except ValueError as e:
        if skipped is None:
            raise
        skipped[name] = str(e)
        return None


def _motion_manifest(name: str, weights: Path | None) -> dict:
    """The manifest of ``name``'s own motion model (in ``weights``, else shipped)."""
    import json

    from refiner.refinement.motion_refiner import _WEIGHTS

    folders = [Path(w) / f"{name}-motion" for w in ([weights] if weights else [])] + [_WEIGHTS / f"{name}-motion"]
    return next(json.loads((f / "manifest.json").read_text()) for f in folders if (f / "manifest.json").is_file())


def skeleton_records(clips, skeletons=SKELETONS, *, families=None, weights: Path | None = None,
                     skipped: dict | None = None) -> dict:
    """Per skeleton: ``clean_mpjpe_change_cm``, ``clean_clips_changed`` (share), ``removed_pct`` per
    family, ``mean_removed_pct`` and ``weights`` (whose model), for ``clips`` (Motions on the 24 HumanAct12 joints).
    A skeleton without a motion model raises ``ValueError``, or with ``skipped`` (a dict) is left out and noted there."""
    flawed = _flawed(clips, list(families or FLAW_FAMILIES))
    rec = {}
    for name in skeletons:
        model = _motion_refiner(name, weights, skipped)
        if model is None:
            continue

        def to(x):
            return np.asarray(x if name == "humanact12" else convert(x, "humanact12", name), np.float32)

        rec[name] = _row(model, [to(m.joints) for m in clips], {f: [to(x) for x in v] for f, v in flawed.items()})[0]
        own = model.model.skeleton
        rec[name]["weights"] = own if own == name else f"{own}, converted"
    return rec


def native_records(data: Path | None, *, families=None, stride: int = 1, n_replications: int = 20,
                   weights: Path | None = None) -> dict:
    """Per skeleton of :data:`NATIVE` with a motion model of its own: the row of :func:`skeleton_records` on its
    own dataset's held-out clips, plus ``accuracy_pct`` of its recogniser on ``clean``, ``flawed`` and
    ``refined`` clips (flawed / refined: mean over families) and the weights' ``licence``."""
    from refiner.evaluation.evaluators import load_recognizer  # imports torch: see skeleton_records
    from refiner.io.datasets import load_cmu_mocap

    rec = {}
    for name, dataset in NATIVE.items():
        model = _motion_refiner(name, weights, {})
        if model is None or model.model.skeleton != name:
            continue
        test = load_cmu_mocap(None if data is None else Path(data) / "cmu_mocap" / "cmu_mocap_labeled_joints.npz")
        clips = [m.with_joints(m.joints[:NATIVE_FRAMES]) for m in test.split("test") if len(m.joints) >= NATIVE_FRAMES]
        clips = clips[::stride]
        flawed = _flawed(clips, list(families or FLAW_FAMILIES))
        row, refined = _row(model, [m.joints for m in clips], flawed)
        recognizer = load_recognizer(dataset, directory=None if data is None else Path(data).parent / "evaluators")
        labels = np.array([m.action for m in clips])

        def accuracy(joints) -> float:
            motions = [m.with_joints(j) for m, j in zip(clips, joints)]
            return 100 * float(np.mean([np.mean(recognizer.predict(motions, random_state=r) == labels)
                                        for r in range(n_replications)]))

        row["accuracy_pct"] = {"clean": accuracy([m.joints for m in clips]),
                               "flawed": float(np.mean([accuracy(v) for v in flawed.values()])),
                               "refined": float(np.mean([accuracy(v) for v in refined.values()]))}
        row["dataset"], row["licence"] = dataset, _motion_manifest(name, weights).get("licence")
        rec[name] = row
    return rec


@one_thread()
def bench_skeletons(data: Path | None, out: Path | None, quick: bool, *, stride: int = 4,
                    weights: Path | None = None, progress: Progress | None = None) -> dict:
    """One row per skeleton (see the module docstring); ``quick``: 4 clips, 2 families, 2 skeletons.

    Returns the record, written as ``skeletons.json`` with ``out``; ``weights``: a folder of weight sets looked in before
    the shipped ones; ``progress`` is accepted like every suite's and not called.
    """
    test = load_bench_humanact12(data).split("test")
    stride = 90 if quick else stride  # quick: 4 clips
    clips = test.motions[::stride]
    skeletons = SKELETONS[:2] if quick else SKELETONS
    families = ("frozen_transition", "foot_sliding") if quick else None
    t0 = time.perf_counter()
    skipped: dict = {}
    rec = skeleton_records(clips, skeletons, families=families, weights=weights, skipped=skipped)
    native = native_records(data, families=families, stride=40 if quick else 2, n_replications=2 if quick else 20,
                            weights=weights)
    seconds = time.perf_counter() - t0
    return write_record(out, "skeletons", {"clips": len(clips), "stride": stride, "seconds": seconds, "skeletons": rec,
                                           "native": native, "skipped": skipped})
