"""Measure the refiner on noise recipes that no benchmark family seeds (the figures in the README's limitations).

Usage::

    python examples/measure_noise_recipes.py                            # the shipped settings
    python examples/measure_noise_recipes.py '{"threshold": 0.5}'        # InfillConfig fields

Every 3rd held-out clip (subjects 11-12), seeded with ``numpy.random.default_rng(clip index)``, refined by the default
refiner (``MotionRefiner.pretrained("humanact12")``) with the true action; prints the share of the added MPJPE removed
per recipe:

- ``arm_noise``: white noise (1 cm) on the 8 arm joints over a 10-30-frame window;
- ``window_noise_2cm``: white noise (2 cm) on every joint over such a window;
- ``bursts``: 3 random frames, each with 3 random joints moved by normal noise of 5 cm per axis (a spike; a joint
  drawn twice in a frame moves once);
- ``low_freq``: noise (3 cm) smoothed over 3 frames and tripled, over such a window;
- ``whole_clip_noise_0.5cm``: white noise (0.5 cm) on every frame.

The JSON sets fields of :class:`refiner.refinement.steps.infill.InfillConfig`.
"""
import json
import sys

import numpy as np
import torch
from scipy.ndimage import gaussian_filter1d
from threadpoolctl import threadpool_limits

from refiner.io.datasets import load_humanact12
from refiner.refinement.motion_refiner import MotionRefiner

ARMS = [16, 17, 18, 19, 20, 21, 22, 23]  # SMPL shoulders, elbows, wrists, hands
RECIPES = ("arm_noise", "window_noise_2cm", "bursts", "low_freq", "whole_clip_noise_0.5cm")


def seeded(name: str, x: np.ndarray, rng) -> np.ndarray:
    """``x (T, J, 3)`` metres with recipe ``name``; float32."""
    n_frames = len(x)
    a = int(rng.integers(0, max(n_frames - 20, 1)))
    b = min(n_frames, a + int(rng.integers(10, 30)))
    y = x.astype(np.float64)
    if name == "arm_noise":
        y[a:b, ARMS] += rng.normal(0, 0.01, (b - a, len(ARMS), 3))
    elif name == "window_noise_2cm":
        y[a:b] += rng.normal(0, 0.02, (b - a, x.shape[1], 3))
    elif name == "bursts":
        for t in rng.integers(1, n_frames - 1, 3):
            y[t, rng.integers(0, x.shape[1], 3)] += rng.normal(0, 0.05, (3, 3))
    elif name == "low_freq":
        y[a:b] += 3 * gaussian_filter1d(rng.normal(0, 0.03, (b - a, x.shape[1], 3)), 3, axis=0)
    else:
        y += rng.normal(0, 0.005, y.shape)
    return y.astype(np.float32)


def main() -> None:
    torch.set_num_threads(1)
    threadpool_limits(1)
    options = json.loads(sys.argv[1] if len(sys.argv) > 1 else "{}")
    clips = load_humanact12().split("test").motions[::3]
    model = MotionRefiner.pretrained("humanact12", **options)
    for name in RECIPES:
        before, after = [], []
        for i, clip in enumerate(clips):
            y = seeded(name, clip.joints, np.random.default_rng(i))
            out = model.refine(y, action=clip.action)
            before.append(np.linalg.norm(y - clip.joints, axis=-1).mean())
            after.append(np.linalg.norm(out - clip.joints, axis=-1).mean())
        print(f"{name:24s} {100 * np.mean(before):.3f} -> {100 * np.mean(after):.3f} cm  "
              f"removed {100 * (1 - np.mean(after) / np.mean(before)):+.1f} %", flush=True)


if __name__ == "__main__":
    main()
