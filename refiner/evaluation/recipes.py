"""Flaw recipes outside the benchmark: how much of the error each adds a refiner removes.

The scripts ``examples/measure_*_recipes.py`` corrupt real clips with recipes of their own (none of them a family of
:mod:`refiner.evaluation.flaws`) and print, per recipe, what :func:`removed_by_recipe` returns.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["removed_by_recipe"]


def removed_by_recipe(model, clips, recipes: dict[str, Callable], *, seed: int, counted: Callable = lambda report: False,
                      with_action: bool = True) -> dict[str, dict]:
    """Each recipe ``fn(x, rng) -> flawed`` (``x (T, J, 3)`` float64 metres, ``rng`` seeded ``seed + clip index``) on
    every Motion of ``clips``, refined by ``model`` (with the clip's action, or unknown); per recipe the mean MPJPE
    ``before_cm`` and ``after_cm`` (all frames, against the clean clip), ``removed_pct`` (share of the added error
    removed) and ``counted`` (clips whose report ``counted(report)`` is true: those a step of interest changed)."""
    out = {}
    for name, recipe in recipes.items():
        before, after, n = [], [], 0
        for i, m in enumerate(clips):
            x = np.asarray(m.joints, dtype=np.float64)
            flawed = np.asarray(recipe(x, np.random.default_rng(seed + i)), dtype=np.float32)
            refined, report = model.refine(flawed, action=m.action if with_action else None, return_report=True)
            before.append(np.linalg.norm(flawed - x, axis=-1).mean())
            after.append(np.linalg.norm(refined - x, axis=-1).mean())
            n += bool(counted(report))
        out[name] = {"before_cm": 100 * float(np.mean(before)), "after_cm": 100 * float(np.mean(after)),
                     "removed_pct": 100 * (1 - float(np.mean(after)) / float(np.mean(before))), "counted": n}
    return out
