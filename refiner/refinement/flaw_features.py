"""Per-frame kinematic evidence of flaws, for the flaw classifier (:class:`~refiner.refinement.flaw_classifier.FlawClassifier`).

Real motion capture is rigid, smooth at 20 fps, keeps planted feet still and rarely reverses
every joint at once; synthetic and generated flaws break one of these. Each feature below is
computed per frame from joint positions alone (any registered skeleton), in units scaled to
about 1, and most come twice: as is and relative to the clip's own median, since a fast action
(boxing) is not a flaw but a sudden change of speed within a clip may be.

=====================  ===========================================================================
feature                meaning
=====================  ===========================================================================
speed mean / max       joint speed (m per frame x 10)
accel mean / max       second difference of positions (x 100)
jerk mean / max        third difference (x 100)
residual mean / max    distance from a Gaussian-smoothed copy (sigma 1 frame, x 100): jitter
bone dev. mean / max   bone length against the clip's median, relative (x 10): stretching, drift
root height / v. vel   root height over the clip's median and its vertical velocity: floating
root h. speed          horizontal root speed (x 10)
feet                   per foot: horizontal speed (x 10) and height over the clip's lowest (x 10): skating
reversal               speed-weighted mean cosine between consecutive joint velocities: reversals
=====================  ===========================================================================
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from refiner.core.contact import foot_joints
from refiner.core.signal import norms
from refiner.core.skeletons import bone_lengths, get_skeleton

__all__ = ["flaw_features", "N_FEATURES"]


def _diff(x: np.ndarray, order: int) -> np.ndarray:
    """``order``-th difference along time (axis 1 of ``(B, T, ...)``), padded back to ``T`` frames by
    repeating the edge values."""
    d = np.diff(x, n=order, axis=1)
    front = order // 2 + order % 2
    back = x.shape[1] - d.shape[1] - front
    return np.concatenate([np.repeat(d[:, :1], front, 1), d, np.repeat(d[:, -1:], back, 1)], 1)


def flaw_features(joints, skeleton="humanact12") -> np.ndarray:
    """Per-frame features of joints ``(T, J, 3)`` or a batch ``(B, T, J, 3)``, metres (T >= 4) ->
    ``(T, N_FEATURES)`` or ``(B, T, N_FEATURES)`` float32."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, dtype=np.float32)  # float64 took half as long again (256 clips: 163 against 106 ms)
    single = x.ndim == 3
    x = x[None] if single else x
    if x.ndim != 4 or x.shape[1] < 4 or x.shape[-1] != 3:
        raise ValueError(f"`joints` must be (T >= 4, J, 3) or (B, T, J, 3); got shape {np.shape(joints)}.")
    up = int(np.abs(skel.up_vector).argmax())
    sign = float(skel.up_vector[up])
    horiz = [a for a in range(3) if a != up]
    vel = _diff(x, 1)
    speed = norms(vel)  # (B, T, J)
    acc = norms(_diff(x, 2))
    jerk = norms(_diff(x, 3))
    resid = norms(x - gaussian_filter1d(x, 1.0, axis=1, mode="nearest"))
    lengths = bone_lengths(x, skel)  # (B, T, J-1)
    dev = np.abs(lengths / np.maximum(np.median(lengths, 1, keepdims=True), 1e-6) - 1.0)
    root = x[:, :, skel.root]
    height = sign * root[..., up]
    feats = [10 * speed.mean(-1), 10 * speed.max(-1), 100 * acc.mean(-1), 100 * acc.max(-1), 100 * jerk.mean(-1),
             100 * jerk.max(-1), 100 * resid.mean(-1), 100 * resid.max(-1), 10 * dev.mean(-1), 10 * dev.max(-1),
             height - np.median(height, 1, keepdims=True), 10 * sign * vel[:, :, skel.root, up],
             10 * norms(vel[:, :, skel.root][..., horiz])]
    for f in foot_joints(skel):
        h = sign * x[:, :, f, up]
        feats += [10 * norms(vel[:, :, f][..., horiz]), 10 * (h - h.min(1, keepdims=True))]
    prev = np.concatenate([vel[:, :1], vel[:, :-1]], 1)
    cos = (vel * prev).sum(-1) / np.maximum(speed * norms(prev), 1e-9)
    w = speed / np.maximum(speed.sum(-1, keepdims=True), 1e-9)
    feats.append((w * cos).sum(-1))
    base = np.stack(feats, -1)  # (B, T, 18)
    relative = base[..., :8] / np.maximum(np.median(base[..., :8], 1, keepdims=True), 1e-3)
    out = np.concatenate([base, np.log1p(relative)], -1).astype(np.float32)
    return out[0] if single else out


N_FEATURES = 13 + 2 * 2 + 1 + 8
