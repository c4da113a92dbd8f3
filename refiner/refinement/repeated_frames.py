"""Repeated frames: a pose that repeats the frame before it exactly while the body moves (a dropped frame, a stutter).

Motion capture never holds a moving body still to the micrometre: no clip of HumanAct12 (1,191 clips) and none of
the real Action2Motion samples repeats a frame exactly, and CMU's subset repeats one in a moving stretch 6 times in
1,088 clips (a capture glitch). A short group of exactly equal frames between moving frames is a sample held while
time ran on: frame ``s`` was shown for ``L`` frames, then the clip jumped to the next sample. Its frames are put back
where they belong in time, on a cubic through the samples around them. A longer group is a stall or a hold, whose
stop and rush the timing steps re-time. It is the refiner's last motion step: run first, the timing estimator read
the in-between frames as mistimed and re-timed them.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from refiner.refinement.splicing import project_bone_lengths, reference_lengths

__all__ = ["repeated_groups", "unrepeated", "REPEAT_TOLERANCE", "MAX_REPEAT", "MOVING", "CONTEXT"]

#: Metres: frames whose every coordinate agrees within this repeat each other (float32 mocap of a still body still
#: differs by about 1e-5 m from frame to frame).
REPEAT_TOLERANCE = 1e-6
#: Longest group of equal frames read as a stutter (a frame shown 2 or 3 times); longer ones are stalls or holds.
MAX_REPEAT = 3
#: Metres per frame (mean joint speed) the steps into and out of a group must reach: the body moves around it.
MOVING = 0.003
#: Frames on each side of a group whose samples the cubic through it uses.
CONTEXT = 3


def repeated_groups(x: np.ndarray) -> list[tuple[int, int]]:
    """Groups ``(s, e)`` of joints ``x (T, J, 3)`` metres: frames ``s..e-1`` all equal frame ``s`` (``2 <= e - s <=``
    :data:`MAX_REPEAT`), with the body moving (:data:`MOVING`) in the step into ``s`` and the step out of ``e - 1``."""
    x = np.asarray(x)
    if x.ndim != 3:
        raise ValueError(f"`x` must be (T, J, 3); got shape {x.shape}.")
    step = np.diff(x.astype(np.float64), axis=0)
    same = np.abs(step).max((1, 2)) <= REPEAT_TOLERANCE  # (T-1,): step t -> t+1 repeats
    speed = np.linalg.norm(step, axis=-1).mean(-1)
    edges = np.flatnonzero(np.diff(np.r_[0, same.astype(np.int8), 0]))
    out = []
    for a, c in zip(edges[::2], edges[1::2]):  # steps a..c-1 repeat: frames a..c are equal
        s, e = int(a), int(c) + 1
        if e - s <= MAX_REPEAT and s > 0 and e < len(x) and speed[s - 1] >= MOVING and speed[e - 1] >= MOVING:
            out.append((s, e))
    return out


def unrepeated(refiner, clips: np.ndarray, reports: list, mode: str) -> np.ndarray:
    """``clips (B, T, J, 3)`` metres with each :func:`repeated_groups` group's repeats put back in time on a cubic
    through the samples within :data:`CONTEXT` frames, on the clip's bone lengths (a transition refinement: skipped
    in ``mode="anchor"``); each stretch of groups is one change in its clip's report."""
    if mode == "anchor":
        return clips
    out = clips
    for b in range(len(clips)):
        groups = repeated_groups(clips[b])
        if not groups:
            continue
        if out is clips:
            out = clips.copy()
        y = out[b].astype(np.float64)
        repeat = np.zeros(len(y), bool)
        for s, e in groups:
            repeat[s + 1 : e] = True
        t = np.arange(len(y))
        for s, e in groups:  # a cubic through the samples around (the repeats of next-door groups left out)
            near = t[max(s - CONTEXT, 0) : e + CONTEXT + 1]
            near = near[~repeat[near]]
            y[s + 1 : e] = CubicSpline(near, y[near], axis=0)(np.arange(s + 1, e))
        spans = []  # groups next to each other (a stutter) make one change
        for s, e in groups:
            if spans and s <= spans[-1][1]:
                spans[-1][1:] = [e, spans[-1][2] + 1]
            else:
                spans.append([s, e, 1])
        for s, e, n in spans:
            reports[b].changes.append({"start": s + 1, "stop": e, "step": "transition", "repair": "repeated_frames",
                                       "reason": f"{n} pose{'s' if n > 1 else ''} in frames {s}-{e - 1} repeated exactly "
                                                 f"while the body moves (dropped frames); the repeats put back in time "
                                                 f"on a cubic through the poses around them"})
            reports[b].flagged_transitions.append([s + 1, e])
        out[b] = project_bone_lengths(y.astype(clips.dtype), reference_lengths(clips[b], refiner.skeleton), repeat,
                                      refiner.skeleton)
    return out
