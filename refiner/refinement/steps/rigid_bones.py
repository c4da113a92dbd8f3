"""Rigid bones: each frame's bones put back within the lengths real motion gives them, what touches the ground held.

Generators stretch and shrink bones; real bones keep their length (a few, which span joints a skeleton leaves out,
bend a little). ``fit`` learns from real clips how far each bone's length strays from its clip's median
(:func:`bone_bands`). ``detect``: frames where some bone strays further. ``propose``: the nearest pose with every
bone within its band (:func:`within_bands`: bone constraints projected in turn, each bone's error shared by its two
joints), with each foot's lowest joint held, and the other foot joints where they are on the ground or lowest, so
feet neither slide nor sink. ``verify``: each run of changed frames is kept only where no physical figure (jerk,
foot slide, penetration, floating) gets worse (:func:`~refiner.refinement.steps.base.harms`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from refiner.core.contact import contact_joints, foot_joints, heights
from refiner.core.skeletons import get_skeleton
from refiner.refinement.steps.base import clip_ground, harms, runs, window_figures

__all__ = ["RigidBonesConfig", "RigidBonesStep", "bone_bands", "held_joints", "within_bands"]


@dataclass(frozen=True)
class RigidBonesConfig:
    """Options of :class:`RigidBonesStep`. ``quantile``: the share of real frames a bone's band holds (``fit``);
    ``floor``: the narrowest band (a share of the length: real bones' float error); ``contact_m``: a foot joint this
    close to the ground is held; ``iterations``: passes of :func:`within_bands`; ``jerk_share`` / ``slack_m`` as in
    :func:`~refiner.refinement.steps.base.harms`."""

    quantile: float = 0.99
    floor: float = 0.002
    contact_m: float = 0.05
    iterations: int = 50
    jerk_share: float = 0.05
    slack_m: float = 0.0


def _relative_lengths(joints, skeleton) -> np.ndarray:
    """``(..., T, B)``: each frame's bone lengths over the clip's median length of that bone."""
    lengths = get_skeleton(skeleton).bone_lengths(np.asarray(joints, np.float64))
    return lengths / np.maximum(np.median(lengths, axis=-2, keepdims=True), 1e-9)


def bone_bands(clips, skeleton, quantile: float = 0.99, floor: float = 0.002) -> np.ndarray:
    """``(B,)``: per bone, the ``quantile`` over all frames of real ``clips`` (each ``(T, J, 3)`` metres) of how far
    its length strays from its clip's median, as a share of that median; at least ``floor``."""
    dev = np.concatenate([np.abs(_relative_lengths(c, skeleton) - 1.0) for c in clips if len(c) > 1])
    return np.maximum(np.quantile(dev, quantile, axis=0), floor)


def held_joints(joints, skeleton, ground, contact_m: float = 0.05) -> np.ndarray:
    """``(..., T, J)`` bool: each foot's lowest joint (where foot skating is measured) in every frame, the other
    contact joints where within ``contact_m`` of ``ground`` (a float, or ``(...,)`` per clip) or lowest of the frame."""
    skel = get_skeleton(skeleton)
    h = heights(np.asarray(joints, np.float64), skel)
    contact = np.zeros(skel.n_joints, bool)
    contact[list(contact_joints(skel))] = True
    ground = np.asarray(ground, np.float64)[..., None, None]
    lowest = np.arange(skel.n_joints) == h.argmin(-1)[..., None]
    held = contact & ((h - ground < contact_m) | lowest)
    held[..., list(foot_joints(skel))] = True
    return held


def within_bands(joints, bands, held, skeleton, iterations: int = 50) -> np.ndarray:
    """``joints (..., T, J, 3)`` metres moved as little as the projection finds so that every bone's length lies within
    ``bands (B,)`` of its clip's median; ``held (..., T, J)`` joints do not move (a bone between two held joints is
    left as it is). Frames already within their bands come back exactly as given.

    ``iterations`` passes over the bones, each bone's error shared equally by its two joints (least squares: for
    joints that are each a little off, as a generator that regresses positions leaves them, the smallest move)."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, np.float64)
    median = np.median(skel.bone_lengths(x), axis=-2, keepdims=True)  # (..., 1, B)
    low, high = median * (1.0 - np.asarray(bands)), median * (1.0 + np.asarray(bands))
    free = (~np.asarray(held, bool)).astype(np.float64)
    y = x.copy()
    for _ in range(iterations):
        for i, (p, c) in enumerate(skel.bones):  # parents first: a correction travels down the chain in one pass
            share = free[..., p] + free[..., c]
            d = y[..., c, :] - y[..., p, :]
            n = np.linalg.norm(d, axis=-1)
            err = n - np.clip(n, low[..., i], high[..., i])
            move = np.divide(err, share * np.maximum(n, 1e-9), out=np.zeros_like(err), where=share > 0)[..., None] * d
            y[..., p, :] += free[..., p, None] * move
            y[..., c, :] -= free[..., c, None] * move
    return y


class RigidBonesStep:
    """Detect / propose / verify / report for bones that stretch (see the module docstring); ``bands`` from
    :func:`bone_bands` on real clips of ``skeleton`` (the weights' manifest), None: every bone rigid (``config.floor``)."""

    name = "rigid_bones"
    moves_whole_body = False

    def __init__(self, skeleton: str, bands=None, config: RigidBonesConfig = RigidBonesConfig()):
        self.skeleton, self.config = get_skeleton(skeleton).name, config
        n_bones = len(get_skeleton(skeleton).bones)
        self.bands = np.full(n_bones, config.floor) if bands is None else np.asarray(bands, np.float64)
        if self.bands.shape != (n_bones,):
            raise ValueError(f"`bands` must hold one value per bone of {self.skeleton!r} ({n_bones}); "
                             f"got shape {self.bands.shape}.")

    def detect(self, clips) -> np.ndarray:
        """``(N, T, B)`` bool: the bones of each frame whose length strays from the clip's median beyond its band."""
        return np.abs(_relative_lengths(clips, self.skeleton) - 1.0) > self.bands + 1e-9

    def propose(self, clips, stretched) -> np.ndarray:
        """The clips with the frames that hold a ``stretched (N, T, B)`` bone put within the bands (others as given)."""
        x = np.asarray(clips, np.float64)
        ground = np.array([clip_ground(c, self.skeleton) for c in x])
        held = held_joints(x, self.skeleton, ground, self.config.contact_m)
        out = within_bands(x, self.bands, held, self.skeleton, self.config.iterations)
        frames = stretched.any(-1)
        return np.where(frames[..., None, None], out, x)

    def refine(self, clips, actions=None) -> tuple[np.ndarray, list[list[dict]], None]:
        """Detect, propose and verify on ``clips (N, T, J, 3)``: the kept clips and each clip's change entries
        (``actions`` are not used: bones are the same whatever the action)."""
        x = np.array(clips, dtype=np.float64)
        stretched = self.detect(x)
        changes = [[] for _ in x]
        todo = np.flatnonzero(stretched.any((1, 2)))
        if len(todo):
            proposed = self.propose(x[todo], stretched[todo])
            for i, given, new, flags in zip(todo, x[todo], proposed, stretched[todo]):
                x[i], changes[i] = self.verify(given, new, flags)
        return x, changes, None

    def verify(self, given, proposed, stretched) -> tuple[np.ndarray, list[dict]]:
        """Keep each run of changed frames of one clip where :func:`harms` finds nothing worse; the clip and its
        change entries."""
        out = np.array(given, dtype=np.float64)
        ground = clip_ground(given, self.skeleton)
        entries = []
        for s, e in runs(stretched.any(-1)):
            worse = harms(window_figures(given, s, e, self.skeleton, ground),
                          window_figures(proposed, s, e, self.skeleton, ground),
                          jerk_share=self.config.jerk_share, slack_m=self.config.slack_m)
            worst = float(np.abs(_relative_lengths(given, self.skeleton)[s:e] - 1.0).max())
            entries.append({"step": self.name, "start": s, "stop": e, "kept": not worse, "worse": worse,
                            "parts": np.flatnonzero(stretched[s:e].any(0)).tolist(),
                            "reason": f"bones up to {100 * worst:.1f} % off their length put back within the lengths "
                                      f"real motion gives them"})
            if not worse:
                out[s:e] = proposed[s:e]
        return out, entries
