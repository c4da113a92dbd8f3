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

Retimed frames are linearly interpolated between the two nearest source frames.
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import numpy as np

from refiner.concepts.segmentation import DEFAULT_PENALTY, Segmentation, segment
from refiner.core.motion import Motion
from refiner.core.signal import resample, smoothstep
from refiner.core.validation import check_random_state

__all__ = [
    "Corruption",
    "FLAW_FAMILIES",
    "SEVERITIES",
    "corrupt",
    "wrong_anchor",
    "anchor_drift",
    "transition_jitter",
    "frozen_transition",
    "reversed_transition",
    "time_warp",
    "foot_sliding",
]

SEVERITIES = (1, 2, 3)
#: Fewest frames a clip needs to be corrupted.
MIN_FRAMES = 8

_WRONG_ANCHOR_BLEND = (0.4, 0.7, 1.0)
_DRIFT_STD = (0.02, 0.04, 0.08)  # metres, per axis, at the last anchor
_JITTER_STD = (0.005, 0.01, 0.02)  # metres
_FREEZE_FRACTION = (0.3, 0.6, 0.9)
_REVERSE_AMPLITUDE = (1.5, 2.5, 3.5)
_WARP_AMPLITUDE = (0.3, 0.6, 0.9)
_SLIDE_DISTANCE = (0.1, 0.2, 0.4)  # metres
_SLIDE_WINDOW = 20  # frames
_MIN_GAP = 10  # frames between an anchor and a same-clip replacement pose
_WRONG_POSE_DISTANCE = 0.10  # metres of mean joint distance that makes a replacement "wrong"


class Corruption(NamedTuple):
    """A corrupted clip and where it was corrupted.

    Attributes
    ----------
    motion : Motion
        The corrupted clip (same length, skeleton, fps and action as the input).
    mask : ndarray of bool, shape (T,)
        True at the frames the corruption touched; all other frames equal the input exactly.
    """

    motion: Motion
    mask: np.ndarray


def _setup(motion, severity, random_state, segmentation, penalty, *, need_anchors: bool = True):
    """Validated Motion, float64 joints, anchors (None unless needed), rng and the severity's table index."""
    if isinstance(severity, (bool, np.bool_)) or severity not in SEVERITIES:
        raise ValueError(f"`severity` must be one of {SEVERITIES}; got {severity!r}.")
    m = motion if isinstance(motion, Motion) else Motion(motion)
    if m.n_frames < MIN_FRAMES:
        raise ValueError(f"`motion` is too short to corrupt: needs at least {MIN_FRAMES} frames; got {m.n_frames}.")
    if segmentation is not None and (
        not isinstance(segmentation, Segmentation) or segmentation.n_frames != m.n_frames
    ):
        raise ValueError(f"`segmentation` must be a Segmentation of this {m.n_frames}-frame clip.")
    anchors = None
    if need_anchors:
        seg = segmentation if segmentation is not None else segment(m.joints, penalty=penalty)
        anchors = np.asarray(seg.anchors)
    rng = check_random_state(random_state)
    return m, m.joints.astype(np.float64), anchors, rng, int(severity) - 1


def _finish(m: Motion, x: np.ndarray, new: np.ndarray, mask: np.ndarray) -> Corruption:
    """Write ``new`` into the masked frames only, so untouched frames stay bit-identical."""
    out = m.numpy()
    out[mask] = new[mask].astype(np.float32)
    mask = mask.copy()
    mask.flags.writeable = False
    return Corruption(m.with_joints(out), mask)


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
    m, x, anchors, rng, level = _setup(motion, severity, random_state, segmentation, penalty)
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
    return _finish(m, x, new, mask)


def anchor_drift(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Let the anchor poses drift: a per-joint random walk over the anchors, smooth in between.

    Offsets start at 0 on the first anchor; each later anchor adds independent Gaussian steps per joint
    and axis, scaled so the offset at the last anchor has standard deviation 2 / 4 / 8 cm per axis.
    Between anchors the offset moves by smoothstep. Parameters as :func:`wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: every frame after the first anchor.
    """
    m, x, anchors, rng, level = _setup(motion, severity, random_state, segmentation, penalty)
    n_steps = len(anchors) - 1
    steps = rng.normal(size=(n_steps, x.shape[1], 3)) / np.sqrt(n_steps)
    offsets = np.concatenate([np.zeros((1, x.shape[1], 3)), np.cumsum(steps, axis=0)]) * _DRIFT_STD[level]
    t = np.arange(len(x))
    seg = np.clip(np.searchsorted(anchors, t, side="right") - 1, 0, n_steps - 1)
    u = smoothstep((t - anchors[seg]) / (anchors[seg + 1] - anchors[seg]))[:, None, None]
    new = x + (1.0 - u) * offsets[seg] + u * offsets[seg + 1]
    return _finish(m, x, new, t > anchors[0])


def transition_jitter(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Add white noise (std 0.5 / 1 / 2 cm) inside about half of the transitions, windowed to 0 at anchors.

    Each transition is chosen with probability 1/2 (at least one). Parameters as :func:`wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the chosen transitions.
    """
    m, x, anchors, rng, level = _setup(motion, severity, random_state, segmentation, penalty)
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
    return _finish(m, x, new, window > 0)


def frozen_transition(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Freeze one transition at its start pose for 30 / 60 / 90 % of its frames, then rush to its end.

    The transition (one of at least 4 frame intervals, else the longest) is retimed: source time stays
    at its first anchor for ``F`` frames and then runs ``L / (L - F)`` times too fast.
    Parameters as :func:`wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the transition.
    """
    m, x, anchors, rng, level = _setup(motion, severity, random_state, segmentation, penalty)
    k, n = _pick_transition(anchors, rng, 4)
    length = n - k
    held = int(np.clip(round(_FREEZE_FRACTION[level] * length), 1, max(length - 1, 1))) / length

    def warp(v):
        return np.where(v <= held, 0.0, (v - held) / (1.0 - held))

    new, mask = _retime(x, k, n, warp)
    return _finish(m, x, new, mask)


def reversed_transition(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Play part of one transition backwards: retime it by ``u + a sin(2 pi u) / (2 pi)``, a = 1.5 / 2.5 / 3.5.

    With ``a > 1`` the source time runs backwards around the middle of the transition (the motion
    retracts, then completes); its ends stay at the anchors. The transition is one of at least 6 frame
    intervals, else the longest. Parameters as :func:`wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the transition.
    """
    m, x, anchors, rng, level = _setup(motion, severity, random_state, segmentation, penalty)
    k, n = _pick_transition(anchors, rng, 6)
    a = _REVERSE_AMPLITUDE[level]
    new, mask = _retime(x, k, n, lambda v: v + a * np.sin(2 * np.pi * v) / (2 * np.pi))
    return _finish(m, x, new, mask)


def time_warp(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Retime a span of about half the transitions monotonically: ``u +- b sin(2 pi u) / (2 pi)``, b = 0.3 / 0.6 / 0.9.

    The span runs between two anchors; the sign (speed up first or slow down first) is random.
    Parameters as :func:`wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the span.
    """
    m, x, anchors, rng, level = _setup(motion, severity, random_state, segmentation, penalty)
    n_trans = len(anchors) - 1
    span = max(1, int(np.ceil(n_trans / 2)))
    i = int(rng.integers(0, n_trans - span + 1))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    b = sign * _WARP_AMPLITUDE[level]
    new, mask = _retime(x, int(anchors[i]), int(anchors[i + span]), lambda v: v + b * np.sin(2 * np.pi * v) / (2 * np.pi))
    return _finish(m, x, new, mask)


def foot_sliding(
    motion, severity: int = 2, *, random_state=0, segmentation: Segmentation | None = None,
    penalty: float = DEFAULT_PENALTY,
) -> Corruption:
    """Make the whole body glide horizontally out and back by up to 10 / 20 / 40 cm while the feet are down.

    The offset is ``D sin²(pi u)`` along a random horizontal direction over a 20-frame window (the
    clip, if shorter), placed at random among the windows with the most foot-contact frames (lowest
    foot joint within 5 cm of the clip's ground, see :mod:`refiner.evaluation.physics`). The segmentation is
    not used. Parameters as :func:`wrong_anchor`.

    Returns
    -------
    Corruption
        Mask: the frames strictly inside the window.
    """
    from refiner.evaluation.physics import foot_joints, ground_height, heights

    m, x, _, rng, level = _setup(motion, severity, random_state, segmentation, penalty, need_anchors=False)
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
    return _finish(m, x, new, bump > 0)


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
