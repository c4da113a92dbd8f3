"""Measure the refiner on flaws the refinement issue and the project brief name that no benchmark family seeds.

Usage::

    python examples/measure_body_recipes.py                                  # subjects 11-12, the shipped settings
    python examples/measure_body_recipes.py '{"subjects": [9, 10]}'          # the calibration subjects
    python examples/measure_body_recipes.py '{"params": {"threshold": 0.5}}'  # InfillConfig fields
    python examples/measure_body_recipes.py '{"recipes": ["float", "stutter"]}'

Every 3rd clip of the given subjects, corrupted by each recipe (seed 700 + clip index; a window of 15-40 frames from
a random frame), refined by the default refiner (``MotionRefiner.pretrained("humanact12")``, its model learned on
subjects 1-8 and calibrated on 9-10) with the true action; prints the share of the added MPJPE removed and the clips changed:

- ``float``: the whole body raised 10 cm over the window (5-frame smoothstep ramps);
- ``sink``: ... sunk 5 cm into the ground;
- ``stutter``: every 2nd frame of the window shown twice (dropped frames);
- ``damped`` / ``exaggerated``: the window's root-relative motion scaled by 0.5 / 1.5 about its mean pose (ramped);
- ``same_foot``: the legs swapped and mirrored about the body's midplane over the window (ramped over 4 frames):
  in a walk, a step with the same foot twice; ``same_foot_abrupt``: the same without ramps; ``legs_relabelled``: the
  left and right legs' joints trade places as they are, not mirrored (ramped over 4 frames: labels confused);
  ``limbs_relabelled``: every left joint trades places with its right one as they are, without ramps;
  ``limbs_blended``: every left joint blended with its right one by a weight of 0.6-1.0, ramped over 4 frames;
- ``arm_up``: an arm held where it was at the window's start (its elbow, wrist and hand fixed to the shoulder, in
  the world's frame), let go over 6 frames at its end; ``arm_never_down``: held to the clip's end;

and two inputs that are no flaw, whose change is printed instead: ``faster`` (played 1.25 times as fast) and
``mirrored`` (left and right swapped, mirrored in x).
"""
import json
import sys

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from refiner.core.signal import resample, smoothstep
from refiner.core.skeletons import get_skeleton
from refiner.evaluation.recipes import removed_by_recipe
from refiner.io.datasets import load_humanact12
from refiner.refinement.motion_refiner import MotionRefiner

torch.set_num_threads(1)
threadpool_limits(1)
SKEL = get_skeleton("humanact12")
UP = SKEL.up_vector
ARMS = {side: [SKEL.index(f"{side}_{j}") for j in ("elbow", "wrist", "hand")] for side in ("left", "right")}
LEGS = [[SKEL.index(f"{side}_{j}") for j in ("hip", "knee", "ankle", "foot")] for side in ("left", "right")]
FLAWS = ("float", "sink", "stutter", "damped", "exaggerated", "same_foot", "same_foot_abrupt", "legs_relabelled",
         "limbs_relabelled", "limbs_blended", "arm_up", "arm_never_down")
NO_FLAWS = ("faster", "mirrored")


def mirror_pairs(skel) -> np.ndarray:
    """``(J,)`` index of each joint's left/right counterpart (itself when it has none), from the joint names."""
    names = list(skel.joint_names)
    out = np.arange(len(names))
    for j, n in enumerate(names):
        for a, b in (("left", "right"), ("right", "left")):
            if a in n and n.replace(a, b) in names:
                out[j] = names.index(n.replace(a, b))
    return out


def ramp(n_frames, a, b, width):
    """``(T,)``: 0 outside frames ``a..b-1``, 1 inside but for smoothstep ramps of ``width`` frames."""
    t = np.arange(n_frames, dtype=float)
    return smoothstep(np.clip((t - a + 1) / width, 0, 1)) * smoothstep(np.clip((b - t) / width, 0, 1))


def mirrored_legs(x, t):
    """The legs of frames ``t`` swapped, each mirrored about the plane through the pelvis across the hips."""
    across = x[t, LEGS[1][0]] - x[t, LEGS[0][0]]
    across /= np.linalg.norm(across, axis=-1, keepdims=True)
    out = []
    for src in (LEGS[1], LEGS[0]):
        rel = x[t][:, src] - x[t, 0][:, None]
        out.append(x[t, 0][:, None] + rel - 2 * (rel * across[:, None]).sum(-1, keepdims=True) * across[:, None])
    return out


def corrupted(x, rng, recipe):
    """``x (T, 24, 3)`` float64 metres with ``recipe``."""
    n = len(x)
    a = int(rng.integers(3, max(n - 25, 4)))
    b = min(n - 2, a + int(rng.integers(15, 40)))
    w = ramp(n, a, b, 5)[:, None, None]
    y = x.copy()
    if recipe in ("float", "sink"):
        return y + (0.10 if recipe == "float" else -0.05) * w * UP
    if recipe == "stutter":
        idx = np.arange(n)
        idx[a:b] = a + ((idx[a:b] - a) // 2) * 2
        return y[idx]
    if recipe in ("damped", "exaggerated"):
        rel = y - y[:, :1]
        mean = rel[a:b].mean(0)
        return y + w * (mean + (0.5 if recipe == "damped" else 1.5) * (rel - mean) - rel)
    if recipe in ("same_foot", "same_foot_abrupt", "legs_relabelled"):
        t = np.arange(a, b)
        v = ramp(n, a, b, 1 if recipe == "same_foot_abrupt" else 4)[t][:, None, None]
        new = [x[t][:, leg] for leg in LEGS[::-1]] if recipe == "legs_relabelled" else mirrored_legs(x, t)
        for leg, other in zip(LEGS, new):
            y[t[:, None], leg] = v * other + (1 - v) * x[t][:, leg]
        return y
    if recipe == "limbs_relabelled":
        y[a:b] = x[a:b][:, mirror_pairs(SKEL)]
        return y
    if recipe == "limbs_blended":
        v = rng.uniform(0.6, 1.0) * ramp(n, a, b, 4)[:, None, None]
        return y + v * (y[:, mirror_pairs(SKEL)] - y)
    if recipe in ("arm_up", "arm_never_down"):
        side = ("left", "right")[int(rng.integers(2))]
        shoulder, arm = SKEL.index(f"{side}_shoulder"), ARMS[side]
        end = n if recipe == "arm_never_down" else b
        held = x[a:end, shoulder][:, None] + (x[a, arm] - x[a, shoulder])[None]
        v = np.ones(end - a)
        if end < n:
            v[-6:] = smoothstep(np.linspace(1, 0, 8)[1:-1])
        y[a:end, arm] = v[:, None, None] * held + (1 - v[:, None, None]) * x[a:end, arm]
        return y
    if recipe == "faster":
        return resample(y, np.arange(0, n - 1, 1.25))
    if recipe == "mirrored":
        y = y[:, mirror_pairs(SKEL)]
        y[..., 0] *= -1
        return y
    raise ValueError(f"unknown recipe {recipe!r}")


def main():
    cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
    data = load_humanact12()
    subjects = tuple(cfg.get("subjects", (11, 12)))
    clips = [m for m, s in zip(data.motions, data.subjects) if s in subjects][::3]
    model = MotionRefiner.pretrained("humanact12", **cfg.get("params", {}))
    names = cfg.get("recipes", FLAWS + NO_FLAWS)
    flaws = [r for r in names if r in FLAWS]
    records = removed_by_recipe(model, clips, {r: (lambda x, rng, r=r: corrupted(x, rng, r)) for r in flaws}, seed=700,
                                counted=lambda report: bool(report.changes))
    for recipe, r in records.items():
        print(f"{recipe:15s} {r['before_cm']:.3f} -> {r['after_cm']:.3f} cm  removed {r['removed_pct']:+.1f} %  "
              f"({r['counted']} of {len(clips)} clips changed)", flush=True)
    for recipe in (r for r in names if r in NO_FLAWS):
        moved, changed = [], 0
        for i, m in enumerate(clips):
            y = corrupted(m.joints.astype(np.float64), np.random.default_rng(700 + i), recipe).astype(np.float32)
            out = model.refine(y, action=m.action)
            moved.append(100 * np.linalg.norm(out - y, axis=-1).mean())
            changed += bool(np.abs(out - y).max() > 0)
        print(f"{recipe:15s} no flaw: moved {np.mean(moved):.3f} cm on average ({changed} of {len(clips)} clips changed)",
              flush=True)


if __name__ == "__main__":
    main()
