"""Measure the learned refiner's repair choices on the calibration subjects (the figures behind
``refiner.refinement.learned_pipeline.TYPED_REPAIRS`` and ``VERIFY_TYPED``).

Usage::

    python examples/measure_typed_repairs.py                       # the shipped choices
    python examples/measure_typed_repairs.py '{"typed": {"timing": ["retime", 0]}}'
    python examples/measure_typed_repairs.py '{"verify": ["root", "pose"]}' frozen_transition,time_warp
    python examples/measure_typed_repairs.py '{"params": {"repair": "select"}}'

Every 2nd clip of subjects 9-10 of the train split (the subjects the ``humanact12-train`` weights
calibrate on, never the benchmark's 11-12), corrupted by the benchmark's families at severity 2
(seed 500 + clip index), refined with the true action; prints the share of the flaw's added MPJPE
removed per family and the mean, and the clean clips' MPJPE change and share touched. The JSON
overrides ``typed`` (group -> [repair, widen]), ``verify`` (groups verified), ``params`` (Refiner
keywords), ``classifier`` (a FlawClassifier file to swap in), ``weights`` (a refiner folder instead of
the shipped train-split weights). About 20 s on one CPU core.
"""
import json
import sys
import time

import numpy as np
import torch
from threadpoolctl import threadpool_limits

import refiner.refinement.learned_pipeline as lp
from refiner.evaluation.flaws import FLAW_FAMILIES, corrupt
from refiner.io.datasets import load_humanact12
from refiner.refinement.flaw_classifier import FlawClassifier
from refiner.refinement.pipeline import Refiner

torch.set_num_threads(1)
threadpool_limits(1)
cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
lp.TYPED_REPAIRS.update({k: tuple(v) for k, v in cfg.get("typed", {}).items()})
if "verify" in cfg:
    lp.VERIFY_TYPED = tuple(cfg["verify"])
model = (Refiner.load(cfg["weights"], **cfg.get("params", {})) if "weights" in cfg
         else Refiner.pretrained("humanact12", split="train", **cfg.get("params", {})))
if "classifier" in cfg:
    model.flaw_classifier = FlawClassifier.load(cfg["classifier"])
families = sys.argv[2].split(",") if len(sys.argv) > 2 else FLAW_FAMILIES
data = load_humanact12().split("train")
clips = [m for m, s in zip(data.motions, data.subjects) if s in (9, 10)][::2]
donors = [[d for d in clips if d.action == c.action and d is not c] for c in clips]
t0 = time.time()
moved = [100 * np.linalg.norm(model.refine(c).joints - c.joints, axis=-1).mean() for c in clips]
print(f"clean clips: {np.mean(moved):.3f} cm, {100 * np.mean(np.array(moved) > 0):.1f} % touched")
removed = []
for family in families:
    before, after = [], []
    for i, c in enumerate(clips):
        flawed = corrupt(c, family, 2, random_state=500 + i, donors=donors[i]).motion
        before.append(np.linalg.norm(flawed.joints - c.joints, axis=-1).mean())
        after.append(np.linalg.norm(model.refine(flawed, action=c.action).joints - c.joints, axis=-1).mean())
    removed.append(100 * (1 - np.mean(after) / np.mean(before)))
    print(f"{family:22s} {100 * np.mean(before):.3f} -> {100 * np.mean(after):.3f} cm  removed {removed[-1]:+.1f} %")
print(f"mean {np.mean(removed):+.1f} %   ({time.time() - t0:.0f} s)")
