"""Measure the retrace cut on reversal recipes other than the benchmark's ``reversed_transition``.

Usage::

    python examples/measure_retrace_recipes.py                      # subjects 9-10, the shipped settings
    python examples/measure_retrace_recipes.py '{"subjects": [11, 12]}'
    python examples/measure_retrace_recipes.py '{"max_ratio": 0.12, "min_probability": 0.7}'
    python examples/measure_retrace_recipes.py '{"params": {"retiming": "stalls"}}'   # the step off

Every 2nd clip of the given subjects (default 9-10, the calibration subjects of the ``humanact12-train``
weights), corrupted by three recipes (seed 900 + clip index), refined with the true action; prints the
share of the added MPJPE removed per recipe, how many clips had a loop cut, and the mean. The recipes:

- ``pingpong``: a transition of the clip's own segmentation (at least 8 frames) re-timed piecewise
  linearly ``0 -> p -> q -> 1`` (p in 0.55-0.85, q at least 0.25 below it) at 35 % and 65 % of it;
- ``rewind``: a transition played through in half its time, half of it rewound, then played again;
- ``random_window``: the benchmark's warp ``u + 2.5 sin(2 pi u) / (2 pi)`` on a random 10-25-frame
  window that ignores the anchors.

The JSON sets ``max_ratio`` / ``min_probability`` / ``max_span`` (the module's constants), ``params``
(Refiner keywords) and ``subjects``. About 25 s on one CPU core.
"""
import json
import sys

import numpy as np
import torch
from threadpoolctl import threadpool_limits

import refiner.refinement.retrace as retrace
from refiner.concepts.segmentation import segment
from refiner.core.signal import resample
from refiner.io.datasets import load_humanact12
from refiner.refinement.pipeline import Refiner

torch.set_num_threads(1)
threadpool_limits(1)
cfg = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
retrace.MAX_RATIO = cfg.get("max_ratio", retrace.MAX_RATIO)
retrace.MIN_FLAW_PROBABILITY = cfg.get("min_probability", retrace.MIN_FLAW_PROBABILITY)
retrace.MAX_SPAN = cfg.get("max_span", retrace.MAX_SPAN)
model = Refiner.pretrained("humanact12", split="train", **cfg.get("params", {}))
data = load_humanact12()
subjects = tuple(cfg.get("subjects", (9, 10)))
clips = [m for m, s in zip(data.motions, data.subjects) if s in subjects][::2]


def window(x, rng, recipe):
    if recipe == "random_window":
        length = min(int(rng.integers(10, 26)), len(x) - 1)
        start = int(rng.integers(0, len(x) - length))
        return start, start + length
    anchors = segment(x).anchors
    gaps = np.diff(anchors)
    ok = np.flatnonzero(gaps >= 8)
    i = int(rng.choice(ok)) if ok.size else int(np.argmax(gaps))
    return int(anchors[i]), int(anchors[i + 1])


def warp(u, recipe, rng):
    if recipe == "pingpong":
        p = rng.uniform(0.55, 0.85)
        q = rng.uniform(0.15, p - 0.25)
        return np.interp(u, [0, 0.35, 0.65, 1], [0, p, q, 1])
    if recipe == "rewind":
        return np.interp(u, [0, 0.5, 0.75, 1], [0, 1, 0.5, 1])
    return u + 2.5 * np.sin(2 * np.pi * u) / (2 * np.pi)


removed = []
for recipe in ("pingpong", "rewind", "random_window"):
    before, after, cut = [], [], 0
    for i, clip in enumerate(clips):
        rng = np.random.default_rng(900 + i)
        x = clip.joints
        lo, hi = window(x, rng, recipe)
        t = np.arange(lo, hi + 1)
        flawed = x.copy()
        flawed[t] = resample(x, lo + (hi - lo) * warp((t - lo) / (hi - lo), recipe, rng))
        out, report = model.refine(flawed, action=clip.action, return_report=True)
        cut += any(c.get("repair") == "retrace_cut" for c in report.changes)
        before.append(np.linalg.norm(flawed - x, axis=-1).mean())
        after.append(np.linalg.norm(out - x, axis=-1).mean())
    removed.append(100 * (1 - np.mean(after) / np.mean(before)))
    print(f"{recipe:14s} loop cut in {cut}/{len(clips)} clips, removed {removed[-1]:+.1f} % "
          f"(the recipe added {100 * np.mean(before):.2f} cm)", flush=True)
print(f"mean {np.mean(removed):+.1f} %")
