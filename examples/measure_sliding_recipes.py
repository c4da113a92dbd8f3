"""Measure the refiner on sliding recipes other than the benchmark's ``foot_sliding``.

Usage::

    python examples/measure_sliding_recipes.py                        # subjects 9-10, the shipped settings
    python examples/measure_sliding_recipes.py '{"subjects": [11, 12]}'
    python examples/measure_sliding_recipes.py '{"params": {"threshold": 0.5}}'  # InfillConfig fields
    python examples/measure_sliding_recipes.py '{"dataset": "cmu_mocap"}'       # CMU's motion model (once it ships)

Every 2nd clip of the given subjects (default: the motion model's calibration subjects, HumanAct12 9-10, or CMU 122
and 127) of at least 40 frames, corrupted by four recipes (seed 900 + clip index), refined by the default refiner
(``MotionRefiner.pretrained``) with the action unknown; prints the share of the added MPJPE removed per recipe and
the mean. The benchmark's recipe (the whole body out and back by 20 cm over 20 frames, sin², where the feet are down
most) is none of them:

- ``slow``: the whole body out and back by 15 cm over 40 frames (sin²) at a random frame;
- ``shuffle``: three short glides out and back by 8 cm over 8 frames each, each its own direction;
- ``drift``: the whole body slides 12 cm one way over 20 frames (smoothstep) and stays there to the end;
- ``one_foot``: one leg (hip down) slides out and back by 10 cm over 20 frames, the body stays: foot skating proper.

"""
import json
import sys

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from refiner.core.skeletons import get_skeleton
from refiner.evaluation.recipes import removed_by_recipe
from refiner.io.datasets import load_cmu_mocap, load_humanact12
from refiner.refinement.motion_refiner import MotionRefiner

torch.set_num_threads(1)
threadpool_limits(1)
cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
name = cfg.get("dataset", "humanact12")
data = load_cmu_mocap() if name == "cmu_mocap" else load_humanact12()
model = MotionRefiner.pretrained(name, **cfg.get("params", {}))
skel = get_skeleton(name)
subjects = tuple(cfg.get("subjects", (122, 127) if name == "cmu_mocap" else (9, 10)))
clips = [m for m, s in zip(data.motions, data.subjects) if s in subjects and len(m.joints) >= 40][::2]
horizontal = [np.eye(3)[i] for i in range(3) if skel.up_vector[i] == 0]
legs = [[skel.index(n) for n in skel.joint_names if n.startswith(side) and any(w in n for w in ("hip", "knee", "ankle", "foot", "toe", "heel"))]
        for side in ("left_", "right_")]


RECIPES = ("slow", "shuffle", "drift", "one_foot")


def bump(t, start, width):
    u = (np.arange(t) - start) / (width - 1)
    return np.where((u > 0) & (u < 1), np.sin(np.pi * u) ** 2, 0.0)


def direction(rng):
    theta = rng.uniform(0.0, 2.0 * np.pi)
    return np.cos(theta) * horizontal[0] + np.sin(theta) * horizontal[1]


def corrupted(x, rng, recipe):
    t = len(x)
    if recipe == "slow":
        width = min(40, t)
        return x + 0.15 * bump(t, int(rng.integers(0, t - width + 1)), width)[:, None, None] * direction(rng)
    if recipe == "shuffle":
        out = x.copy()
        for _ in range(3):
            out += 0.08 * bump(t, int(rng.integers(0, t - 8 + 1)), 8)[:, None, None] * direction(rng)
        return out
    if recipe == "drift":
        start = int(rng.integers(0, t - 20))
        u = np.clip((np.arange(t) - start) / 20, 0.0, 1.0)
        return x + 0.12 * (u * u * (3 - 2 * u))[:, None, None] * direction(rng)
    out = x.copy()  # one_foot
    width = min(20, t)
    leg = legs[int(rng.integers(2))]
    out[:, leg] += 0.10 * bump(t, int(rng.integers(0, t - width + 1)), width)[:, None, None] * direction(rng)
    return out


records = removed_by_recipe(model, clips, {r: (lambda x, rng, r=r: corrupted(x, rng, r)) for r in RECIPES}, seed=900,
                           with_action=False, counted=lambda report: bool(report.changes))
for recipe, r in records.items():
    print(f"{recipe:9s} {r['before_cm']:.3f} -> {r['after_cm']:.3f} cm  removed {r['removed_pct']:+.1f} %  "
          f"({r['counted']} of {len(clips)} clips changed)")
print(f"mean {np.mean([r['removed_pct'] for r in records.values()]):+.1f} %")
