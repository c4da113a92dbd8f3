"""``motion-refiner bench skeletons``: the refiner on every skeleton it serves, one row each.

HumanAct12 has weights of its own; ``uestc``, ``cmu_mocap`` and ``humanml3d`` are refined through
them (:class:`~refiner.refinement.converted_refinement.ConvertedRefiner`). Every held-out clip (subjects
11-12; every ``stride``-th) is converted to each layout by :func:`refiner.core.skeletons.convert`, clean
and with each seeded flaw family of :mod:`refiner.evaluation.flaws` (severity 2, made on the 24 joints, then
converted, seed = clip index), refined with the action unknown (the other layouts' datasets have
other labels), and scored against the converted clean clip: MPJPE change of clean clips and share
of clips touched; share of each flaw's added MPJPE removed.

The record (``skeletons.json``): ``clips``, ``stride`` (every how many held-out clips were kept),
``seconds`` and ``skeletons`` (:func:`skeleton_records`).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from refiner.concepts.segmentation import segment
from refiner.core.skeletons import convert
from refiner.evaluation.bench_setup import Progress, load_bench_humanact12, one_thread, write_record
from refiner.evaluation.flaws import FLAW_FAMILIES, corrupt

__all__ = ["bench_skeletons", "skeleton_records", "SKELETONS"]

#: The skeletons a row is made for (HumanAct12 natively, the others through its weights).
SKELETONS = ("humanact12", "uestc", "cmu_mocap", "humanml3d")


def skeleton_records(clips, skeletons=SKELETONS, *, families=None, split: str = "train") -> dict:
    """Per skeleton: ``clean_mpjpe_change_cm``, ``clean_clips_changed`` (share), ``removed_pct`` per
    family and ``mean_removed_pct``, for ``clips`` (Motions on the 24 HumanAct12 joints)."""
    from refiner.refinement.pipeline import Refiner  # imports torch: here, so that importing the suites stays cheap

    families = list(families or FLAW_FAMILIES)
    segs = [segment(m.joints) for m in clips]
    donors = [[d for j, d in enumerate(clips) if j != i and d.action == m.action] for i, m in enumerate(clips)]
    flawed = {f: [corrupt(m, f, 2, random_state=i, segmentation=segs[i], donors=donors[i]).motion.joints
                  for i, m in enumerate(clips)] for f in families}
    rec = {}
    for name in skeletons:
        model = Refiner.pretrained(name, split=split)

        def to(x):
            return np.asarray(x if name == "humanact12" else convert(x, "humanact12", name), np.float32)

        clean = [to(m.joints) for m in clips]
        moved = [float(np.linalg.norm(model.refine(c) - c, axis=-1).mean()) for c in clean]
        row = {"clips": len(clips), "clean_mpjpe_change_cm": 100 * float(np.mean(moved)),
               "clean_clips_changed": float(np.mean(np.array(moved) > 0)), "removed_pct": {}}
        for family in families:
            given = [to(x) for x in flawed[family]]
            before = np.mean([np.linalg.norm(g - c, axis=-1).mean() for g, c in zip(given, clean)])
            after = np.mean([np.linalg.norm(model.refine(g) - c, axis=-1).mean() for g, c in zip(given, clean)])
            row["removed_pct"][family] = 100 * float(1 - after / before) if before > 0 else 0.0
        row["mean_removed_pct"] = float(np.mean(list(row["removed_pct"].values())))
        rec[name] = row
    return rec


@one_thread()
def bench_skeletons(data: Path | None, out: Path | None, quick: bool, *, stride: int = 4,
                    progress: Progress | None = None) -> dict:
    """One row per skeleton (see the module docstring); ``quick``: 4 clips, 2 families, 2 skeletons.

    Returns the record, written as ``skeletons.json`` with ``out``; ``progress`` is accepted like every
    suite's and not called.
    """
    test = load_bench_humanact12(data).split("test")
    stride = 90 if quick else stride  # quick: 4 clips
    clips = test.motions[::stride]
    skeletons = SKELETONS[:2] if quick else SKELETONS
    families = ("frozen_transition", "foot_sliding") if quick else None
    t0 = time.perf_counter()
    rec = skeleton_records(clips, skeletons, families=families)
    seconds = time.perf_counter() - t0
    return write_record(out, "skeletons", {"clips": len(clips), "stride": stride, "seconds": seconds, "skeletons": rec})
