"""``motion-refiner bench heldout``: flaws made by mechanisms the scoring weights never saw, on subjects they never saw.

Every mechanism of :mod:`refiner.refinement.training.mechanisms` belongs to a fold; it is scored with the motion model trained
and calibrated without that fold (``fold0`` / ``fold1`` weights), on HumanAct12 subjects 11-12 (the model learns on
subjects 1-8 and is calibrated on 9-10). Mechanisms written blind (:mod:`refiner.evaluation.blind_mechanisms`, by
someone who had not read the refiner) are scored with the default weights, which never saw them either.

Per mechanism: the share of the added error (MPJPE to the clean clip) the refiner removes, and the same for two
stand-ins on the same flags (the motion model's repair replaced by linear interpolation of the parts it flagged, the
other steps as they are; and leaving the frames as given, which is 0);
per family their mean. Clean clips: cm moved and share touched. The record is ``heldout.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from refiner.evaluation.bench_setup import Progress, ignore_progress, load_bench_humanact12, one_thread, write_record
from refiner.refinement.motion_model import linear_fill
from refiner.refinement.training.mechanisms import FAMILIES, MECHANISMS

__all__ = ["bench_heldout", "removed_share_of"]


def _error(a, b) -> np.ndarray:
    """``(N,)`` MPJPE in metres between clip batches ``(N, T, J, 3)``."""
    return np.linalg.norm(np.asarray(a, np.float64) - b, axis=-1).mean((-1, -2))


def removed_share_of(clean, flawed, refined) -> float:
    """Share of the flaws' summed MPJPE that ``refined`` removes, over lists of clips (negative: it added error)."""
    added = sum(_error(f[None], c[None])[0] for c, f in zip(clean, flawed))
    left = sum(_error(r[None], c[None])[0] for c, r in zip(clean, refined))
    return float(1.0 - left / added) if added > 0 else 0.0


def _by_length(clips):
    groups = {}
    for i, c in enumerate(clips):
        groups.setdefault(len(c), []).append(i)
    return groups


def _refine_all(refiner, clips, actions, *, linear: bool = False):
    """Refined clips, in order, batched by length; ``linear``: the stand-in repair on the refiner's own flags."""
    out = [None] * len(clips)
    for n, idx in _by_length(clips).items():
        batch = np.stack([clips[i] for i in idx])
        acts = [actions[i] for i in idx]
        if linear:  # the steps in order, the motion model's repair replaced by linear in-fill on its flags
            refined = np.array(batch, dtype=np.float64)
            for step in refiner.steps:
                if not hasattr(step, "model"):
                    refined = step.refine(refined, acts)[0]
                    continue
                prob, flagged = step.detect(refined, acts)
                proposed = step.propose(refined, acts, flagged, infill=linear_fill)
                refined = step.verify(refined, proposed, acts, flagged, prob)[0]
        else:
            refined = refiner.refine(batch, action=acts)
        for k, i in enumerate(idx):
            out[i] = np.asarray(refined[k], np.float64)
    return out


@one_thread()
def bench_heldout(data: Path | None, out: Path | None, quick: bool, *, stride: int = 1, weights: Path | None = None,
                  progress: Progress | None = None) -> dict:
    """Score every mechanism with the weights that never saw it (see the module docstring); ``quick``: 12 clips."""
    from refiner.refinement.motion_refiner import MotionRefiner
    from refiner.evaluation import blind_mechanisms

    progress = progress or ignore_progress
    test = load_bench_humanact12(data).split("test")
    clean = [np.asarray(m.joints, np.float64) for m in test if m.n_frames >= 24][::stride]
    actions = [m.action for m in test if m.n_frames >= 24][::stride]
    if quick:
        clean, actions = clean[:12], actions[:12]
    refiners = {name: MotionRefiner.pretrained("humanact12", model=name, weights=weights) for name in ("all", "fold0", "fold1")}
    rec = {"clips": len(clean), "subjects": [11, 12], "mechanisms": {}, "blind": {}, "clean": {}}
    for name, refiner in refiners.items():
        refined = _refine_all(refiner, clean, actions)
        moved = [np.linalg.norm(r - c, axis=-1).mean() for r, c in zip(refined, clean)]
        rec["clean"][name] = {"cm_moved": 100 * float(np.mean(moved)), "clips_touched": float(np.mean(np.array(moved) > 0))}
    table = [(k, m, f"fold{m.fold}", rec["mechanisms"]) for k, m in MECHANISMS.items()]
    table += [(k, fn, "all", rec["blind"]) for k, fn in blind_mechanisms.MECHANISMS.items()]
    for name, mech, model, into in table:
        flawed = [np.asarray(mech(c, np.random.default_rng([i, 17]), 1.0), np.float64) for i, c in enumerate(clean)]
        row = {"weights": model}
        for label, linear in (("refined", False), ("linear", True)):
            refined = _refine_all(refiners[model], flawed, actions, linear=linear)
            row[label] = 100 * removed_share_of(clean, flawed, refined)
            if not linear:
                row["clips_touched"] = float(np.mean([np.abs(r - f).max() > 0 for r, f in zip(refined, flawed)]))
        row["added_cm"] = 100 * float(np.mean([_error(f[None], c[None])[0] for c, f in zip(clean, flawed)]))
        if hasattr(mech, "family"):
            row["family"] = mech.family
        into[name] = row
        progress("mechanism", {"name": name, **row})
    fams = {f: [r["refined"] for r in rec["mechanisms"].values() if r["family"] == f] for f in FAMILIES}
    rec["families"] = {f: float(np.mean(v)) for f, v in fams.items() if v}
    rec["heldout_mean"] = float(np.mean([r["refined"] for r in rec["mechanisms"].values()]))
    rec["linear_mean"] = float(np.mean([r["linear"] for r in rec["mechanisms"].values()]))
    return write_record(out, "heldout", rec)
