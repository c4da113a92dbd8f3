"""Measure the rigid-skeleton step on bone-length flaws, which no benchmark family seeds.

Usage::

    python examples/measure_bone_recipes.py                                  # subjects 11-12, the shipped settings
    python examples/measure_bone_recipes.py '{"params": {"rigid_core": false}}'   # every frame projected first
    python examples/measure_bone_recipes.py '{"subjects": [9, 10]}'

Every 2nd clip of the given subjects (default 11-12), one limb's bones (an arm from the shoulder, or a leg
from the hip; limbs in turn) scaled by a ``sin²`` bump over 20 frames (half the clip if shorter) at a random
place (seed 1100 + clip index), refined with the true action; prints the share of the added MPJPE removed per
recipe and how many clips the rigid-skeleton step changed. The recipes: ``shrink`` (to 90 % at the peak),
``stretch`` (110 %), ``mixed`` (every other clip each). The shipped refiner rebuilds such frames outward on
the clip's rigid core (:data:`refiner.core.rigid.REBUILD_BONES`). About 60 s on one CPU core.
"""
import json
import sys

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from refiner.core.skeletons import joint_bone_lengths, with_bone_lengths
from refiner.io.datasets import load_humanact12
from refiner.refinement.pipeline import Refiner

torch.set_num_threads(1)
threadpool_limits(1)
cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
model = Refiner.pretrained("humanact12", split="train", **cfg.get("params", {}))
data = load_humanact12()
subjects = tuple(cfg.get("subjects", (11, 12)))
clips = [m for m, s in zip(data.motions, data.subjects) if s in subjects][::2]
#: The bones (by the joint they end at) of HumanAct12's left / right arm and left / right leg.
LIMBS = ((16, 18, 20, 22), (17, 19, 21, 23), (1, 4, 7, 10), (2, 5, 8, 11))

for recipe, peaks in (("shrink", (0.9,)), ("stretch", (1.1,)), ("mixed", (0.9, 1.1))):
    before, after, changed = [], [], 0
    for i, m in enumerate(clips):
        rng = np.random.default_rng(1100 + i)
        x = m.joints.astype(np.float64)
        width = min(20, len(x) // 2)
        start = int(rng.integers(0, len(x) - width + 1))
        bump = np.zeros(len(x))
        bump[start : start + width] = np.sin(np.linspace(0, np.pi, width)) ** 2
        lengths = joint_bone_lengths(x, "humanact12")
        scale = np.ones_like(lengths)
        scale[:, list(LIMBS[i % len(LIMBS)])] = 1 + (peaks[i % len(peaks)] - 1) * bump[:, None]
        flawed = with_bone_lengths(x, lengths * scale, "humanact12").astype(np.float32)
        out, report = model.refine(flawed, action=m.action, return_report=True)
        changed += any(c["step"] == "skeleton" for c in report.changes)
        before.append(np.linalg.norm(flawed - x, axis=-1).mean())
        after.append(np.linalg.norm(out - x, axis=-1).mean())
    print(f"{recipe:8s} {100 * np.mean(before):.3f} -> {100 * np.mean(after):.3f} cm  removed "
          f"{100 * (1 - np.mean(after) / np.mean(before)):+.1f} %  ({changed} of {len(clips)} clips changed by the rigid step)")
