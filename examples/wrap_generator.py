"""Wrap a generator with RefinedGenerator: sample, convert to canonical motions, refine.

Run: ``python examples/wrap_generator.py`` (uses the ToyMotion example generator; with the example
plugin installed, ``pip install examples/third_party_adapter``, the adapter is found through its
entry point; otherwise it is registered by hand here).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from refiner import RefinedGenerator
from refiner.plugins import get_plugin_manager

sys.path.insert(0, str(Path(__file__).resolve().parent / "third_party_adapter"))
import toymotion_adapter  # noqa: E402

pm = get_plugin_manager()
if "toymotion" not in pm.adapters():  # the example package is not installed: register its module
    pm.register(toymotion_adapter, name="toymotion")


def smooth(motion):
    """A stand-in refiner: 3-frame moving average of the joints."""
    j = motion.numpy()
    j[1:-1] = (j[:-2] + j[1:-1] + j[2:]) / 3.0
    return motion.with_joints(j)


gen = RefinedGenerator(toymotion_adapter.ToyMotionGenerator(), refiner=smooth, plugin_manager=pm)
motions, raw = gen.sample(1, n=3, return_raw=True, random_state=0)
print(gen)
for m in motions:
    head = m.joints[:, 15] - m.joints[:, 0]
    print(f"{m}: head {-head[:, 1].mean():.2f} m above the pelvis, walked {-m.joints[-1, 0, 2]:.2f} m along -z")
unrefined = pm.convert("toymotion", raw)
moved = max(np.abs(a.joints - b.joints).max() for a, b in zip(motions, unrefined))
print(f"raw output {raw.shape} in cm; the refiner moved joints by up to {100 * moved:.1f} cm")
