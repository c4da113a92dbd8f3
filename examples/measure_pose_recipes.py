"""Measure the refiner on wrong key poses blended in otherwise than the benchmark's ``wrong_anchor`` does.

Usage::

    python examples/measure_pose_recipes.py                                  # subjects 11-12, the shipped settings
    python examples/measure_pose_recipes.py '{"subjects": [9, 10]}'          # the calibration subjects
    python examples/measure_pose_recipes.py '{"unblend": false}'             # the blended-pose step off
    python examples/measure_pose_recipes.py '{"dataset": "cmu_mocap"}'       # CMU's held-out subjects, CMU weights

Every 3rd clip of the given subjects, corrupted by each recipe (seed 900 + clip index; a window of 15-40 frames from a
random frame; the wrong pose from a frame of the clip at least 10 frames from the window's peak, or from another
clip of the same action; a peak weight of 0.5-1.0), refined with the true action (``cmu_mocap``: every 2nd clip of
CMU's held-out subjects, cut to 120 frames, refined by the CMU weights); prints the share of the added
MPJPE removed and the clips the blended-pose step changed. The benchmark blends a pose in with smoothstep ramps between
two anchors; these recipes were written after the step, and none of its thresholds was chosen on them:

- ``linear``: the whole pose (about the root) blended in and out with linear ramps;
- ``held``: blended in over 5 frames, held, blended out over 5 frames;
- ``arm``: one arm's elbow, wrist and hand only, moved toward that arm's pose about its shoulder (smoothstep);
- ``legs``: both legs' knees, ankles and feet toward their pose about the hips, linear ramps;
- ``other_clip``: the pose of another clip of the same action (smoothstep);
- ``two``: two poses blended in, in the window's two halves (smoothstep each).
About 30 seconds on one CPU core.
"""
import json
import sys

import numpy as np
import torch
from threadpoolctl import threadpool_limits

import refiner.refinement.blended_pose as blended_pose
from refiner.core.signal import smoothstep
from refiner.core.skeletons import get_skeleton
from refiner.evaluation.recipes import removed_by_recipe
from refiner.io.datasets import load_cmu_mocap, load_humanact12
from refiner.refinement.pipeline import Refiner

torch.set_num_threads(1)
threadpool_limits(1)
SKEL = get_skeleton("humanact12")  # main() sets the dataset's
RECIPES = ("linear", "held", "arm", "legs", "other_clip", "two")


def profile(n_frames, a, b, kind):
    """``(T,)`` weight, 0 outside frames ``a..b``: a tent (``"smooth"``: smoothstep ramps, ``"linear"``) peaking
    mid-window, or ``"held"``: 5-frame smoothstep ramps and 1 between."""
    t = np.arange(n_frames, dtype=float)
    if kind == "held":
        return smoothstep(np.clip((t - a) / 5, 0, 1)) * smoothstep(np.clip((b - t) / 5, 0, 1))
    u = np.clip(1 - np.abs(t - (a + b) / 2) / ((b - a) / 2), 0, 1)
    return smoothstep(u) if kind == "smooth" else u


def blended(x, peak, donor, joints, about, kind, a, b):
    """``x`` with ``joints`` moved toward ``donor (J, 3)``'s pose about joint ``about``, weight ``profile * peak``."""
    w = profile(len(x), a, b, kind) * peak
    delta = np.zeros_like(x[0])
    delta[joints] = (donor[joints] - donor[about]) - (x[(a + b) // 2, joints] - x[(a + b) // 2, about])
    return x + w[:, None, None] * delta


def corrupted(x, rng, recipe, others):
    """``x (T, J, 3)`` float64 metres with ``recipe``; ``others``: clips of the same action, ``(T', J, 3)``."""
    n = len(x)
    a = int(rng.integers(3, max(n - 25, 4)))
    b = min(n - 3, a + int(rng.integers(15, 40)))
    mid = (a + b) // 2
    far = [t for t in range(n) if abs(t - mid) >= 10] or [0, n - 1]
    donor = x[int(rng.choice(far))]
    peak = rng.uniform(0.5, 1.0)
    whole = np.arange(1, SKEL.n_joints)
    if recipe == "linear":
        return blended(x, peak, donor, whole, 0, "linear", a, b)
    if recipe == "held":
        return blended(x, peak, donor, whole, 0, "held", a, b)
    if recipe == "arm":
        side = ("left", "right")[int(rng.integers(2))]
        arm = [SKEL.index(f"{side}_{j}") for j in ("elbow", "wrist", "hand")]
        return blended(x, peak, donor, arm, SKEL.index(f"{side}_shoulder"), "smooth", a, b)
    if recipe == "legs":
        foot = "foot" if "left_foot" in SKEL.joint_names else "toe"
        legs = [SKEL.index(f"{s}_{j}") for s in ("left", "right") for j in ("knee", "ankle", foot)]
        return blended(x, peak, donor, legs, 0, "linear", a, b)
    if recipe == "other_clip":
        if others:
            other = others[int(rng.integers(len(others)))]
            donor = other[int(rng.integers(len(other)))]
        return blended(x, peak, donor, whole, 0, "smooth", a, b)
    if recipe == "two":
        donor2 = x[int(rng.choice(far))]
        y = blended(x, peak, donor, whole, 0, "smooth", a, mid - 1)
        return blended(y, rng.uniform(0.5, 1.0), donor2, whole, 0, "smooth", mid + 1, b)
    raise ValueError(f"unknown recipe {recipe!r}")


def main():
    cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
    blended_pose.UNBLEND = bool(cfg.get("unblend", True))
    global SKEL
    dataset = cfg.get("dataset", "humanact12")
    SKEL = get_skeleton(dataset)
    if dataset == "cmu_mocap":
        clips = [m.with_joints(m.joints[:120]) for m in load_cmu_mocap().split("test") if len(m.joints) >= 120][::2]
    else:
        data = load_humanact12()
        subjects = tuple(cfg.get("subjects", (11, 12)))
        clips = [m for m, s in zip(data.motions, data.subjects) if s in subjects][::3]
    model = Refiner.pretrained(dataset, split="train", **cfg.get("params", {}))
    def same_action(x):  # the other clips of the action of the clip whose joints are x
        own = next(m for m in clips if m.joints.shape == x.shape and np.allclose(m.joints, x))
        return [m.joints.astype(np.float64) for m in clips if m.action == own.action and m is not own]

    recipes = {r: (lambda x, rng, r=r: corrupted(x, rng, r, same_action(x))) for r in cfg.get("recipes", RECIPES)}
    records = removed_by_recipe(model, clips, recipes, seed=900,
                                counted=lambda report: any(c.get("repair") == "unblended_pose" for c in report.changes))
    for recipe, r in records.items():
        print(f"{recipe:11s} {r['before_cm']:.3f} -> {r['after_cm']:.3f} cm  removed {r['removed_pct']:+.1f} %  "
              f"({r['counted']} of {len(clips)} clips unblended)", flush=True)


if __name__ == "__main__":
    main()
