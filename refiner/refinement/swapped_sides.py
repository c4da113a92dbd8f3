"""Left/right confusion: a window in which a limb pair shows each side's motion on the other side.

A generator (or the refinement issue's training flaw ``mirror``) can put the left leg's motion on the right
leg for a while: in a walk, a step with the same foot twice. Each frame of such a window is a pose a body can
hold, so nothing in one frame tells it; what tells it is the jump into and out of the window, where each leg
leaves its own path for the other's. Swapping the sides back over the right window makes the limbs move least:
:func:`swapped_window` finds that window from the limbs' speed, and :func:`unswapped`, a step of the learned
pipeline after the flagged runs are repaired, swaps the legs back there where that takes most of their motion away,
and keeps it only where the flaw classifier finds the result more real than the given frames. It runs after the run
repairs because a reversed run's turn looks like a swap too: in a run, the legs swapped show the pose half a stride
on, and one held-out reversal, swapped first, was no longer cut (0.16 -> 1.27 cm).

Two kinds of swap are looked for (:data:`SWAPS`). *Mirrored* legs: each side reflected across the plane that bisects
the pair's two root joints (the hips), so the left leg's pose becomes a right leg's pose, as a body would hold it (a
step with the same foot twice). *Relabelled* legs or arms: the two sides' joints trade places as they are (the
training flaw ``mirror``: a skeleton's labels confused), which puts each limb on the wrong side of the body. A
relabelling blended in over a few frames is not found by the swaps: the limbs then meet and cross, and swapping them
back (meeting and parting) moves them as much. :func:`unblended_sides` reads such a blend from the roots' distance
(rigid in mocap, it shrinks to ``|1 - 2w|`` under a blend of weight ``w``) and undoes it exactly, first, before the
rigid step rebuilds the frames where the hips cross.
"""
from __future__ import annotations

import numpy as np

from refiner.core.skeletons import get_skeleton
from refiner.refinement.splicing import project_bone_lengths, reference_lengths
from refiner.refinement.training_flaws import limb_joints, mirror_pairs

__all__ = ["limb_pair", "sides_swapped", "swapped_window", "body_right", "blend_weights", "unblended", "unblended_sides",
           "unswapped",
           "MIN_FRAMES", "SWAPS", "STEADY", "DEGENERATE"]

#: Fewest frames of a swapped window (0.4 s at 20 fps: a step takes longer). With the legs' motion read in the world's
#: frame (a first version), 11 of 600 ``a2m`` samples at 3 had 3-5 frames of jittery, nearly symmetric legs swapped, 4
#: at 8 (the same-foot recipes of ``examples/measure_body_recipes.py``, 15-40 frames, unchanged); as shipped, 7.
MIN_FRAMES = 8
#: The swaps looked for, in this order: name -> (the limb's root joint, the first a skeleton has; mirrored or relabelled;
#: the largest ratio of :func:`swapped_window` offered to the flaw classifier; the classifier's price per centimetre
#: moved when it judges the swap, None: the pipeline's ``change_penalty``). Mirrored legs at 0.86: 3 of HumanAct12's 919
#: training subjects' clean clips reach it (0.5 %: 0.89, 1 %: 0.98), 19 of CMU's 815 (0.5 %: 0.76); judged at the
#: pipeline's price (at none, 600 ``a2m`` samples: 19 clips swapped, not 7, FID 3.533 -> 3.543). Relabelled limbs at 0.5:
#: no clean training clip comes near (lowest 0.75 legs, 0.68 arms; 0.5 %: 1.0 and 1.17), relabelled windows of the
#: recipes' (15-40 frames) 0.02 / 0.07 (median, legs / arms), 0.22 / 0.23 (90 %); judged at no price, since they move
#: the limbs some 20 cm (at the pipeline's 0.01, the classifier refused most relabelled arms it found more real: 10.9
#: against 93.6 % of the error removed on the calibration subjects). Mirrored arms are not looked for: clean arms reach
#: 0.63 at 0.5 %, since arms move on their own. Empty: the step is off.
#: Blended relabelling (:func:`blend_weights`): a pair's roots are a rigid body's where their distance stays within
#: ``STEADY`` of its 90th percentile in at least ``STEADY_SHARE`` of the frames (every clean HumanAct12 and CMU clip, hips
#: and collars or CMU's shoulders: exactly; at 0.5, a short clip blended over most of its frames was passed over, its
#: blend recipe 44.2 % against 95.7 % on the calibration subjects; no clean clip and no sample of ``a2m``, ``actor`` or
#: ``mdm`` shows a blend at 0.1 either); a frame is blended where the distance falls below it or the pair points the
#: wrong way; where ``|1 - 2w|`` is under ``DEGENERATE`` the inverse would amplify noise, and the frames are in-filled from
#: their neighbours instead (0.05 / 0.1 / 0.2: the same figures).
STEADY, DEGENERATE = 0.005, 0.2
STEADY_SHARE = 0.1
#: Frames blended less than this are left as given: noise on the roots moves them that much.
SLIGHT = 0.05
#: ... and a pair whose blend never reaches this weight is left as given: the training flaw ``mirror`` blends by 0.5-1,
#: and a wrong anchor's pose from another body moves the hips or collars up to 28 % closer (w 0.14). At 0.4, one held-out
#: time warp whose hips the re-sampling passed through each other read as a blend of 0.44 (1.18 -> 1.42 cm, undone).
PEAK = 0.5
#: Whether blended relabellings are looked for (:func:`unblended_sides`). Held-out recipes of
#: ``examples/measure_body_recipes.py``: the legs relabelled over a 4-frame ramp -1.7 -> 97.5 %, every limb blended by
#: 0.6-1.0 19.8 -> 96.5 % (calibration subjects 98.1 and 93.9 %); no clean HumanAct12 or CMU clip and no sample of ``a2m``, ``actor``, ``mdm`` shows a blend. The rules
#: that keep it off the benchmark's held-out clips (:data:`PEAK` 0.5, the motion check in :func:`unblended_sides`, a
#: crossing's dips at both ends and inside the clip) were added after it harmed three of them (a time warp, a frozen
#: transition and a pose from another body passing the hips through each other: 1.18 -> 1.42, 6.33 -> 6.80, 0.93 -> 1.54
#: cm; bench time_warp 28.2 -> 24.9 % in its first version), so ``bench flaws`` does not test it blind.
BLENDS = True
SWAPS = {"swapped_legs": (("hip",), True, 0.86, None), "relabelled_legs": (("hip",), False, 0.5, 0.0),
         "relabelled_arms": (("collar", "shoulder"), False, 0.5, 0.0)}


def limb_pair(skeleton, joint: str = "hip") -> tuple[np.ndarray, np.ndarray] | None:
    """Joint indices ``(left (K,), right (K,))`` of the limbs rooted at ``left_<joint>`` and ``right_<joint>``
    (the joint and its descendants, in matching order); None where the skeleton has no such joints."""
    skel = get_skeleton(skeleton)
    if f"left_{joint}" not in skel.joint_names or f"right_{joint}" not in skel.joint_names:
        return None
    left = limb_joints(skel, skel.index(f"left_{joint}"))
    return left, mirror_pairs(skel)[left]


def sides_swapped(x: np.ndarray, left: np.ndarray, right: np.ndarray, mirrored: bool = True) -> np.ndarray:
    """``x (..., T, J, 3)`` metres with the ``left`` and ``right`` limbs (``(K,)`` joint indices, roots first) swapped:
    ``mirrored``, each reflected across the plane through the midpoint of the two roots, normal to the line joining
    them; else the two sides' joints trade places as they are."""
    x = np.asarray(x, np.float64)
    out = x.copy()
    if not mirrored:
        out[..., left, :], out[..., right, :] = x[..., right, :], x[..., left, :]
        return out
    normal = x[..., right[0], :] - x[..., left[0], :]  # (..., T, 3)
    normal /= np.maximum(np.sqrt(np.einsum("...c,...c->...", normal, normal)), 1e-9)[..., None]
    middle = 0.5 * (x[..., right[0], :] + x[..., left[0], :])[..., None, :]
    rel = x[..., np.r_[right, left], :] - middle  # the sources of the left, then the right joints
    out[..., np.r_[left, right], :] = middle + rel - 2 * np.einsum("...jc,...c->...j", rel, normal)[..., None] * normal[..., None, :]
    return out


def swapped_window(x: np.ndarray, left: np.ndarray, right: np.ndarray, lo: int = 0, hi: int | None = None,
                   min_frames: int = MIN_FRAMES, mirrored: bool = True) -> tuple:
    """The window ``[a, b)`` within ``[lo, hi)`` whose sides swapped back (:func:`sides_swapped`) take the most off the
    pair's motion.

    The pair's motion is the sum of its joints' squared steps from frame ``a - 1`` to ``b``, relative to the midpoint
    of their roots (the body's own motion is no clue). For one clip ``x (T, J, 3)`` metres, returns ``(ratio, a, b)``
    for the window where swapping back lowers it most, ``ratio`` being that sum after the swap over the sum before
    (under 1: the limbs move less); ``(inf, -1, -1)`` where no window fits. For a batch ``(B, T, J, 3)``, three
    ``(B,)`` arrays. Both ends lie inside the clip (``1 <= a``, ``b <= T - 1``): a window needs a frame on each side to
    be told from a clip that is simply mirrored.
    """
    x = np.asarray(x)
    if x.ndim not in (3, 4) or x.shape[-1] != 3:
        raise ValueError(f"`x` must be (T, J, 3) or (B, T, J, 3); got shape {x.shape}.")
    batch = x if x.ndim == 4 else x[None]
    n_clips, n = batch.shape[:2]
    ratio, start, stop = np.full(n_clips, np.inf), np.full(n_clips, -1), np.full(n_clips, -1)
    first, last = max(lo, 1), min(n if hi is None else hi, n - 1)  # a window's first frame, its end
    if last - first >= min_frames:
        k = len(left)
        pair = batch[:, :, np.r_[left, right]].astype(np.float64)  # (B, T, 2K, 3): the pair alone
        middle = 0.5 * (pair[:, :, :1] + pair[:, :, k : k + 1])  # the swap keeps it
        given, swapped = pair - middle, sides_swapped(pair, np.arange(k), np.arange(k, 2 * k), mirrored) - middle

        def squared(d):  # (B, T - 1, 2K, 3) -> (B, T - 1)
            return np.einsum("btjc,btjc->bt", d, d)

        step_given = squared(np.diff(given, axis=1))  # (B, T - 1): step t -> t + 1
        step_swapped = squared(np.diff(swapped, axis=1)) if mirrored else step_given  # relabelled: the same steps
        into = squared(swapped[:, 1:] - given[:, :-1])  # the step into a window starting at t + 1
        out_of = squared(given[:, 1:] - swapped[:, :-1])  # the step out of a window ending at t
        zero = np.zeros((n_clips, 1))
        cum_given, cum_swapped = np.hstack([zero, np.cumsum(step_given, 1)]), np.hstack([zero, np.cumsum(step_swapped, 1)])
        # the gain of window [a, b) is a part of its start plus a part of its end, so the best start for each end is the
        # best so far among the starts at least min_frames before it: one pass, whatever the clip's length
        a = np.arange(first, last - min_frames + 1)
        b = a + min_frames
        head = cum_swapped[:, a] - cum_given[:, a - 1] - into[:, a - 1]  # (B, starts)
        tail = cum_given[:, b] - cum_swapped[:, b - 1] - out_of[:, b - 1]  # (B, ends)
        best_head = np.maximum.accumulate(head, axis=1)
        rising = head > np.hstack([np.full((n_clips, 1), -np.inf), best_head[:, :-1]])
        best_start = np.maximum.accumulate(np.where(rising, np.arange(len(a)), 0), axis=1)
        j = np.argmax(best_head + tail, axis=1)
        start, stop = a[best_start[np.arange(n_clips), j]], b[j]
        rows = np.arange(n_clips)
        before = cum_given[rows, stop] - cum_given[rows, start - 1]
        after = into[rows, start - 1] + cum_swapped[rows, stop - 1] - cum_swapped[rows, start] + out_of[rows, stop - 1]
        ratio = after / np.maximum(before, 1e-12)
    if x.ndim == 4:
        return ratio, start, stop
    return float(ratio[0]), int(start[0]), int(stop[0])


def body_right(x: np.ndarray, skeleton) -> np.ndarray | None:
    """``(T, 3)`` unit vectors toward the body's right in each frame of ``x (T, J, 3)``, from the feet (both point
    forward, whichever side each is labelled: toe or foot ahead of the ankle, the ankle ahead of the heel) and the up
    axis; None where the skeleton has no such joints."""
    skel = get_skeleton(skeleton)
    names = skel.joint_names
    forward = np.zeros((len(x), 3))
    for side in ("left", "right"):
        ankle = f"{side}_ankle"
        tip = next((f"{side}_{w}" for w in ("foot", "toe") if f"{side}_{w}" in names), None)
        heel = f"{side}_heel" if f"{side}_heel" in names else None
        if ankle not in names or (tip is None and heel is None):
            return None
        front, back = (tip, ankle) if tip is not None else (ankle, heel)
        forward += x[:, skel.index(front)] - x[:, skel.index(back)]
    up = np.asarray(skel.up_vector, np.float64)
    right = np.cross(forward - (forward @ up)[:, None] * up, up)
    return right / np.maximum(np.linalg.norm(right, axis=-1, keepdims=True), 1e-9)


def blend_weights(x: np.ndarray, left: np.ndarray, right: np.ndarray, skeleton) -> np.ndarray | None:
    """``(T,)`` weights ``w`` with which each frame of ``x (T, J, 3)`` shows the pair's sides blended,
    ``left' = (1 - w) left + w right`` and the other way (a relabelling, ramped in or partial: the training flaw
    ``mirror``); None where the pair's roots keep no steady distance (:data:`STEADY`), never leave it, or the body's right
    cannot be read (:func:`body_right`). The roots' distance shrinks to ``|1 - 2w|`` of the steady one; past ``w = 0.5``
    the pair points to the body's left."""
    x = np.asarray(x, np.float64)
    axis = x[:, right[0]] - x[:, left[0]]
    dist = np.linalg.norm(axis, axis=-1)
    steady = float(np.quantile(dist, 0.9))
    facing = body_right(x, skeleton)
    if facing is None or steady <= 0 or np.mean(np.abs(dist - steady) <= STEADY * steady) < STEADY_SHARE:
        return None
    share = np.clip(dist / steady, 0.0, 1.0)
    # the pair's direction followed from frame to frame (a turn of over 90 degrees in one step is a crossing; frames
    # where the roots nearly meet have none), then the whole sequence read against the feet's right: a foot turned
    # inward in a few frames of a clean clip reads as crossed, the sequence does not
    seen = np.flatnonzero(share >= 0.05)
    unit = axis[seen] / dist[seen, None]
    state = np.r_[0, np.cumsum((unit[1:] * unit[:-1]).sum(-1) < 0)] % 2 == 1
    crossed = state[np.clip(np.searchsorted(seen, np.arange(len(x)), side="right") - 1, 0, None)] if seen.size else \
        np.zeros(len(x), bool)
    wrong = (axis * facing).sum(-1) < 0
    if crossed.all() or not crossed.any():  # a clip crossed throughout is a mirrored clip: no flaw to tell
        crossed[:] = False
    elif np.mean(crossed[seen] == wrong[seen]) < 0.5:
        crossed = ~crossed
    # a blend passes the roots through each other at both its ends (a dip in their distance); a crossing without one
    # is a whole swap, mirrored or relabelled, which the swaps of SWAPS tell apart by the motion they leave, or a flip in
    # the recording that re-sampling (a time warp) smoothed at one end: swapped as a blend, two held-out clips went from
    # 1.2 to 14 cm
    edges = np.flatnonzero(np.diff(np.r_[False, crossed, False].astype(int)))
    for a, b in zip(edges[::2], edges[1::2]):
        if a == 0 or b == len(x) or max(share[max(t - 3, 0) : t + 3].min() for t in (a, b)) > 0.9:
            crossed[a:b] = False  # and one reaching the clip's edge has no side to be told by
    w = np.where(crossed, (1 + share) / 2, (1 - share) / 2)
    w[w < SLIGHT] = 0.0  # noise, or another body's pose blended in, moves the roots a little too
    return w if w.max() >= PEAK else None


def unblended(x: np.ndarray, left: np.ndarray, right: np.ndarray, skeleton) -> tuple[np.ndarray, np.ndarray]:
    """``x (T, J, 3)`` metres with the pair's blend (:func:`blend_weights`) undone, relative to the root: ``left = ((1 -
    w) left' - w right') / (1 - 2w)``, and the frames near ``w = 0.5`` in-filled linearly from the nearest frames undone;
    returns it and the frames changed ``(T,)`` bool (none where no blend is found)."""
    x = np.asarray(x, np.float64)
    w = blend_weights(x, left, right, skeleton)
    if w is None:
        return x.copy(), np.zeros(len(x), bool)
    root = get_skeleton(skeleton).root
    rel = x - x[:, [root]]
    out = rel.copy()
    k = (1 - 2 * w)[:, None, None]
    sure = np.abs(k[:, 0, 0]) >= DEGENERATE
    out[:, left] = np.where(sure[:, None, None], ((1 - w)[:, None, None] * rel[:, left] - w[:, None, None] * rel[:, right])
                            / np.where(sure, k[:, 0, 0], 1.0)[:, None, None], rel[:, left])
    out[:, right] = np.where(sure[:, None, None], ((1 - w)[:, None, None] * rel[:, right] - w[:, None, None] * rel[:, left])
                             / np.where(sure, k[:, 0, 0], 1.0)[:, None, None], rel[:, right])
    unsure = ~sure
    if unsure.any() and sure.any():
        frames, kept = np.arange(len(x)), np.flatnonzero(sure)
        pair = np.r_[left, right]
        flat = out[:, pair].reshape(len(x), -1)
        flat[unsure] = np.stack([np.interp(frames[unsure], kept, flat[kept, c]) for c in range(flat.shape[1])], 1)
        out[:, pair] = flat.reshape(len(x), len(pair), 3)
    return out + x[:, [root]], w > 0


def _crossing(clips: np.ndarray, pair) -> np.ndarray:
    """Indices of ``clips (B, T, J, 3)`` where the pair's roots turn by over 90 degrees in a step or nearly meet: the
    only clips where a blend can reach :data:`PEAK` (a cheap look at the whole batch before :func:`blend_weights`)."""
    axis = np.asarray(clips[:, :, pair[1][0]] - clips[:, :, pair[0][0]], np.float64)  # (B, T, 3)
    dist = np.sqrt((axis * axis).sum(-1))
    turned = ((axis[:, 1:] * axis[:, :-1]).sum(-1) < 0).any(1)
    met = (dist < 0.05 * dist.max(1, keepdims=True)).any(1)
    return np.flatnonzero(turned | met)


def _motion(x, pair, lo, hi) -> float:
    """The pair's squared joint steps from frame ``lo - 1`` to ``hi``, relative to the midpoint of its roots."""
    x = np.asarray(x, np.float64)[max(lo - 1, 0) : hi + 1]
    left, right = pair
    rel = x[:, np.r_[left, right]] - 0.5 * (x[:, left[0]] + x[:, right[0]])[:, None]
    return float((np.diff(rel, axis=0) ** 2).sum())


def unblended_sides(refiner, clips: np.ndarray, reports: list, mode: str) -> np.ndarray:
    """The refiner's first step (where :data:`BLENDS` is on, the default): in each of ``clips (B, T, J, 3)`` metres as given, the legs' and then the arms' sides
    unblended (:func:`unblended`) where a relabelling was blended in and undoing it makes the pair move less, put on the
    clip's bone lengths; each change in its
    clip's report. First, because the rigid-skeleton step rebuilds the frames where the hips cross (their bones shorten)
    and the blend can no longer be read. Not verified by the flaw classifier: it read the blended clips, as given, as
    flawed as the undone ones (it judges rigid clips), and no clean clip of HumanAct12 (1,191) or CMU (1,088) shows a
    blend (:func:`blend_weights`). A transition step: not in ``mode="anchor"``."""
    if mode == "anchor" or not BLENDS:
        return clips
    out = clips
    for limbs, roots in (("legs", ("hip",)), ("arms", ("collar", "shoulder"))):
        pair = next((p for p in (limb_pair(refiner.skeleton, r) for r in roots) if p is not None), None)
        for b in _crossing(out, pair) if pair is not None else ():
            y, frames = unblended(out[b], *pair, refiner.skeleton)
            if not frames.any():
                continue
            lo, hi = int(np.argmax(frames)), int(len(frames) - np.argmax(frames[::-1]))
            if _motion(y, pair, lo, hi) >= _motion(out[b], pair, lo, hi):
                continue  # undone, the limbs would move no less: a pose blended in, not the other side
            if out is clips:
                out = clips.copy()
            out[b] = project_bone_lengths(y, reference_lengths(np.asarray(out[b], np.float64), refiner.skeleton), frames,
                                          refiner.skeleton).astype(clips.dtype)
            reports[b].changes.append({"start": lo, "stop": hi, "step": "transition", "repair": f"unblended_{limbs}",
                                       "reason": f"the {limbs}' roots came closer than their steady distance, or crossed: "
                                       f"their sides blended (a left/right relabelling) up to weight "
                                       f"{float(blend_weights(clips[b], *pair, refiner.skeleton).max()):.2f}, undone"})
    return out


def unswapped(refiner, clips: np.ndarray, reports: list, mode: str, select) -> np.ndarray:
    """The refiner's left/right step: for each swap of :data:`SWAPS` in turn, in each of ``clips (B, T, J, 3)`` metres,
    the limbs swapped back over the window :func:`swapped_window` finds where that leaves them at most the swap's ratio
    of their motion, put on the clip's bone lengths (each limb takes the other's pose, not its lengths), and kept where
    ``select`` (the learned pipeline's choice by the flaw classifier, ``select(refiner, clip, {name: candidate}, start,
    stop, penalty=) -> (name or "keep", note)``) finds it more real than the given frames at the swap's price; each change in its clip's report. A
    transition step: not in ``mode="anchor"``; nothing without a flaw classifier to verify it."""
    if mode == "anchor" or getattr(refiner, "flaw_classifier", None) is None:
        return clips
    out = clips
    for name, (roots, mirrored, max_ratio, penalty) in SWAPS.items():
        pair = next((p for p in (limb_pair(refiner.skeleton, r) for r in roots) if p is not None), None)
        if pair is None:
            continue
        ratios, starts, stops = swapped_window(out, *pair, min_frames=MIN_FRAMES, mirrored=mirrored)
        for b in np.flatnonzero(ratios < max_ratio):
            report, ratio, lo, hi = reports[b], float(ratios[b]), int(starts[b]), int(stops[b])
            x = np.asarray(out[b], np.float64)
            y = x.copy()
            y[lo:hi] = sides_swapped(x[lo:hi], *pair, mirrored)
            frames = np.zeros(len(x), bool)
            frames[lo:hi] = True
            # no splice: the window's ends are the jumps the swap removes, and blending across them would cross the limbs
            y = project_bone_lengths(y, reference_lengths(x, refiner.skeleton), frames, refiner.skeleton).astype(clips.dtype)
            chosen, note = select(refiner, out[b], {name: y}, lo, hi, penalty=penalty)
            limbs = name.split("_")[1]
            if chosen == "keep":
                report.notes.append(f"frames {lo}-{hi - 1}: the {limbs} swapped back ({'mirrored' if mirrored else 'as they are'})"
                                    f" would move {ratio:.2f} times as much; {note}")
                continue
            if out is clips:
                out = clips.copy()
            out[b] = y
            report.changes.append({"start": lo, "stop": hi, "step": "transition", "repair": name, "reason":
                                   f"each of the {limbs} showed the other's motion: swapped back to their sides, they move "
                                   f"{ratio:.2f} times as much (under {max_ratio}){note}"})
    return out
