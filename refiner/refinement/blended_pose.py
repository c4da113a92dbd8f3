"""Blended poses undone: a wrong key pose blended into mocap, read from the rigid bones' lengths and taken out.

A pose blended toward another over a window (the benchmark's ``wrong_anchor``: ``x'(t) = x(t) + w(t) Δ``, ``Δ`` a
constant offset of every joint from the root, ``w`` a weight that rises from 0 and falls back) leaves a mocap clip's
bones exact outside the window (its exact core: the frames whose bones match the first frame's, as the last frame's
must) and shortens and stretches them inside it. Every bone ``j`` then reads ``b'_j(t) = b_j(t) + w(t) δ_j`` (``δ_j``
the difference of its two joints' offsets), while the true bone ``b_j(t)`` keeps the core's length ``L_j``:

    ``|b'_j(t) - w(t) δ_j| = L_j``  for every frame of the window and every bone.

One unknown weight per frame and three per bone against one equation per bone and frame (23 per frame on HumanAct12):
the blend is over-determined, and where the equations are met to a hundredth of a millimetre (mocap's bones are exact
to 1e-5) it is the blend, which is then taken out exactly: ``x = x' - w(t) Δ``. The rigid-skeleton step can only put
such frames back on their lengths, moving each joint along the arc, away from both poses (the benchmark's wrong
anchors: 0.9 % of the added error removed); a pose prior or an in-fill cannot tell a blend of two real poses from a
pose a body holds. The weight's profile is free (any ramp, a plateau; two limbs or the whole body: one limb alone is
left to the rigid step, :func:`one_chain`); a window that reaches the clip's first or last frame is left (drift to
the clip's end fits such a profile and is not a blend). ``motion-refiner bench flaws --severity 2``: wrong_anchor
0.9 -> 96.5 % of the added error removed, every other family and the clean clips unchanged (README).

Re-timed frames (interpolated between two frames of the clip) shorten bones too, and on short windows a free profile
nearly fits them: :data:`FIT_SHARE` keeps those out (calibration subjects 9-10, every 2nd clip, severity 2: the
wrong anchors' fits leave at most 0.0015 of the largest deviation, median 0.0001; the re-timing families' at least
0.0013, median 0.02-0.05; jitter's and drift's fail by far). Not the root: a blend that moves the root changes no
bone, so the root path is kept as given.
"""
from __future__ import annotations

import numpy as np

from refiner.core.rigid import EXACT_TOLERANCE, bending_bones
from refiner.core.skeletons import bone_lengths, get_skeleton

__all__ = ["blend_windows", "exact_bones", "one_chain", "fit_blend", "unblended_pose", "unblended_poses", "blend_change", "UNBLEND",
           "STARTS", "FIT_RMS", "FIT_SHARE", "MIN_FRAMES",
           "MIN_EXACT_BONES", "VARYING_SHARE"]

#: The step on (the default) or off (the release before).
UNBLEND = True

#: Metres: the fit's root-mean-square bone-length error must stay under this ...
FIT_RMS = 5e-5
#: ... and under this share of the window's largest bone deviation (see the module docstring).
FIT_SHARE = 1e-3
#: A window of fewer frames off the core is not looked at: too few equations for the unknowns (the frozen transitions'
#: rushes, 3-5 frames off, were fitted exactly; the calibration wrong anchors have 8 or more).
MIN_FRAMES = 8
#: Off-core frames this close together form one window (a bone's deviation may pass zero for a frame).
MERGE = 2
#: A window whose mean bone deviation changes more roughly than this (its second difference in time, against its
#: mean) is not fitted: frames re-timed between two frames of the clip shorten bones most half-way between them and
#: not at all on them (calibration subjects, severity 2: the re-timing families 0.73-4.3, wrong anchors 0.01-0.41).
#: It saves the fits (up to eight starts each) that the gates would refuse.
ROUGH = 0.6
#: A window whose first or last off frame deviates by more than this share of its largest deviation is not fitted: a
#: blend ramps in and out, while limbs swapped in whole over a window (a step with the same foot twice, a left/right
#: relabelling) trade their lengths at once, which a blend with a box-shaped weight meets too; fitted, they moved the
#: legs by under a centimetre and hid the swap from the left/right step (held-out subjects, ``same_foot_abrupt`` of
#: ``examples/measure_body_recipes.py``: 70.1 -> 60.1 %). Subjects 1-4, every 3rd clip: such swaps 1.0, the benchmark's
#: wrong anchors at most 0.18 / 0.33 / 0.12 at severity 1 / 2 / 3.
ABRUPT = 0.5
#: A fit whose first start leaves more than this share of the largest deviation tries no other (noise: its windows
#: keep 0.3-0.6 of it; wrong anchors' first starts, where they fail, 0.003-0.02; re-timings' up to 0.08).
HOPELESS = 0.1
#: The weight (under 1) of a bending chain's length equation against a rigid bone's (:func:`unblended_pose`'s
#: ``bones``). UESTC's 18 joints (calibration subjects' wrong anchors converted there): 0.01 / 0.03 / 0.1 / 0.3 / 0.6
#: remove 59.0 / 58.8 / 57.7 / 25.5 / 3.0 %: the neck, shoulders and nose hang on bending chains only, so their shift
#: is read from those chains' ends, roughly, and higher weights make the fits miss the gates.
BENDING_WEIGHT = 0.03
#: A clip is looked at with at least this many exact bones (:func:`exact_bones`; fewer cannot tell a blend from a
#: limb's change).
MIN_EXACT_BONES = 6
#: A bone off its first frame's length in at least this share of a clip's frames may vary by nature and be back on it
#: in the last frame by chance (CMU: 85 of 1,088 clean clips hold a hand, a toe or the spine so, and a blend window
#: then spans the clip): where the fit with it finds no blend, it is tried again without such bones. Not the first
#: try: a wrong anchor's window may span all but the clip's first and last frames.
VARYING_SHARE = 0.9
#: Iterations per start, at most (a fit stops when its error stops falling).
ITERATIONS = 100
#: The fit's starts, in turn: a weight profile (a tent peaking at the largest mean bone deviation, that deviation, a
#: flat 0.5, the deviation squared) and the bone offsets (zero, or what explains the deviations to first order). The
#: fit has local minima: calibration subjects 9-10 (every 2nd clip, severity 2), wrong anchors fitted within the gates
#: from the first start alone 79 of 84, the first three 80, the first four 81, all 83 (the re-timing families none);
#: Levenberg-Marquardt takes 5-15 ms a clip, L-BFGS (torch) from three starts 0.7 s and fitted 79 (these counts with the
#: rigid step's loosest core for the lengths; with the exact core, all starts: 84 of 85).
STARTS = (("tent", "zero"), ("deviation", "zero"), ("flat", "zero"), ("squared", "zero"), ("deviation", "first_order"),
          ("squared", "first_order"), ("flat", "first_order"), ("tent", "first_order"))


def exact_bones(off: np.ndarray) -> np.ndarray:
    """``off (..., T, B)`` bool (each bone's length off its first frame's by more than :data:`EXACT_TOLERANCE`) ->
    ``(..., B)`` bool: the bones a clip holds exact, back on their first frame's length in its last frame, as a blend
    inside the clip leaves them. CMU's processed clips hold 13 of their 19 bones exact in every frame of all 1,088
    clips (1,081 exactly those 13), while the spine's two, the hands' and the toes' vary in nearly every frame: a
    blend is read from those 13 but the two the layout bends (spine -> shoulders, :data:`~refiner.core.rigid.FLEXIBLE_BONES`), 11.
    Not a share of the clip's frames: a wrong anchor's window may span all but the clip's first and last frames."""
    return ~off[..., -1, :]


def one_chain(skeleton, bones: np.ndarray) -> bool:
    """Whether the ``bones (J - 1,)`` bool (in :attr:`~refiner.core.skeletons.Skeleton.bones` order) form one chain
    without branches (a limb, or part of one). A window where only such bones leave the core is left to the rigid step,
    which rebuilds them along their own directions: a blend that moves one limb and that limb stretched or shrunk meet
    the lengths alike (both exactly where the limb hardly turns), and stretching bones is a flaw we know. With such
    windows fitted, ``examples/measure_bone_recipes.py`` (one limb stretched or shrunk 10 %, subjects 11-12) fell from
    99.7-100 % to 90.0-92.3 % removed; with every window of at most 6 bones off left (the rigid step's
    :data:`~refiner.core.rigid.REBUILD_BONES`), both legs blended toward another pose came out 34.6 % worse."""
    pairs = get_skeleton(skeleton).bones[np.asarray(bones, bool)]
    if not len(pairs):
        return True
    starts = np.isin(pairs[:, 0], pairs[:, 1], invert=True).sum()  # bones whose parent bone is not among them
    return starts == 1 and len(np.unique(pairs[:, 0])) == len(pairs)  # one start, no joint with two of them


def blend_windows(off: np.ndarray) -> list[tuple[int, int]]:
    """``off (T,)`` bool (frames off the rigid core) -> ``[(lo, hi)]``: runs of off frames, those under :data:`MERGE`
    frames apart merged, each padded by one core frame either side; runs that reach the clip's first or last frame
    and runs of fewer than :data:`MIN_FRAMES` frames left out."""
    idx = np.flatnonzero(off)
    if not idx.size:
        return []
    cuts = np.flatnonzero(np.diff(idx) > MERGE)
    starts, stops = idx[np.r_[0, cuts + 1]], idx[np.r_[cuts, idx.size - 1]] + 1
    return [(int(a) - 1, int(b) + 1) for a, b in zip(starts, stops)
            if a > 0 and b < len(off) and off[a:b].sum() >= MIN_FRAMES]


def _levenberg_marquardt(bones: np.ndarray, lengths: np.ndarray, weights: np.ndarray, w: np.ndarray, delta: np.ndarray,
                         iterations: int) -> tuple[np.ndarray, np.ndarray, float]:
    """One start of :func:`fit_blend`: Levenberg-Marquardt over the weights ``w (n,)`` and the bone offsets ``delta
    (B, 3)``, the weights eliminated from the normal equations (their block is diagonal: a weight touches one frame)."""
    n, n_bones = bones.shape[:2]

    def residuals(w, delta):
        v = bones - w[:, None, None] * delta
        norm = np.linalg.norm(v, axis=-1)
        return v, norm, (norm - lengths) * weights

    v, norm, r = residuals(w, delta)
    cost, damping = float((r ** 2).sum()), 1e-2
    for step in range(iterations):
        u = v / np.maximum(norm[..., None], 1e-12)
        dw = -(u * delta).sum(-1) * weights  # (n, B): d r / d w
        dd = -w[:, None, None] * u * weights[:, None]  # (n, B, 3): d r / d delta
        h_ww, h_dd = (dw ** 2).sum(1), np.einsum("tji,tjk->jik", dd, dd)
        h_wd = (dw[..., None] * dd).reshape(n, -1)
        g_w, g_d = (dw * r).sum(1), (dd * r[..., None]).sum(0).ravel()
        improved = False
        while damping < 1e10 and not improved:
            ww = h_ww * (1 + damping) + 1e-12
            blocks = h_dd + (damping * np.einsum("jii->ji", h_dd)[..., None] + 1e-12) * np.eye(3)
            schur = -h_wd.T @ (h_wd / ww[:, None])
            for j in range(n_bones):
                schur[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] += blocks[j]
            step_d = np.linalg.lstsq(schur, h_wd.T @ (g_w / ww) - g_d, rcond=None)[0]
            step_w = (-g_w - h_wd @ step_d) / ww
            v1, norm1, r1 = residuals(w + step_w, delta + step_d.reshape(n_bones, 3))
            if (cost1 := float((r1 ** 2).sum())) < cost:
                improved, stalled = True, cost - cost1 < 1e-4 * cost
                w, delta, v, norm, r, cost = w + step_w, delta + step_d.reshape(n_bones, 3), v1, norm1, r1, cost1
                damping = max(damping / 3, 1e-9)
            else:
                damping *= 4
        if not improved or (step >= 10 and stalled):
            break
    return w, delta, float(np.sqrt((r[:, weights == 1.0] ** 2).mean()))  # the rigid bones' (weight 1)


def _first_order(bones: np.ndarray, lengths: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``(B, 3)``: each bone's offset that explains its length change to first order, ``|b'| - L = -w (b'/|b'|) . δ``."""
    norm = np.linalg.norm(bones, axis=-1)
    along = -w[:, None, None] * bones / np.maximum(norm[..., None], 1e-12)
    change = norm - lengths
    return np.stack([np.linalg.lstsq(along[:, k], change[:, k], rcond=None)[0] for k in range(bones.shape[1])])


def fit_blend(bones: np.ndarray, lengths: np.ndarray, *, bending: np.ndarray | None = None,
              iterations: int = ITERATIONS) -> tuple[np.ndarray, np.ndarray, float]:
    """``bones (n, B, 3)`` metres (a window's bone vectors), ``lengths (B,)`` or ``(n, B)`` metres (their true
    lengths) -> ``(w (n,), delta (B, 3) metres, rms metres)``: the blend weights (largest 1 in size) and bone offsets
    that best restore the lengths, by Levenberg-Marquardt from the :data:`STARTS` in turn until one passes the gates
    well, and the bone lengths' root-mean-square error left. ``bending (B,)`` bool: bones whose length real motion
    changes (a layout's bending chains), weighed by :data:`BENDING_WEIGHT` and left out of the error."""
    b = np.asarray(bones, np.float64)
    target = np.broadcast_to(np.asarray(lengths, np.float64), b.shape[:2])
    weights = np.where(np.zeros(b.shape[1], bool) if bending is None else bending, BENDING_WEIGHT, 1.0)
    size = np.abs(np.linalg.norm(b, axis=-1) - target)[:, weights == 1]
    dev, enough = size.mean(-1), 0.5 * min(FIT_RMS, FIT_SHARE * float(size.max()))
    n, t = len(dev), np.arange(len(dev))
    peak = int(np.argmax(dev))
    profiles = {"tent": np.minimum(t / max(peak, 1), (n - 1 - t) / max(n - 1 - peak, 1)).clip(0, 1),
                "deviation": dev / max(dev.max(), 1e-12), "flat": np.full(n, 0.5)}
    profiles["squared"] = profiles["deviation"] ** 2
    best = None
    for profile, offsets in STARTS:
        w = profiles[profile].copy()
        start = np.zeros((b.shape[1], 3)) if offsets == "zero" else _first_order(b, target, w)
        w, d, rms = _levenberg_marquardt(b, target, weights, w, start, iterations)
        if best is None or rms < best[2]:
            best = (w, d, rms)
        if rms <= enough or rms > HOPELESS * float(size.max()):
            break
    w, d, rms = best
    scale = float(w[np.argmax(np.abs(w))]) or 1.0
    return w / scale, d * scale, rms


def unblended_pose(joints: np.ndarray, skeleton, bones: np.ndarray | None = None) -> tuple[np.ndarray, list[dict]]:
    """``joints (T, J, 3)`` metres -> ``(joints, blends)``: every window off the clip's exact rigid core where a blend
    (module docstring) restores the core's bone lengths within :data:`FIT_RMS` and :data:`FIT_SHARE` taken out, the
    root left as given; ``blends``: ``{"start", "stop", "weight_peak" (frame), "move_cm", "rms_mm"}`` per window
    taken out. A clip without an exact core (a generator's) is returned as given. ``bones (J - 1,)`` bool: the rigid
    bones (default all); the others (a layout's bending chains, such as UESTC's neck -> shoulder) are held to the
    lengths they have at the window's two ends, interpolated, at :data:`BENDING_WEIGHT`."""
    x = np.asarray(joints, np.float64)
    skel = get_skeleton(skeleton)
    pairs = skel.bones
    rigid = np.ones(len(pairs), bool) if bones is None else np.asarray(bones, bool)
    lengths = bone_lengths(x, skel)
    off_first = (np.abs(lengths - lengths[0]) / np.maximum(lengths[0], 1e-9) > EXACT_TOLERANCE)[:, rigid].any(-1)
    if off_first[-1] or not off_first.any():  # a blend inside the clip leaves its first and last frames on the core
        return joints, []
    true = np.median(lengths[~off_first], 0)  # the exact core: the frames whose bones are the first frame's
    off = (np.abs(lengths - true) / np.maximum(true, 1e-9) > EXACT_TOLERANCE)[:, rigid].any(-1)
    out, blends = x.copy(), []
    for lo, hi in blend_windows(off):
        if one_chain(skel, (np.abs(lengths[lo:hi] - true) / np.maximum(true, 1e-9) > EXACT_TOLERANCE).any(0) & rigid):
            continue  # one limb's bones alone: stretched or shrunk, which the rigid step rebuilds along them
        profile = np.abs(lengths[lo:hi] - true)[:, rigid].mean(-1)
        if np.abs(np.diff(profile, 2)).mean() > ROUGH * profile.mean():
            continue  # frames re-timed between two of the clip's: no fit needed
        if max(profile[1], profile[-2]) > ABRUPT * profile.max():
            continue  # no ramp: limbs swapped in whole (their lengths traded), the left/right step's
        vec = x[lo:hi, pairs[:, 1]] - x[lo:hi, pairs[:, 0]]
        target = np.where(rigid, true, np.linspace(lengths[lo], lengths[hi - 1], hi - lo))
        w, delta, rms = fit_blend(vec, target, bending=~rigid)
        if rms > FIT_RMS or rms > FIT_SHARE * float(np.abs(lengths[lo:hi] - true)[:, rigid].max()):
            continue
        offset = np.zeros_like(x[0])
        for (parent, child), d in zip(pairs, delta):  # parents come first in every registered skeleton
            offset[child] = offset[parent] + d
        out[lo:hi] -= w[:, None, None] * offset
        blends.append({"start": lo, "stop": hi, "weight_peak": lo + int(np.argmax(w)), "rms_mm": round(1e3 * rms, 4),
                       "move_cm": round(100 * float(np.linalg.norm(w[:, None, None] * offset, axis=-1).max()), 2)})
    return (out.astype(np.asarray(joints).dtype) if blends else joints), blends


def blend_change(blend: dict) -> dict:
    """A report's change entry for one ``blend`` of :func:`unblended_pose`."""
    return {"start": blend["start"], "stop": blend["stop"], "step": "anchor", "repair": "unblended_pose",
            "reason": f"bones off the clip's exact core, shortened and stretched as by a pose blended in (weight peak at "
                      f"frame {blend['weight_peak']}); the blend restores their lengths to {blend['rms_mm']} mm (root "
                      f"mean square) and was taken out, moving joints up to {blend['move_cm']} cm"}


def unblended_poses(refiner, clips: np.ndarray, reports: list, mode: str, skeleton: str | None = None) -> np.ndarray:
    """A step of the learned refiner, before the rigid-skeleton step (which would put the blended frames on their
    lengths and lose the evidence): each of ``clips (B, T, J, 3)`` metres (of ``skeleton``, by default the
    refiner's) with its blended poses taken out (:func:`unblended_pose`), each in its clip's report. An anchor step:
    not in ``mode="transition"``."""
    if mode == "transition" or not UNBLEND:
        return clips
    out, skeleton = clips, skeleton or refiner.skeleton
    lengths = bone_lengths(clips, skeleton)
    off = np.abs(lengths - lengths[:, :1]) > EXACT_TOLERANCE * np.maximum(lengths[:, :1], 1e-9)  # (B, T, bones)
    rigid = exact_bones(off) & ~bending_bones(skeleton)
    steady = rigid & (off.mean(1) < VARYING_SHARE)  # without bones back on their length by chance
    off_first = (off & rigid[:, None]).any(-1)  # the whole batch's first look, as unblended_pose's
    for b in np.flatnonzero(off_first.any(-1) & ~off_first[:, -1] & (rigid.sum(-1) >= MIN_EXACT_BONES)):
        y, blends = unblended_pose(clips[b], skeleton, rigid[b])
        if not blends and (steady[b] != rigid[b]).any() and steady[b].sum() >= MIN_EXACT_BONES:
            y, blends = unblended_pose(clips[b], skeleton, steady[b])
        if not blends:
            continue
        if out is clips:
            out = clips.copy()
        out[b] = y
        reports[b].changes.extend(blend_change(blend) for blend in blends)
    return out
