"""The seeded ground flaw: the whole body glides over the ground while the feet are down (``foot_sliding``).

See :mod:`refiner.evaluation.flaws` for the table of all families and their severities.
"""
from __future__ import annotations

import numpy as np

from refiner.concepts.segmentation import DEFAULT_PENALTY, Segmentation
from refiner.core.contact import foot_joints, heights
from refiner.evaluation.corruption import Corruption, finish_corruption, prepare_corruption
from refiner.evaluation.ground_metrics import ground_height

__all__ = ["foot_sliding"]

_SLIDE_DISTANCE = (0.1, 0.2, 0.4)  # metres
_SLIDE_WINDOW = 20  # frames


def foot_sliding(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Make the whole body glide horizontally out and back by up to 10 / 20 / 40 cm while the feet are down.

    The offset is ``D sin²(pi u)`` along a random horizontal direction over a 20-frame window (the
    clip, if shorter), placed at random among the windows with the most foot-contact frames (lowest
    foot joint within 5 cm of the clip's ground, see :mod:`refiner.evaluation.ground_metrics`). The segmentation is
    not used. Parameters as :func:`~refiner.evaluation.anchor_flaws.wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the window.
    """
    m, x, _, rng, level = prepare_corruption(motion, severity, random_state, segmentation, penalty, need_anchors=False)
    skel = m.skeleton_info
    n_frames = len(x)
    width = min(_SLIDE_WINDOW, n_frames)
    low = heights(x[:, list(foot_joints(skel))], skel).min(-1) - ground_height(m)
    contact = (low < 0.05).astype(np.int64)
    counts = np.convolve(contact, np.ones(width, dtype=np.int64), mode="valid")  # windows starting at 0..T-width
    start = int(rng.choice(np.flatnonzero(counts == counts.max())))
    up = skel.up_vector
    axes = [np.eye(3)[i] for i in range(3) if up[i] == 0]
    theta = rng.uniform(0.0, 2.0 * np.pi)
    direction = np.cos(theta) * axes[0] + np.sin(theta) * axes[1]
    t = np.arange(n_frames)
    u = (t - start) / (width - 1)
    bump = np.where((u > 0) & (u < 1), np.sin(np.pi * u) ** 2, 0.0)
    new = x + _SLIDE_DISTANCE[level] * bump[:, None, None] * direction
    return finish_corruption(m, x, new, bump > 0)
