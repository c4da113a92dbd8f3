"""Measure the pose-prior step on drift recipes other than the benchmark's ``anchor_drift``.

Usage::

    python examples/measure_drift_recipes.py                      # subjects 9-10, the shipped settings
    python examples/measure_drift_recipes.py '{"subjects": [11, 12]}'
    python examples/measure_drift_recipes.py '{"params": {"posing": "keep"}}'   # the step off
    python examples/measure_drift_recipes.py '{"share": 0.5, "autocorrelation": 0.7}'

Every 2nd clip of the given subjects (default 9-10, the calibration subjects of the ``humanact12-train``
weights), corrupted by four recipes (seed 700 + clip index), refined with the true action; prints the
share of the added MPJPE removed per recipe, how many clips the step changed, and the mean. None of them is
the benchmark's random walk over the anchors:

- ``limb``: the joints of one limb (an arm or a leg, below its root joint) moved by one offset that grows
  by smoothstep from 0 at a random frame to 5 cm per axis (standard deviation) at a later one, then stays;
- ``linear``: every joint moves along its own straight line from frame 0, 4 cm per axis at the last frame;
- ``wander``: every joint wanders by white noise smoothed over 6-12 frames (Gaussian sigma), 2.5 cm per axis;
- ``late``: as ``linear``, but from a random frame in the second half of the clip (its start untouched).

The JSON sets ``autocorrelation`` / ``share`` / ``off`` / ``bones`` (:data:`refiner.refinement.pose_prior.DRIFT_AUTOCORRELATION`,
``DRIFT_SHARE``, ``DRIFT_OFF``, ``DRIFT_BONES``), the prior's ``threshold`` (metres), ``params`` (Refiner keywords) and ``subjects``. About 40 s on one CPU core.
"""
import json
import sys

import numpy as np
import torch
from scipy.ndimage import gaussian_filter1d
from threadpoolctl import threadpool_limits

import refiner.refinement.pose_prior as pose_prior
from refiner.evaluation.recipes import removed_by_recipe
from refiner.io.datasets import load_humanact12
from refiner.refinement.pipeline import Refiner

torch.set_num_threads(1)
threadpool_limits(1)
cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
pose_prior.DRIFT_AUTOCORRELATION = cfg.get("autocorrelation", pose_prior.DRIFT_AUTOCORRELATION)
pose_prior.DRIFT_SHARE = cfg.get("share", pose_prior.DRIFT_SHARE)
pose_prior.DRIFT_OFF = cfg.get("off", pose_prior.DRIFT_OFF)
pose_prior.DRIFT_BONES = cfg.get("bones", pose_prior.DRIFT_BONES)
model = Refiner.pretrained("humanact12", split="train", **cfg.get("params", {}))
if "threshold" in cfg:  # metres
    model.pose_prior.threshold_ = float(cfg["threshold"])
data = load_humanact12()
subjects = tuple(cfg.get("subjects", (9, 10)))
clips = [m for m, s in zip(data.motions, data.subjects) if s in subjects and len(m.joints) >= 20][::2]
#: HumanAct12 limbs below their root joint: left / right arm (collar down), left / right leg (hip down).
LIMBS = ((13, 16, 18, 20, 22), (14, 17, 19, 21, 23), (1, 4, 7, 10), (2, 5, 8, 11))


def smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3 - 2 * u)


def corrupted(x, rng, recipe):
    t, j = len(x), x.shape[1]
    if recipe == "limb":
        a = int(rng.integers(0, t // 2))
        b = int(rng.integers(a + 5, t + 1)) if a + 5 < t else t
        grow = smoothstep((np.arange(t) - a) / max(b - a, 1))[:, None, None]
        offset = np.zeros((1, j, 3))
        offset[0, list(LIMBS[int(rng.integers(len(LIMBS)))])] = rng.normal(size=3) * 0.05
        return x + grow * offset
    if recipe in ("linear", "late"):
        start = 0 if recipe == "linear" else int(rng.integers(t // 2, t - 2))
        ramp = np.clip((np.arange(t) - start) / max(t - 1 - start, 1), 0.0, 1.0)[:, None, None]
        return x + ramp * rng.normal(size=(1, j, 3)) * 0.04
    noise = gaussian_filter1d(rng.normal(size=(t + 60, j, 3)), rng.uniform(6, 12), axis=0)[30 : 30 + t]
    return x + noise / max(noise.std(), 1e-9) * 0.025


records = removed_by_recipe(model, clips, {r: (lambda x, rng, r=r: corrupted(x, rng, r)) for r in ("limb", "linear", "wander", "late")},
                           seed=700, counted=lambda report: any(c.get("repair") == "pose_prior" for c in report.changes))
for recipe, r in records.items():
    print(f"{recipe:8s} {r['before_cm']:.3f} -> {r['after_cm']:.3f} cm  removed {r['removed_pct']:+.1f} %  "
          f"({r['counted']} of {len(clips)} clips changed by the pose prior)")
print(f"mean {np.mean([r['removed_pct'] for r in records.values()]):+.1f} %")
