"""Synthetic flaws for benchmarking refiners: documented corruptions of real clips at three severities.

Each corruption takes a clean clip, finds its anchors and transitions with
:func:`refiner.concepts.segmentation.segment` (λ = 200), and returns a :class:`Corruption`: the corrupted clip
and the boolean mask of the frames it touched (True = touched; every other frame is bit-identical to
the input). All random choices (which anchor, which transition, noise, directions) are drawn from
``random_state`` *before* and independently of the severity, so for one seed the severities differ
only in amplitude. Severity ``s`` in (1, 2, 3) picks the ``s``-th value of the family's table:

======================  =====================================================================  ===============
family                  what is done                                                            amplitude (1/2/3)
======================  =====================================================================  ===============
``wrong_anchor``        an interior anchor's root-relative pose is moved toward a pose from     0.4 / 0.7 / 1.0
                        another phase of the clip (an anchor >= 10 frames away) or from a        of the way
                        ``donors`` clip of the same action (preferring poses >= 10 cm away),
                        blended in over the two adjacent transitions (smoothstep weight 1 at
                        the anchor, 0 at its neighbouring anchors); the root path is kept
``anchor_drift``        the anchor poses drift: a per-joint random walk over the anchors        2 / 4 / 8 cm
                        (0 at the first), smoothstep-interpolated between them; the value is    per axis at the
                        the drift's standard deviation at the last anchor                       last anchor
``transition_jitter``   white noise inside about half of the transitions (at least one),        0.5 / 1 / 2 cm
                        windowed by ``sin(pi u)`` so the anchors stay put                       noise std
``frozen_transition``   one transition stalls at its start pose for a fraction of its           30 / 60 / 90 %
                        frames, then rushes to its end anchor                                   of its frames
``reversed_transition`` one transition is retimed by ``u + a sin(2 pi u) / (2 pi)``: part of     a = 1.5 / 2.5 /
                        it plays backwards (the motion retracts, then goes on)                   3.5
``time_warp``           a span of about half the transitions is retimed monotonically by        b = 0.3 / 0.6 /
                        ``u +- b sin(2 pi u) / (2 pi)`` (too fast, then too slow or the          0.9
                        reverse)
``foot_sliding``        the whole body glides horizontally out and back (``D sin²``) over a     D = 10 / 20 /
                        20-frame window chosen where the feet are on the ground; at 20 fps the  40 cm
                        peak speed is 0.31 / 0.63 / 1.26 m/s
======================  =====================================================================  ===============

Retimed frames are linearly interpolated between the two nearest source frames. The families live in
:mod:`refiner.evaluation.anchor_flaws`, :mod:`refiner.evaluation.transition_flaws` and
:mod:`refiner.evaluation.ground_flaws`, what they share in :mod:`refiner.evaluation.corruption`; every
public name of those is importable from here.
"""
from __future__ import annotations

from typing import Callable, Sequence

from refiner.concepts.segmentation import DEFAULT_PENALTY, Segmentation
from refiner.core.motion import Motion
from refiner.evaluation.anchor_flaws import anchor_drift, wrong_anchor
from refiner.evaluation.corruption import MIN_FRAMES, SEVERITIES, Corruption
from refiner.evaluation.ground_flaws import foot_sliding
from refiner.evaluation.transition_flaws import frozen_transition, reversed_transition, time_warp, transition_jitter

__all__ = [
    "Corruption",
    "FLAW_FAMILIES",
    "SEVERITIES",
    "MIN_FRAMES",
    "corrupt",
    "wrong_anchor",
    "anchor_drift",
    "transition_jitter",
    "frozen_transition",
    "reversed_transition",
    "time_warp",
    "foot_sliding",
]


#: Corruption families by name, each ``fn(motion, severity, *, random_state, segmentation, ...)``.
FLAW_FAMILIES: dict[str, Callable[..., Corruption]] = {
    "wrong_anchor": wrong_anchor,
    "anchor_drift": anchor_drift,
    "transition_jitter": transition_jitter,
    "frozen_transition": frozen_transition,
    "reversed_transition": reversed_transition,
    "time_warp": time_warp,
    "foot_sliding": foot_sliding,
}


def corrupt(
    motion,
    family: str,
    severity: int = 2,
    *,
    random_state=0,
    donors: Sequence[Motion] | None = None,
    segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Apply one corruption family (see the module docstring) to a clean clip.

    Parameters
    ----------
    motion : Motion or array-like of shape (T, J, 3)
        Clean clip, metres, T >= 8.
    family : str
        A key of :data:`FLAW_FAMILIES`.
    severity : {1, 2, 3}, default=2
    random_state : None, int or numpy Generator, default=0
        The same seed gives the same corruption; severities of one seed differ only in amplitude.
    donors : sequence of Motion, optional
        Same-action clips for ``wrong_anchor`` (ignored by the other families).
    segmentation : Segmentation, optional
        Precomputed segmentation of ``motion``.
    penalty : float, default=200.0

    Returns
    -------
    Corruption
        ``(motion, mask)``; frames outside ``mask`` are exactly the input's.

    Examples
    --------
    >>> import numpy as np
    >>> from refiner.core.motion import Motion
    >>> t = np.linspace(0, 1, 40)[:, None, None]
    >>> clip = Motion(np.concatenate([np.sin(3 * t), t, t**2], axis=2).repeat(24, axis=1))
    >>> bad, mask = corrupt(clip, "transition_jitter", 3, random_state=0)
    >>> bool(np.array_equal(bad.joints[~mask], clip.joints[~mask]))
    True
    """
    if family not in FLAW_FAMILIES:
        raise ValueError(f"unknown flaw family {family!r}; known: {', '.join(FLAW_FAMILIES)}.")
    kwargs = {"random_state": random_state, "segmentation": segmentation, "penalty": penalty}
    if family == "wrong_anchor":
        kwargs["donors"] = donors
    return FLAW_FAMILIES[family](motion, severity, **kwargs)
