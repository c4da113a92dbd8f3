"""Retrace cut: motion that turns back over the path it just took, then forward over it again.

A body that reverses mid-motion and replays its own path backwards (forward to a turn, back to a
second turn, forward again past the first) shows the same poses three times. Real motion turns back
too (a dumbbell lowered along the path it was raised), but it does not retrace its path as exactly:
this module measures how exactly, and the refiner cuts a retrace only where the flaw classifier also
flags the frames around it (real back-and-forth motion it leaves alone).

The repair cuts the loop: the poses from where the first pass reached the second turn's pose to the
second turn are dropped, so the path is travelled once, and the frames around it (grown over the rush
before and after, as a stall's window is) are re-timed along that path with a speed that joins their
neighbours' speeds (:func:`~refiner.refinement.repair_candidates.retime_path`, as stalls are).

Written knowing the benchmark's ``reversed_transition`` family (no training flaw plays motion
backwards), so that family is not a held-out test of this step; other reversal recipes are (README).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from refiner.core.signal import resample
from refiner.refinement.repair_candidates import frame_speed, retime_path, teleports
from refiner.refinement.splicing import project_bone_lengths, reference_lengths

__all__ = ["Retrace", "turn_frames", "find_retraces", "retrace_window", "cut_retrace", "cut_retraces", "MAX_RATIO",
           "MIN_FLAW_PROBABILITY", "MAX_SPAN"]

#: A loop counts as a retrace when its backward poses lie within this share of its size from the path
#: the motion came along ... (real clips' most retrace-like loop: 1 % of HumanAct12's training clips under
#: 0.136, 2 % under 0.156; reversals seeded by the benchmark's recipe: mostly 0.02-0.10)
MAX_RATIO = 0.10
#: ... and the flaw classifier's probability between its turns (2 frames either side too) is at least this.
#: Both chosen on HumanAct12's training subjects and reversal recipes other than the benchmark's (README):
#: 0 of its 919 clean clips cut; 0.12 and 0.7 instead: 0 clips too, but 20.9 against 24.7 % removed.
MIN_FLAW_PROBABILITY = 0.5
#: Longest loop (frames from where the motion enters it to where it gets past its first turn again) that is
#: cut. The real loops as exact as :data:`MAX_RATIO` are whole repetitions of an exercise (a squat with a
#: dumbbell, 41-58 cm between the turning poses) spanning 37-52 frames (the shortest in the training clips
#: 36.7); cutting one removes real motion (10 cm on such a clip of the benchmark's subjects). Seeded
#: reversals on the training subjects span 16 frames in the median, 28 for 95 % of them.
MAX_SPAN = 32


@dataclass(frozen=True)
class Retrace:
    """One loop in a clip: forward to ``turn``, back to ``back_turn``, forward again.

    ``start``: the (fractional) frame where the first pass reached the pose of ``back_turn``;
    ``resume``: where the third pass gets past the pose of ``turn``; ``size``: mean joint distance
    (metres) between the two turning poses; ``ratio``: the backward poses' largest mean joint distance
    from the first pass's path (and the third pass's from the first turn's pose), over ``size``.
    """

    start: float
    turn: int
    back_turn: int
    resume: float
    size: float
    ratio: float


def turn_frames(joints: np.ndarray, *, cos_max: float = -0.5, floor: float = 0.0005, gaps=(1, 2)):
    """Frames where the whole body reverses: the displacement over ``g`` frames before and after a frame
    point opposite ways (cosine under ``cos_max``, all joints together), for any ``g`` in ``gaps``, both
    moving at least ``floor`` metres per frame (root-mean-square over joints). One frame per run of such
    frames (the most reversed). ``joints (T, J, 3)`` metres -> ``(K,)`` int; a batch ``(B, T, J, 3)`` (judged
    in one pass) -> a list of B such arrays."""
    if np.ndim(joints) not in (3, 4):
        raise ValueError(f"turn_frames needs joints of shape (T, J, 3) or (B, T, J, 3); got {np.shape(joints)}.")
    single = np.ndim(joints) == 3
    x = np.asarray(joints, np.float64)[None] if single else np.asarray(joints, np.float64)
    x = x.reshape(x.shape[0], x.shape[1], -1)  # (B, T, 3J)
    n_frames, n_joints = x.shape[1], x.shape[2] // 3
    cosine = np.ones(x.shape[:2])
    for g in gaps:
        if n_frames < 2 * g + 1:
            continue
        before, after = x[:, g:-g] - x[:, : -2 * g], x[:, 2 * g :] - x[:, g:-g]
        nb, na = np.linalg.norm(before, axis=-1), np.linalg.norm(after, axis=-1)
        c = (before * after).sum(-1) / np.maximum(nb * na, 1e-12)
        c[np.minimum(nb, na) / np.sqrt(n_joints) < floor * g] = 1.0
        cosine[:, g:-g] = np.minimum(cosine[:, g:-g], c)
    turns = []
    for row in cosine:
        edges = np.flatnonzero(np.diff(np.concatenate([[False], row < cos_max, [False]]).astype(np.int8)))
        turns.append(np.array([a + int(np.argmin(row[a:b])) for a, b in zip(edges[::2], edges[1::2])], dtype=np.int64))
    return turns[0] if single else turns


def _on_path(points: np.ndarray, path: np.ndarray, n_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``points (N, D)``: its fractional index on the polyline ``path (M, D)`` and its mean
    joint distance from it."""
    start, step = path[:-1], np.diff(path, axis=0)
    w = np.clip(((points[:, None] - start[None]) * step[None]).sum(-1)
                / np.maximum((step * step).sum(1), 1e-12)[None], 0.0, 1.0)
    gap = points[:, None] - (start[None] + w[..., None] * step[None])
    dist = np.linalg.norm(gap.reshape(len(points), len(start), n_joints, 3), axis=-1).mean(-1)
    i = dist.argmin(1)
    rows = np.arange(len(points))
    return i + w[rows, i], dist[rows, i]


def find_retraces(joints: np.ndarray, *, max_ratio: float = MAX_RATIO, max_back: int = 16, max_span: int = MAX_SPAN,
                  min_size: float = 0.005, turns: np.ndarray | None = None) -> list[Retrace]:
    """The retraces of a clip ``(T, J, 3)`` metres: loops whose backward run (at most ``max_back`` frames,
    turning poses at least ``min_size`` metres apart) lies within ``max_ratio`` of its size from the path
    before it, and whose third pass gets past the first turn within ``max_span`` frames of where the first
    pass entered the loop. A loop's second turn is the first later turn within ``max_back`` that makes a
    retrace (a spurious turn may lie between the two: pairing consecutive turns only lost 6 of HumanAct12's
    1,191 seeded reversals at severity 3); ``turns``: the clip's :func:`turn_frames`, when known. At most one
    loop per first turn."""
    x = np.asarray(joints, np.float64)
    flat, n_joints = x.reshape(len(x), -1), x.shape[1]
    turns, reach = (turn_frames(x) if turns is None else turns), 2 * max_back
    found = []
    for i, f1 in enumerate(turns):
        for f2 in turns[i + 1 :]:
            if f2 - f1 > max_back:
                break
            loop = _retrace(flat, n_joints, int(f1), int(f2), max_ratio, max_span, min_size, reach)
            if loop is not None:
                found.append(loop)
                break
    return found


def _retrace(flat: np.ndarray, n_joints: int, f1: int, f2: int, max_ratio: float, max_span: int, min_size: float,
             reach: int) -> Retrace | None:
    """The loop turning at ``f1`` and ``f2`` of the flattened clip ``flat (T, 3J)``, if it is a retrace."""
    size = float(np.linalg.norm((flat[f1] - flat[f2]).reshape(n_joints, 3), axis=1).mean())
    lo, hi = max(0, f1 - reach), min(len(flat) - 1, f2 + reach)
    if size < min_size or f1 - lo < 1 or hi - f2 < 1:
        return None
    # cheapest first: does the third pass get back to the first turn's pose, and the run's end onto the path?
    ahead, past = _on_path(flat[f1 : f1 + 1], flat[f2 : hi + 1], n_joints)
    if past[0] > max_ratio * size or _on_path(flat[f2 : f2 + 1], flat[lo : f1 + 1], n_joints)[1][0] > max_ratio * size:
        return None
    along, back = _on_path(flat[f1 : f2 + 1], flat[lo : f1 + 1], n_joints)
    start, resume = lo + along[-1], f2 + ahead[0]
    ratio = max(float(back.max()), float(past[0])) / size
    if start < f1 - 0.5 and f2 + 0.5 < resume < hi and ratio <= max_ratio and resume - start <= max_span:
        return Retrace(float(start), f1, f2, float(resume), size, ratio)
    return None


def retrace_window(joints: np.ndarray, loop: Retrace, rush: float = 1.5, reach: int = 12) -> tuple[int, int]:
    """Frames ``(lo, hi)`` (inclusive; the ends keep their poses) that cutting ``loop`` re-times in ``joints
    (T, J, 3)``: the loop grown over the frames before and after it that move faster than ``rush`` times the
    clip's median speed (but not over a jump in the recording,
    :func:`~refiner.refinement.repair_candidates.teleports`), at most ``reach`` each side, up to the clip's first
    and last frames: a motion that turned back had to rush ahead before it and catch up after it. (The stall repair grows its run the same
    way, :func:`~refiner.refinement.repair_candidates.stall_window`, but over the changed frames, so that its
    window never reaches the clip's ends: here that cost the calibration reversals 40.7 -> 28.3 %.)"""
    speed, median = frame_speed(joints)
    lo, hi = int(np.floor(loop.start)), int(np.ceil(loop.resume))
    a, b = lo, hi
    jumps = teleports(joints, median)
    while a > max(lo - reach, 0) and speed[a - 1] > rush * median and not jumps[a - 1]:
        a -= 1
    while b < min(hi + reach, len(joints) - 1) and speed[b] > rush * median and not jumps[b]:
        b += 1
    return a, b


def cut_retrace(joints: np.ndarray, loop: Retrace, window: tuple[int, int] | None = None
                ) -> tuple[np.ndarray, tuple[int, int]]:
    """``joints (T, J, 3)`` with ``loop`` cut: the poses from ``loop.start`` to ``loop.back_turn`` dropped and the
    ``window`` (default :func:`retrace_window`; inclusive, its two ends keep their poses) re-timed along the
    path that is left; returns ``(clip, window)``."""
    lo, hi = retrace_window(joints, loop) if window is None else window
    times = np.r_[np.arange(lo, np.floor(loop.start) + 1), loop.start, np.arange(loop.back_turn, hi + 1)]
    path = resample(np.asarray(joints, np.float64), times.astype(np.float64))
    return retime_path(np.asarray(joints), lo, hi, path), (lo, hi)


def cut_retraces(refiner, clips: np.ndarray, reports: list, mode: str, flaw_probability: np.ndarray | None = None
                 ) -> np.ndarray:
    """The refiner's retrace step: in ``clips (B, T, J, 3)``, each retrace that the flaw classifier flags between
    its turns (2 frames either side too) is cut (the most exact first; none whose window overlaps a cut one), the
    changed frames put back on the clip's bone lengths and the change written to the clip's report. A
    transition step: not in ``mode="anchor"``, nor with ``refiner.retiming == "stalls"`` or without a flaw
    classifier. ``flaw_probability (B, T)``: the classifier's on ``clips`` when the caller has it (then clips it
    never flags are not searched: the search is the step's cost)."""
    classifier = getattr(refiner, "flaw_classifier", None)
    if classifier is None or getattr(refiner, "retiming", "flagged") == "stalls" or mode == "anchor":
        return clips
    turns = turn_frames(clips) if len(clips) else []
    flagged = (np.ones(len(clips), bool) if flaw_probability is None
               else np.asarray(flaw_probability).max(axis=1, initial=0.0) >= MIN_FLAW_PROBABILITY)
    found = {b: loops for b in range(len(clips)) if len(turns[b]) > 1 and flagged[b]
             and (loops := find_retraces(clips[b], max_ratio=MAX_RATIO, max_span=MAX_SPAN, turns=turns[b]))}
    if not found:
        return clips
    out = clips.copy()
    prob = (classifier.predict(clips[list(found)]) if flaw_probability is None
            else np.asarray(flaw_probability)[list(found)])
    for k, (b, loops) in enumerate(found.items()):
        changed = np.zeros(clips.shape[1], bool)
        for loop in sorted(loops, key=lambda loop: loop.ratio):  # the most exact first; one overlapping a cut one: left
            peak = float(prob[k, max(loop.turn - 2, 0) : loop.back_turn + 3].max())
            lo, hi = retrace_window(clips[b], loop)
            if peak < MIN_FLAW_PROBABILITY or changed[lo : hi + 1].any():
                continue
            cut = cut_retrace(out[b], loop, (lo, hi))[0]
            if np.array_equal(cut, out[b]):  # the path held a jump in the recording: not re-timed
                continue
            out[b] = cut
            changed[lo : hi + 1] = True
            moved = 100 * float(np.linalg.norm(out[b][lo : hi + 1] - clips[b][lo : hi + 1], axis=-1).mean())
            reports[b].flagged_transitions.append([lo, hi + 1])
            reports[b].changes.append({
                "start": lo, "stop": hi + 1, "step": "transition", "repair": "retrace_cut",
                "reason": f"the motion turned back at frame {loop.turn} and retraced its path (within "
                          f"{100 * loop.ratio:.0f} % of the {100 * loop.size:.1f} cm loop) to frame {loop.back_turn}; "
                          f"kinematic flaw probability up to {peak:.2f} between the turns (at least "
                          f"{MIN_FLAW_PROBABILITY:g} asked); the loop cut and the frames re-timed along the path "
                          f"(moved {moved:.1f} cm on average)"})
        if changed.any():
            out[b] = project_bone_lengths(out[b], reference_lengths(clips[b], refiner.skeleton), changed, refiner.skeleton)
    return out
