"""What every refinement step shares: runs of flagged frames, and the physical figures a change is verified on.

A step has a frozen config dataclass and four parts: ``detect`` (which frames and parts are flawed), ``propose``
(a repair of them), ``verify`` (keep a repair only where it makes the clip better on some figure and worse on none)
and ``report`` (the changes, in :class:`~refiner.refinement.report.RefinementReport` entries).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from refiner.core.contact import foot_joints, heights
from refiner.core.skeletons import get_skeleton

__all__ = ["runs", "grown", "dilated", "WindowFigures", "window_figures", "harms"]


def runs(mask) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the True runs of a ``(T,)`` bool mask."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def grown(start: int, stop: int, allowed) -> tuple[int, int]:
    """The run ``[start, stop)`` grown back and forward over the frames where ``allowed (T,)`` holds, stopping short
    of the first and last frame (which bound every repair)."""
    n = len(allowed)
    while start > 1 and allowed[start - 1]:
        start -= 1
    while stop < n - 1 and allowed[stop]:
        stop += 1
    return start, stop


def dilated(mask, before: int, after: int | None = None) -> np.ndarray:
    """``(T, ...)`` bool mask grown by ``before`` frames back and ``after`` (default the same) forward along axis 0."""
    after = before if after is None else after
    m = np.asarray(mask, bool)
    out = m.copy()
    for k in range(1, before + 1):
        out[:-k] |= m[k:]
    for k in range(1, after + 1):
        out[k:] |= m[:-k]
    return out


@dataclass(frozen=True)
class WindowFigures:
    """Physical figures of a window of a clip: mean joint jerk (m/frame³), foot slide (frame pairs in which a foot
    within ``contact_m`` of the ground moves faster than ``skate_m`` horizontally, as GMD's foot skating counts them),
    penetration of the lowest foot below ``ground`` and its floating beyond ``contact_m`` (metres, means over the
    window's frames, so that a tolerance per frame can be put on them)."""

    jerk: float
    slide: float
    penetration: float
    floating: float


def window_figures(joints, start: int, stop: int, skeleton, ground: float, contact_m: float = 0.05,
                   skate_m: float = 0.025) -> WindowFigures:
    """:class:`WindowFigures` of ``joints (T, J, 3)`` over ``[start, stop)`` widened by 3 frames (jerk needs them)."""
    x = np.asarray(joints, np.float64)
    lo, hi = max(0, start - 3), min(len(x), stop + 3)
    w = x[lo:hi]
    jerk = float(np.linalg.norm(np.diff(w, 3, axis=0), axis=-1).mean()) if len(w) > 3 else 0.0
    feet = list(foot_joints(skeleton))
    h = heights(w[:, feet], skeleton) - ground  # (t, 2)
    up = get_skeleton(skeleton).up_vector
    step = np.diff(w[:, feet], axis=0)
    horizontal = np.linalg.norm(step - (step @ up)[..., None] * up, axis=-1)
    on_ground = (h[1:] < contact_m) & (h[:-1] < contact_m) & (horizontal > skate_m)
    low = h.min(1)
    return WindowFigures(jerk, float(on_ground.sum()), float(np.clip(-low, 0, None).mean()),
                         float(np.clip(low - contact_m, 0, None).mean()))


def harms(before: WindowFigures, after: WindowFigures, *, jerk_share: float, ground_tolerance_m: float,
          slide_pairs: float) -> list[str]:
    """The figures ``after`` is worse on: jerk up by more than ``jerk_share``, foot slide by more than ``slide_pairs``,
    penetration and floating by more than ``ground_tolerance_m``."""
    out = []
    if after.jerk > before.jerk * (1 + jerk_share) + 1e-6:
        out.append("jerk")
    if after.slide > before.slide + slide_pairs:
        out.append("slide")
    for name in ("penetration", "floating"):
        if getattr(after, name) > getattr(before, name) + ground_tolerance_m:
            out.append(name)
    return out
