"""Seeded anchor flaws: a wrong key pose (``wrong_anchor``) and drifting key poses (``anchor_drift``).

See :mod:`refiner.evaluation.flaws` for the table of all families and their severities.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from refiner.concepts.segmentation import DEFAULT_PENALTY, Segmentation
from refiner.core.motion import Motion
from refiner.core.signal import smoothstep
from refiner.evaluation.corruption import Corruption, finish_corruption, prepare_corruption

__all__ = ["wrong_anchor", "anchor_drift"]

_WRONG_ANCHOR_BLEND = (0.4, 0.7, 1.0)
_DRIFT_STD = (0.02, 0.04, 0.08)  # metres, per axis, at the last anchor
_MIN_GAP = 10  # frames between an anchor and a same-clip replacement pose
_WRONG_POSE_DISTANCE = 0.10  # metres of mean joint distance that makes a replacement "wrong"


def wrong_anchor(
    motion,
    severity: int = 2,
    *,
    random_state=0,
    donors: Sequence[Motion] | None = None,
    segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Replace an anchor pose by a pose of another phase or another clip of the same action.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3)
        Clean clip, metres, T >= 8 (an array is taken as HumanAct12 at 20 fps).
    severity : {1, 2, 3}, default=2
        Blend 0.4 / 0.7 / 1.0 of the way to the wrong pose at the anchor.
    random_state : None, int or numpy Generator, default=0
    donors : sequence of Motion, optional
        Other clips of the same action (same skeleton) whose frames (every 5th) may supply the pose.
    segmentation : Segmentation, optional
        The clip's segmentation, to save recomputing it.
    penalty : float, default=200.0
        λ for the segmentation when none is given.

    Returns
    -------
    Corruption
        Mask: the frames strictly between the anchor's two neighbouring anchors.
    """
    m, x, anchors, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty)
    root = m.skeleton_info.root
    n_frames = len(x)
    if len(anchors) > 2:
        k = int(rng.integers(1, len(anchors) - 1))
        prev, a, nxt = int(anchors[k - 1]), int(anchors[k]), int(anchors[k + 1])
    else:  # one transition: treat its middle frame as the anchor
        prev, a, nxt = 0, n_frames // 2, n_frames - 1
    candidates = [x[t] for t in anchors if abs(int(t) - a) >= _MIN_GAP]
    for i, d in enumerate(donors or ()):
        if not isinstance(d, Motion) or d.skeleton != m.skeleton:
            raise ValueError(f"`donors` item {i} must be a Motion on skeleton {m.skeleton!r}.")
        if m.action is not None and d.action is not None and d.action != m.action:
            raise ValueError(f"`donors` item {i} has action {d.action}, the clip has action {m.action}.")
        candidates.extend(d.joints[::5].astype(np.float64))
    if not candidates:
        candidates = [x[t] for t in range(n_frames) if abs(t - a) >= 3]
    cand = np.stack(candidates)
    cand_rel = cand - cand[:, root : root + 1]
    orig_rel = x[a] - x[a, root]
    dist = np.linalg.norm(cand_rel - orig_rel, axis=-1).mean(-1)
    far = np.flatnonzero(dist >= _WRONG_POSE_DISTANCE)
    choice = int(rng.choice(far)) if far.size else int(np.argmax(dist))
    delta = cand_rel[choice] - orig_rel  # root row is 0: the root path is kept
    t = np.arange(n_frames)
    w = np.where(t <= a, smoothstep((t - prev) / max(a - prev, 1)), smoothstep((nxt - t) / max(nxt - a, 1)))
    w[(t <= prev) | (t >= nxt)] = 0.0
    new = x + _WRONG_ANCHOR_BLEND[level] * w[:, None, None] * delta
    mask = (t > prev) & (t < nxt)
    return finish_corruption(m, x, new, mask)


def anchor_drift(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Let the anchor poses drift: a per-joint random walk over the anchors, smooth in between.

    Offsets start at 0 on the first anchor; each later anchor adds independent Gaussian steps per joint
    and axis, scaled so the offset at the last anchor has standard deviation 2 / 4 / 8 cm per axis.
    Between anchors the offset moves by smoothstep. Parameters as :func:`~refiner.evaluation.anchor_flaws.wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: every frame after the first anchor.
    """
    m, x, anchors, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty)
    n_steps = len(anchors) - 1
    steps = rng.normal(size=(n_steps, x.shape[1], 3)) / np.sqrt(n_steps)
    offsets = np.concatenate([np.zeros((1, x.shape[1], 3)), np.cumsum(steps, axis=0)]) * _DRIFT_STD[level]
    t = np.arange(len(x))
    seg = np.clip(np.searchsorted(anchors, t, side="right") - 1, 0, n_steps - 1)
    u = smoothstep((t - anchors[seg]) / (anchors[seg + 1] - anchors[seg]))[:, None, None]
    new = x + (1.0 - u) * offsets[seg] + u * offsets[seg + 1]
    return finish_corruption(m, x, new, t > anchors[0])
