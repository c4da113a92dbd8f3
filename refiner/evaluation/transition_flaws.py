"""Seeded transition flaws: jitter, a frozen transition, a transition played partly backwards, a time warp.

See :mod:`refiner.evaluation.flaws` for the table of all families and their severities. Retimed
frames are linearly interpolated between the two nearest source frames.
"""
from __future__ import annotations

import numpy as np

from refiner.concepts.segmentation import DEFAULT_PENALTY, Segmentation
from refiner.core.signal import resample
from refiner.evaluation.corruption import Corruption, finish_corruption, prepare_corruption

__all__ = ["transition_jitter", "frozen_transition", "reversed_transition", "time_warp"]

_JITTER_STD = (0.005, 0.01, 0.02)  # metres
_FREEZE_FRACTION = (0.3, 0.6, 0.9)
_REVERSE_AMPLITUDE = (1.5, 2.5, 3.5)
_WARP_AMPLITUDE = (0.3, 0.6, 0.9)


def transition_jitter(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Add white noise (std 0.5 / 1 / 2 cm) inside about half of the transitions, windowed to 0 at anchors.

    Each transition is chosen with probability 1/2 (at least one). Parameters as :func:`~refiner.evaluation.anchor_flaws.wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the chosen transitions.
    """
    m, x, anchors, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty)
    n_trans = len(anchors) - 1
    chosen = rng.random(n_trans) < 0.5
    first = int(rng.integers(n_trans))
    if not chosen.any():
        chosen[first] = True
    noise = rng.normal(size=x.shape)
    window = np.zeros(len(x))
    for i in np.flatnonzero(chosen):
        k, n = int(anchors[i]), int(anchors[i + 1])
        window[k + 1 : n] = np.sin(np.pi * (np.arange(k + 1, n) - k) / (n - k))
    new = x + _JITTER_STD[level] * window[:, None, None] * noise
    return finish_corruption(m, x, new, window > 0)


def frozen_transition(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Freeze one transition at its start pose for 30 / 60 / 90 % of its frames, then rush to its end.

    The transition (one of at least 4 frame intervals, else the longest) is retimed: source time stays
    at its first anchor for ``F`` frames and then runs ``L / (L - F)`` times too fast.
    Parameters as :func:`~refiner.evaluation.anchor_flaws.wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the transition.
    """
    m, x, anchors, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty)
    k, n = _pick_transition(anchors, rng, 4)
    length = n - k
    held = int(np.clip(round(_FREEZE_FRACTION[level] * length), 1, max(length - 1, 1))) / length

    def warp(v):
        return np.where(v <= held, 0.0, (v - held) / (1.0 - held))

    new, mask = _retime(x, k, n, warp)
    return finish_corruption(m, x, new, mask)


def reversed_transition(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Play part of one transition backwards: retime it by ``u + a sin(2 pi u) / (2 pi)``, a = 1.5 / 2.5 / 3.5.

    With ``a > 1`` the source time runs backwards around the middle of the transition (the motion
    retracts, then completes); its ends stay at the anchors. The transition is one of at least 6 frame
    intervals, else the longest. Parameters as :func:`~refiner.evaluation.anchor_flaws.wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the transition.
    """
    m, x, anchors, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty)
    k, n = _pick_transition(anchors, rng, 6)
    a = _REVERSE_AMPLITUDE[level]
    new, mask = _retime(x, k, n, lambda v: v + a * np.sin(2 * np.pi * v) / (2 * np.pi))
    return finish_corruption(m, x, new, mask)


def time_warp(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Retime a span of about half the transitions monotonically: ``u +- b sin(2 pi u) / (2 pi)``, b = 0.3 / 0.6 / 0.9.

    The span runs between two anchors; the sign (speed up first or slow down first) is random.
    Parameters as :func:`~refiner.evaluation.anchor_flaws.wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the span.
    """
    m, x, anchors, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty)
    n_trans = len(anchors) - 1
    span = max(1, int(np.ceil(n_trans / 2)))
    i = int(rng.integers(0, n_trans - span + 1))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    b = sign * _WARP_AMPLITUDE[level]
    new, mask = _retime(x, int(anchors[i]), int(anchors[i + span]), lambda v: v + b * np.sin(2 * np.pi * v) / (2 * np.pi))
    return finish_corruption(m, x, new, mask)


def _retime(x, start, stop, warp) -> tuple[np.ndarray, np.ndarray]:
    """Retime frames ``start..stop`` by ``warp`` (maps [0, 1] onto [0, 1]); returns (new clip, mask)."""
    new = x.copy()
    t = np.arange(start, stop + 1)
    v = (t - start) / (stop - start)
    new[t] = resample(x, start + (stop - start) * warp(v))
    mask = np.zeros(len(x), dtype=bool)
    mask[start + 1 : stop] = True
    return new, mask


def _pick_transition(anchors, rng, min_duration) -> tuple[int, int]:
    """A random transition at least ``min_duration`` long, else the longest one."""
    durations = np.diff(anchors)
    ok = np.flatnonzero(durations >= min_duration)
    i = int(rng.choice(ok)) if ok.size else int(np.argmax(durations))
    return int(anchors[i]), int(anchors[i + 1])
