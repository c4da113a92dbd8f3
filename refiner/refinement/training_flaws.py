"""Randomised, compositional flaws for *training* the learned refiner (issue: learned flaw detection and repair).

This is deliberately separate from :mod:`refiner.evaluation.flaws`, which seeds the benchmark's seven documented
families. Here each training clip gets 0-3 flaws drawn from the mechanisms below, each in a random
window with random ramps, joint subsets and a continuous severity; :func:`synthesize` returns the
flawed clip and the per-frame mask of what it touched.

Mechanisms (``MECHANISMS``):

=================  ======================================================================
kind               what is done
=================  ======================================================================
``hold``           frames of a window repeat the window's first frame (a pause that pops back)
``stall``          a window is retimed by ``u ** p`` (p in 1.5-4): slow start, rush to the end
``time_warp``      a window is retimed monotonically by ``u + b sin(2 pi u) / (2 pi)``, ``|b| < 0.95``
``stutter``        duplicated frames: every 2nd-3rd frame of a window is held (frame drops)
``other_phase``    the root-relative pose moves toward a frame of the same clip >= 8 frames away
``other_clip``     ... toward a pose of another clip (any action), smoothstep bump
``mirror``         left/right confusion: the limbs' root-relative positions swap sides in a window
``limb_offset``    a limb (a joint and its descendants) or a joint subset without the root is
                   displaced by a constant offset, ramped
``limb_drift``     ... drifts instead: a smoothed random walk of offsets
``amplitude``      a window's root-relative motion is damped (x0.2-0.7) or exaggerated (x1.3-2) about its mean
``bone_stretch``   the bones of a limb stretch or shrink by 5-30 % over a window
``white_noise``    Gaussian noise (0.3-3 cm) on a joint subset over a window
``burst``          1-3-frame spikes (3-15 cm) on a few joints
``low_freq``       temporally smoothed noise (1-6 cm, sigma 2-6 frames) on a joint subset
``float``          the whole body rises or sinks (vertical root offset, 2-20 cm), smooth bump
``sink_drift``     a slow vertical drift of the whole body that stays
=================  ======================================================================

**Held out by design.** Two mechanisms of the benchmark's :data:`refiner.evaluation.flaws.FLAW_FAMILIES` are
*not* used here, so the bench can report how the refiner generalises to flaws it never saw:
``reversed_transition`` (no training flaw plays motion backwards: every retiming above is monotone)
and ``foot_sliding`` (no training flaw moves the body horizontally: limb offsets and drifts never
move the root; they used to move the whole body in 30 % of draws, a glide in all but name). They are listed in
:data:`HELD_OUT_FAMILIES`.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d

from refiner.core.signal import resample, smoothstep
from refiner.core.skeletons import get_skeleton, joint_bone_lengths, with_bone_lengths

__all__ = ["MECHANISMS", "GROUPS", "HELD_OUT_FAMILIES", "TRAINING_FAMILIES", "SyntheticFlaw", "synthesize", "mirror_pairs",
           "limb_joints"]

MECHANISMS = ("hold", "stall", "time_warp", "stutter", "other_phase", "other_clip", "mirror", "limb_offset",
              "limb_drift", "amplitude", "bone_stretch", "white_noise", "burst", "low_freq", "float", "sink_drift")
#: The mechanisms by what their repair needs: re-timing, a root path, a pose correction, denoising.
GROUPS = {
    "timing": ("hold", "stall", "time_warp", "stutter"),
    "root": ("float", "sink_drift"),
    "pose": ("other_phase", "other_clip", "mirror", "limb_offset", "limb_drift", "amplitude", "bone_stretch"),
    "noise": ("white_noise", "burst", "low_freq"),
}
#: Benchmark families (``refiner.evaluation.flaws``) whose mechanism no training flaw uses.
HELD_OUT_FAMILIES = ("reversed_transition", "foot_sliding")
#: Benchmark families whose mechanism training uses (pose from elsewhere, drift, noise, stalls, warps).
TRAINING_FAMILIES = ("wrong_anchor", "anchor_drift", "transition_jitter", "frozen_transition", "time_warp")


class SyntheticFlaw(NamedTuple):
    """A flawed clip and what was done.

    Attributes
    ----------
    joints : ndarray (T, J, 3) float32
        The flawed clip.
    touched : ndarray of bool (T,)
        Frames any flaw changed (all others equal the input exactly).
    kinds : tuple of str
        The mechanisms applied, in order.
    group_touched : ndarray of bool (T, len(GROUPS))
        Frames each group of :data:`GROUPS` changed.
    """

    joints: np.ndarray
    touched: np.ndarray
    kinds: tuple
    group_touched: np.ndarray


def mirror_pairs(skeleton) -> np.ndarray:
    """``(J,)`` index of each joint's left/right counterpart (itself when it has none), from the joint names."""
    skel = get_skeleton(skeleton)
    names = list(skel.joint_names)
    out = np.arange(len(names))
    for j, n in enumerate(names):
        for a, b in (("left", "right"), ("right", "left")):
            if a in n and n.replace(a, b) in names:
                out[j] = names.index(n.replace(a, b))
    return out


def limb_joints(skeleton, joint: int) -> np.ndarray:
    """``joint`` and all its descendants."""
    parents = np.asarray(get_skeleton(skeleton).parents)
    members = {int(joint)}
    for j in range(len(parents)):  # parents precede children in every registered skeleton
        if parents[j] in members:
            members.add(j)
    return np.array(sorted(members))


def _bump(n_frames: int, a: int, b: int, ramp: int) -> np.ndarray:
    """``(T,)`` weight: 0 outside ``[a, b)``, 1 inside, smoothstep ramps of ``ramp`` frames inside the ends."""
    t = np.arange(n_frames, dtype=np.float64)
    r = max(ramp, 1)
    w = np.minimum(smoothstep((t - a + 1) / r), smoothstep((b - t) / r))
    w[(t < a) | (t >= b)] = 0.0
    return w


def _window(rng, n_frames: int, lo: int = 3, hi_frac: float = 0.5) -> tuple[int, int]:
    length = int(rng.integers(lo, max(lo + 1, int(n_frames * hi_frac)) + 1))
    length = min(length, n_frames - 2)
    a = int(rng.integers(1, n_frames - length))
    return a, a + length


def _joint_subset(rng, n_joints: int, skeleton) -> np.ndarray:
    choice = rng.random()
    if choice < 0.3:
        return np.arange(n_joints)
    if choice < 0.7:
        return limb_joints(skeleton, int(rng.integers(1, n_joints)))
    subset = np.flatnonzero(rng.random(n_joints) < rng.uniform(0.2, 0.6))
    return subset if subset.size else np.array([int(rng.integers(n_joints))])


def _retime(x, a, b, warp):
    new = x.copy()
    u = np.linspace(0.0, 1.0, b - a + 1)
    new[a : b + 1] = resample(x, a + (b - a) * warp(u))
    return new


def _apply(kind: str, x: np.ndarray, rng, skeleton, donors) -> np.ndarray:
    """One mechanism on float64 joints ``(T, J, 3)``; returns the new clip."""
    n_frames, n_joints = x.shape[:2]
    skel = get_skeleton(skeleton)
    root = skel.root
    up = np.abs(skel.up_vector).argmax()
    a, b = _window(rng, n_frames)
    ramp = int(rng.integers(1, max(2, (b - a) // 2) + 1))
    rel = x - x[:, root : root + 1]
    if kind == "hold":
        new = x.copy()
        new[a:b] = x[a]
        return new
    if kind == "stall":
        p = rng.uniform(1.5, 4.0)
        return _retime(x, a, b, (lambda u: u ** p) if rng.random() < 0.5 else (lambda u: 1 - (1 - u) ** p))
    if kind == "time_warp":
        c = rng.uniform(0.3, 0.95) * rng.choice([-1.0, 1.0])
        return _retime(x, a, b, lambda u: u + c * np.sin(2 * np.pi * u) / (2 * np.pi))
    if kind == "stutter":
        step = int(rng.integers(2, 4))
        new = x.copy()
        idx = a + ((np.arange(b - a)) // step) * step
        new[a:b] = x[idx]
        return new
    if kind in ("other_phase", "other_clip"):
        t0 = int(rng.integers(a, b))
        if kind == "other_phase":
            far = np.flatnonzero(np.abs(np.arange(n_frames) - t0) >= 8)
            if far.size == 0:
                return x
            pose = rel[int(rng.choice(far))]
        else:
            if not donors:
                return x
            d = donors[int(rng.integers(len(donors)))]
            pose = d[int(rng.integers(len(d)))]
            pose = pose - pose[root : root + 1]
        w = _bump(n_frames, a, b, max(ramp, (b - a) // 2)) * rng.uniform(0.4, 1.0)
        return x + w[:, None, None] * (pose - rel)
    if kind == "mirror":
        pairs = mirror_pairs(skel)
        w = _bump(n_frames, a, b, ramp) * rng.uniform(0.5, 1.0)
        return x + w[:, None, None] * (rel[:, pairs] - rel)
    joints = _joint_subset(rng, n_joints, skel)
    if kind in ("limb_offset", "limb_drift"):  # never the whole body: moving it all is a glide (held out)
        joints = joints[joints != root] if len(joints) < n_joints else limb_joints(skel, int(rng.integers(1, n_joints)))
        joints = joints if joints.size else limb_joints(skel, int(rng.integers(1, n_joints)))
    if kind == "limb_offset":
        offset = rng.normal(size=3)
        offset *= rng.uniform(0.03, 0.2) / np.linalg.norm(offset)
        new = x.copy()
        new[:, joints] += _bump(n_frames, a, b, ramp)[:, None, None] * offset
        return new
    if kind == "limb_drift":
        walk = np.cumsum(rng.normal(size=(b - a, 1, 3)), axis=0)
        walk = gaussian_filter1d(walk, sigma=rng.uniform(2, 6), axis=0)
        walk *= rng.uniform(0.03, 0.15) / max(np.abs(walk).max(), 1e-9)
        new = x.copy()
        new[a:b, joints] += walk * _bump(n_frames, a, b, ramp)[a:b, None, None]
        return new
    if kind == "amplitude":
        s = rng.uniform(0.2, 0.7) if rng.random() < 0.5 else rng.uniform(1.3, 2.0)
        mean = rel[a:b].mean(0)
        w = _bump(n_frames, a, b, ramp)[:, None, None]
        target = mean + s * (rel - mean)
        new = x.copy()
        new[:, joints] += (w * (target - rel))[:, joints]
        return new
    if kind == "bone_stretch":
        lengths = joint_bone_lengths(x, skel)
        scale = np.ones(n_joints)
        scale[joints] = rng.uniform(0.7, 0.95) if rng.random() < 0.5 else rng.uniform(1.05, 1.3)
        w = _bump(n_frames, a, b, ramp)[:, None]
        return with_bone_lengths(x, lengths * (1 + w * (scale - 1)), skel)
    if kind == "white_noise":
        noise = rng.normal(scale=rng.uniform(0.003, 0.03), size=(b - a, len(joints), 3))
        new = x.copy()
        new[a:b, joints] += noise * _bump(n_frames, a, b, 1)[a:b, None, None]
        return new
    if kind == "burst":
        new = x.copy()
        for _ in range(int(rng.integers(1, 4))):
            t = int(rng.integers(1, n_frames - 1))
            width = int(rng.integers(1, 4))
            js = rng.choice(n_joints, size=int(rng.integers(1, min(4, n_joints) + 1)), replace=False)
            spike = rng.normal(size=(len(js), 3))
            spike *= rng.uniform(0.03, 0.15) / np.linalg.norm(spike, axis=-1, keepdims=True)
            new[t : t + width, js] += spike
        return new
    if kind == "low_freq":
        sigma = rng.uniform(2, 6)
        noise = gaussian_filter1d(rng.normal(size=(n_frames, len(joints), 3)), sigma=sigma, axis=0)
        noise *= rng.uniform(0.01, 0.06) / max(noise.std(), 1e-9)
        new = x.copy()
        new[:, joints] += noise * _bump(n_frames, a, b, ramp)[:, None, None]
        return new
    if kind == "float":
        offset = np.zeros(3)
        offset[up] = rng.uniform(0.02, 0.2) * rng.choice([-1.0, 1.0])
        return x + _bump(n_frames, a, b, ramp)[:, None, None] * offset
    if kind == "sink_drift":
        offset = np.zeros(3)
        offset[up] = rng.uniform(0.03, 0.15) * rng.choice([-1.0, 1.0])
        w = smoothstep((np.arange(n_frames) - a) / max(b - a, 1))
        return x + w[:, None, None] * offset
    raise ValueError(f"unknown flaw mechanism {kind!r}; known: {', '.join(MECHANISMS)}.")


def synthesize(joints, rng: np.random.Generator, *, skeleton="humanact12", kinds: Sequence[str] | None = None,
               max_flaws: int = 3, clean_probability: float = 0.2,
               donors: Sequence[np.ndarray] | None = None) -> SyntheticFlaw:
    """Corrupt one clip with 0 to ``max_flaws`` random mechanisms.

    Parameters
    ----------
    joints : array (T, J, 3), metres, T >= 8
    rng : numpy Generator
    skeleton : str
        Gives the root, the up axis, the limbs and the left/right pairs.
    kinds : sequence of str, optional
        Mechanisms to draw from (default all of :data:`MECHANISMS`).
    max_flaws : int
    clean_probability : float
        Chance that the clip is returned clean.
    donors : sequence of arrays (T_i, J, 3), optional
        Other clips for ``other_clip``.

    Returns
    -------
    SyntheticFlaw
    """
    x = np.asarray(joints, dtype=np.float64)
    if x.ndim != 3 or len(x) < 8:
        raise ValueError(f"`joints` must be (T >= 8, J, 3); got shape {x.shape}.")
    kinds = tuple(MECHANISMS if kinds is None else kinds)
    unknown = set(kinds) - set(MECHANISMS)
    if unknown:
        raise ValueError(f"unknown flaw mechanisms {sorted(unknown)}; known: {', '.join(MECHANISMS)}.")
    applied: list[str] = []
    new = x
    groups = np.zeros((len(x), len(GROUPS)), bool)
    group_of = {k: g for g, (_, members) in enumerate(GROUPS.items()) for k in members}
    if rng.random() >= clean_probability:
        for _ in range(int(rng.integers(1, max_flaws + 1))):
            kind = str(rng.choice(kinds))
            before = new
            new = _apply(kind, new, rng, skeleton, donors)
            groups[:, group_of[kind]] |= np.abs(new - before).reshape(len(x), -1).max(-1) > 1e-7
            applied.append(kind)
    touched = np.abs(new - x).reshape(len(x), -1).max(-1) > 1e-7
    out = np.where(touched[:, None, None], new, x).astype(np.float32)
    return SyntheticFlaw(out, touched, tuple(applied), groups & touched[:, None])
