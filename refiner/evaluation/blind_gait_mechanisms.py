"""Blind gait and limb flaw mechanisms: a step taken with the same foot twice, stretching bones, a lagging limb.

Written from a description of what 3D human-motion generators (Action2Motion, ACTOR, MDM, MotionDiffuse, MLD) get
wrong, without looking at how any refiner detects it:

- ``same_foot_twice`` imitates a generator that loses the alternation of the legs: for a stretch the legs take
  each other's (side-mirrored) motion, so a step is taken with the same foot twice on entering and leaving it, or
  one leg copies the other's step so both feet step together;
- ``bone_stretch`` imitates a joint-position generator whose limbs stretch and shrink: bone lengths of one to
  four chains wobble slowly by a few per cent, joint directions kept;
- ``lagging_limb`` imitates one arm or leg running a few frames late relative to the rest of the body.

Each maps a clean HumanAct12 clip ``(T, 24, 3)`` (metres, y down, facing -z, 20 fps) to a new float32 copy that
differs from it only inside one random window (12-30 frames, clipped to the clip, never the first or last frame)
whose edges fade in and out smoothly; the input is never modified. Poses are edited as unit bone directions
(in the pelvis or chest frame of each frame) and rebuilt by forward kinematics on the clip's own bone lengths, so
``same_foot_twice`` and ``lagging_limb`` keep every frame's bone lengths exactly and move only the edited limbs.
"""
from __future__ import annotations

import numpy as np

from refiner.evaluation.blind_geometry import PARENTS as _PARENTS, bones as _bones, slerp as _slerp, unit as _unit
from refiner.evaluation.blind_ground_mechanisms import _fade

__all__ = ["MECHANISMS", "same_foot_twice", "bone_stretch", "lagging_limb"]

# joints whose incoming bones make each limb below its root joint (thigh, shin, foot; upper arm, forearm, hand)
_LEGS = {"left": (4, 7, 10), "right": (5, 8, 11)}
_ARMS = {"left": (18, 20, 22), "right": (19, 21, 23)}
# chains whose bones bone_stretch scales (arms from the collar bone's end, the spine up to the head)
_CHAINS = {"left_arm": (16, 18, 20, 22), "right_arm": (17, 19, 21, 23), "left_leg": (4, 7, 10),
           "right_leg": (5, 8, 11), "spine": (3, 6, 9, 12, 15)}
_PELVIS, _CHEST = ((1, 2), (0, 3)), ((16, 17), (9, 12))  # (lateral pair, up pair) of each torso frame
_MIRROR = np.array([-1.0, 1.0, 1.0])  # left-right reflection in a torso frame


def _frame(x: np.ndarray, pairs) -> np.ndarray:
    """Per-frame orthonormal torso frame ``(T, 3, 3)``, columns (left, up, forward), from ``x (T, 24, 3)``."""
    (a, b), (c, d) = pairs
    left = _unit(x[:, a] - x[:, b])
    fwd = _unit(np.cross(left, x[:, d] - x[:, c]))
    return np.stack([left, np.cross(fwd, left), fwd], axis=-1)


def _local(frame: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """World directions ``(T, J, 3)`` -> in ``frame`` ``(T, 3, 3)``."""
    return np.einsum("tji,tkj->tki", frame, dirs)


def _world(frame: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Directions ``(T, J, 3)`` in ``frame`` -> world."""
    return np.einsum("tij,tkj->tki", frame, local)


def _below(joints) -> list[int]:
    """``joints`` and every joint under any of them, parents first."""
    inside = set(joints)
    for j in range(len(_PARENTS)):
        if _PARENTS[j] in inside:
            inside.add(j)
    return sorted(inside)


def _place(seg: np.ndarray, dirs: np.ndarray, lengths: np.ndarray, joints) -> np.ndarray:
    """``seg`` with each of ``joints`` (parents first) rebuilt at its parent plus its length along ``dirs``."""
    out = seg.copy()
    for j in joints:
        out[:, j] = out[:, _PARENTS[j]] + lengths[:, j, None] * dirs[:, j]
    return out


def _window(n_frames: int, rng: np.random.Generator, energy: np.ndarray, lo: int = 12, hi: int = 30):
    """A window ``(start, length)`` of ``lo``-``hi`` frames (clipped to the clip) leaving the first and last frame,
    its start drawn with weight on the summed per-frame ``energy`` ``(T,)`` inside it."""
    hi = max(1, min(hi, n_frames - 2))
    length = int(rng.integers(min(lo, hi), hi + 1))
    starts = np.arange(1, n_frames - length)
    e = np.convolve(energy, np.ones(length), "valid")[starts]
    p = e + 0.1 * e.mean() + 1e-12  # quiet stretches stay possible, just rarer
    return int(rng.choice(starts, p=p / p.sum())), length


def same_foot_twice(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a generator stepping with the same foot twice: the legs' alternation is lost for a stretch.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside a 12-30 frame window. In the pelvis
    frame of each frame, the legs' bone directions (thigh, shin, foot) are blended toward the other leg's,
    mirrored left-right. Two forms: (a, 60 %) the legs swap - each does the other's mirrored motion, so in a walk
    the leg that just stepped steps again on entering the window and the other one on leaving it (elsewhere the
    limbs simply change sides: a kick with the wrong leg); (b, 40 %) one leg copies the other's mirrored motion
    from 0-3 frames earlier, the other leg unchanged, so both feet step (nearly) together. The window's start, and
    in (b) which leg copies, are drawn with weight on how much the legs differ, where the swap shows. The blend
    fades in and out over 25-40 % of the window each; ``severity`` scales it (capped at a full swap or copy).
    Bone lengths are kept exactly; hips, upper body and root are untouched.
    """
    x = np.array(clip, dtype=np.float64)
    n_frames = len(x)
    frame = _frame(x, _PELVIS)
    dirs, lengths = _bones(x)
    local = _local(frame, dirs)
    left, right = list(_LEGS["left"]), list(_LEGS["right"])
    target = local.copy()
    if rng.random() < 0.6:
        target[:, left], target[:, right] = local[:, right] * _MIRROR, local[:, left] * _MIRROR
        moved = left + right
    else:
        earlier = np.maximum(np.arange(n_frames) - int(rng.integers(0, 4)), 0)
        gaps = [(np.linalg.norm(local[earlier][:, src] * _MIRROR - local[:, dst], axis=-1) * lengths[:, dst]).sum()
                for src, dst in ((right, left), (left, right))]
        p = np.array(gaps) + 1e-12
        src, dst = ((right, left), (left, right))[int(rng.choice(2, p=p / p.sum()))]
        target[:, dst] = local[earlier][:, src] * _MIRROR
        moved = dst
    gap = (np.linalg.norm(target - local, axis=-1) * lengths).sum(1)  # (T,) metres, roughly
    start, length = _window(n_frames, rng, gap)
    sl = slice(start, start + length)
    w = min(1.0, max(0.0, severity)) * _fade(length, rng, 0.25, 0.4)
    new = local[sl].copy()
    new[:, moved] = _slerp(local[sl][:, moved], target[sl][:, moved], w[:, None])
    out = x.copy()
    out[sl] = _place(x[sl], _world(frame[sl], new), lengths[sl], moved)
    return out.astype(np.float32)


def bone_stretch(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates limbs that stretch and shrink, as a joint-position generator's do.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside a 12-30 frame window. One (20 %), two
    (30 %), three (30 %) or four of the five chains - an arm (collar end to hand), a leg (hip to toe), the spine
    (pelvis to head) - have every bone's length scaled by ``1 + a * s(t)``: ``s`` is a slow 0.4-1.2 Hz sine (random
    phase, each bone's shifted by up to 0.5 rad) faded in and out over 20-40 % of the window each and normalised to
    a peak of 1; ``a`` is a chain's 3-8 % (times ``severity``, random sign) times 0.7-1.1 per bone. Joint directions
    are kept and everything below a stretched bone moves with it (a stretched spine carries the head and arms); the
    root stays, so stretched legs push the feet into the floor or lift them off it. Bone lengths are NOT kept, by
    design.
    """
    x = np.array(clip, dtype=np.float64)
    start, length = _window(len(x), rng, np.ones(len(x)))
    sl = slice(start, start + length)
    dirs, lengths = _bones(x[sl])
    names = list(_CHAINS)
    chosen = rng.choice(len(names), size=int(rng.choice([1, 2, 3, 4], p=[0.2, 0.3, 0.3, 0.2])), replace=False)
    t = np.arange(length) / 20.0  # seconds at 20 fps
    fade = _fade(length, rng, 0.2, 0.4)
    scale = np.ones_like(lengths)
    for k in chosen:
        chain = _CHAINS[names[k]]
        amp = rng.uniform(0.03, 0.08) * severity * rng.choice([-1.0, 1.0])
        hz, phase = rng.uniform(0.4, 1.2), rng.uniform(0.0, 2.0 * np.pi)
        for j in chain:
            s = fade * np.sin(2.0 * np.pi * hz * t + phase + rng.uniform(-0.5, 0.5))
            scale[:, j] = 1.0 + amp * rng.uniform(0.7, 1.1) * s / max(np.abs(s).max(), 1e-9)
    stretched = [j for k in chosen for j in _CHAINS[names[k]]]
    out = x.copy()
    out[sl] = _place(x[sl], dirs, lengths * scale, _below(stretched))
    return out.astype(np.float32)


def lagging_limb(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates an arm or leg that runs late relative to the rest of the body.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside a 15-30 frame window. One limb (an
    arm from the shoulder or a leg from the hip, drawn with weight on how much it moves relative to the torso)
    takes, at frame ``t``, its bone directions relative to the chest (arms) or pelvis (legs) from the fractional
    earlier time ``t - delay(t)`` (slerp between neighbouring frames), placed in the torso frame of frame ``t``.
    ``delay`` is 3-7 frames (times ``severity``) on a plateau, ramping in and out smoothly (sin^2) over 30-50 % of
    the window each, capped so that the limb never plays backwards or freezes (its own playback speed stays within
    0.15-1.85 times normal; short windows thus get shorter delays). The window's start is drawn with weight on the
    limb's motion there. Bone lengths are kept exactly; the rest of the body is untouched.
    """
    x = np.array(clip, dtype=np.float64)
    n_frames = len(x)
    dirs, lengths = _bones(x)
    limbs = [(pairs, list(j)) for pairs, side in ((_CHEST, _ARMS), (_PELVIS, _LEGS)) for j in side.values()]
    motion = []
    for pairs, joints in limbs:
        rel = _local(_frame(x, pairs), dirs[:, joints]) * lengths[:, joints, None]
        motion.append(np.append(np.linalg.norm(np.diff(rel, axis=0), axis=-1).sum(1), 0.0))  # (T,) metres a frame
    act = np.array([m.sum() for m in motion]) + 1e-12
    k = int(rng.choice(len(limbs), p=act / act.sum()))
    pairs, joints = limbs[k]
    start, length = _window(n_frames, rng, motion[k], lo=15)
    sl = slice(start, start + length)
    fade = _fade(length, rng, 0.3, 0.5)
    slope = np.abs(np.diff(np.concatenate([[0.0], fade, [0.0]]))).max()
    delay = min(rng.uniform(3.0, 7.0) * max(0.0, severity), 0.85 / slope) * fade
    tau = np.clip(np.arange(start, start + length) - delay, 0.0, n_frames - 1.0)
    i0 = np.minimum(np.floor(tau).astype(int), n_frames - 2)
    frame = _frame(x, pairs)
    local = _local(frame, dirs[:, joints])
    f = np.broadcast_to((tau - i0)[:, None], (length, len(joints)))
    new = dirs[sl].copy()
    new[:, joints] = _world(frame[sl], _slerp(local[i0], local[i0 + 1], f))
    out = x.copy()
    out[sl] = _place(x[sl], new, lengths[sl], joints)
    return out.astype(np.float32)


MECHANISMS = {
    "same_foot_twice": same_foot_twice,
    "bone_stretch": bone_stretch,
    "lagging_limb": lagging_limb,
}
