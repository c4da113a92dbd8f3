"""Blind ground-contact and jitter flaw mechanisms: hovering, foot skating, sinking and jitter bursts.

Written from a description of what 3D human-motion generators get wrong, without looking at how any refiner
detects it. Each maps a clean HumanAct12 clip ``(T, 24, 3)`` (metres, y axis down so height is ``-y``, facing
about -z, 20 fps) to a new float32 copy that differs from it only inside one random window (8-30 frames) whose
edges fade in and out smoothly; the input is never modified. "Up" is ``-y`` of the data frame and the floor is
taken as the x-z plane (no floor is fitted: the flaws are relative moves, as a generator's would be).
"""
from __future__ import annotations

import numpy as np

from refiner.evaluation.blind_geometry import PARENTS as _PARENTS, unit as _unit

__all__ = ["MECHANISMS", "hover_above_ground", "foot_skate", "sink_into_floor", "joint_jitter"]

_FPS = 20.0
_UP = np.array([0.0, -1.0, 0.0])
# leg -> (hip, knee, ankle, foot)
_LEGS = {"left": (1, 4, 7, 10), "right": (2, 5, 8, 11)}
# joint groups a jitter burst can shake
_GROUPS = {
    "left_arm": (18, 20, 22),
    "right_arm": (19, 21, 23),
    "left_leg": (4, 7, 10),
    "right_leg": (5, 8, 11),
    "head": (12, 15),
    "whole_body": tuple(range(24)),
}


def _window(n_frames: int, rng: np.random.Generator, lo: int, hi: int) -> tuple[int, int]:
    """A random window ``(start, length)`` of ``lo``-``hi`` frames that leaves the first and last frame untouched."""
    hi = max(1, min(hi, n_frames - 2))
    length = int(rng.integers(min(lo, hi), hi + 1))
    return int(rng.integers(1, n_frames - length)), length


def _fade(length: int, rng: np.random.Generator, lo: float = 0.15, hi: float = 0.35) -> np.ndarray:
    """Weights ``(length,)`` in (0, 1]: a sin^2 fade in and a separate fade out (each a random ``lo``-``hi``
    share of the window) around a plateau at 1."""
    u = np.arange(length)
    r_in, r_out = (max(1, int(round(length * rng.uniform(lo, hi)))) for _ in range(2))
    f_in = np.sin(0.5 * np.pi * np.minimum(1.0, (u + 1) / (r_in + 1))) ** 2
    f_out = np.sin(0.5 * np.pi * np.minimum(1.0, (length - u) / (r_out + 1))) ** 2
    return np.minimum(f_in, f_out)


def _out_and_back(length: int, rng: np.random.Generator) -> np.ndarray:
    """Offset shape ``(length,)`` in (0, 1]: smoothstep rise to 1, an optional hold, smoothstep return to 0."""
    u = (np.arange(length) + 1.0) / (length + 1.0)
    a = rng.uniform(0.3, 0.65)
    b = min(0.85, a + rng.uniform(0.0, 0.3))
    s = lambda z: z * z * (3.0 - 2.0 * z)  # noqa: E731
    back = s(np.clip((1.0 - u) / (1.0 - b), 0.0, 1.0))
    return np.where(u < a, s(np.clip(u / a, 0.0, 1.0)), np.where(u <= b, 1.0, back))


def _horizontal_basis(seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit forward and left vectors ``(3,)`` in the floor plane, from the hips of a window ``(L, 24, 3)``."""
    left = (seg[:, 1] - seg[:, 2]).mean(0)
    left = left - (left @ _UP) * _UP
    left = left / np.linalg.norm(left) if np.linalg.norm(left) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.cross(left, _UP), left


def _leg_ik(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, target: np.ndarray, fallback: np.ndarray):
    """Two-bone IK: new knee and ankle ``(L, 3)`` keeping thigh and shin lengths, the ankle on ``target`` (or as
    near as the leg reaches), the knee in its own bend plane (``fallback`` ``(3,)`` when the leg is straight)."""
    a = np.linalg.norm(knee - hip, axis=-1)
    b = np.linalg.norm(ankle - knee, axis=-1)
    d = target - hip
    reach = np.clip(np.linalg.norm(d, axis=-1), np.abs(a - b) + 1e-7, a + b - 1e-7)
    dhat = _unit(d)
    bend = (knee - hip) - ((knee - hip) * dhat).sum(-1, keepdims=True) * dhat
    alt = fallback - (dhat @ fallback)[:, None] * dhat
    bend = np.where(np.linalg.norm(bend, axis=-1, keepdims=True) > 1e-6, bend, alt)
    bhat = _unit(bend)
    cos = np.clip((a * a + reach * reach - b * b) / (2.0 * a * reach), -1.0, 1.0)
    new_knee = hip + a[:, None] * (cos[:, None] * dhat + np.sqrt(1.0 - cos * cos)[:, None] * bhat)
    return new_knee, hip + reach[:, None] * dhat


def _within_reach(rel: np.ndarray, offset: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Largest share ``s`` in [0, 1] per frame ``(L,)`` with ``|rel + s * offset| <= reach`` (``rel`` from the hip)."""
    oo = (offset * offset).sum(-1)
    po = (rel * offset).sum(-1)
    disc = np.maximum(po * po - oo * ((rel * rel).sum(-1) - reach * reach), 0.0)
    return np.clip((np.sqrt(disc) - po) / np.maximum(oo, 1e-18), 0.0, 1.0)


def hover_above_ground(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a body that floats off the floor for a stretch (common in diffusion and VAE generators).

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32. Inside a 10-30 frame window every joint is lifted
    (along ``-y``) by the same height: 3-8 cm times ``severity`` on the plateau, faded in and out over 20-40 % of the
    window each, drifting linearly by up to +-25 % across the window and, half the time, bobbing by 10-25 % at
    1.5-3.5 Hz (so at most about 12 cm at severity 1). A rigid translation per frame, as a rotation-based
    generator's root drift: bone lengths are kept.
    """
    x = np.array(clip, dtype=np.float64)
    start, length = _window(len(x), rng, 10, 30)
    t = np.arange(length) / _FPS
    height = rng.uniform(0.03, 0.08) * severity
    drift = 1.0 + rng.uniform(-0.25, 0.25) * np.linspace(-1.0, 1.0, length)
    bob = 1.0
    if rng.random() < 0.5:
        bob = 1.0 + rng.uniform(0.1, 0.25) * np.sin(2.0 * np.pi * rng.uniform(1.5, 3.5) * t + rng.uniform(0, 2 * np.pi))
    lift = height * _fade(length, rng, 0.2, 0.4) * drift * bob
    out = x.copy()
    out[start:start + length] += lift[:, None, None] * _UP
    return out.astype(np.float32)


def foot_skate(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates feet that slide along the floor for a stretch instead of staying planted.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside a 12-30 frame window. An x-z offset
    rises smoothly to its peak over the first 30-65 % of the window, may hold, and slides back to zero by the
    window's end (so the clip rejoins its own path); its direction turns by up to +-30 degrees on the way. Two
    forms: (a, 60 %) the whole body glides (moonwalk-like) by 4-12 cm times ``severity``, half the time along the
    facing direction (either way), else in any horizontal direction, the limbs keeping their own motion;
    (b, 40 %) the planted (lower, over the window) foot slides by 4-10 cm times ``severity`` while the body stays,
    the ankle and foot moved together and the knee re-solved by two-bone IK; where the leg is too straight to
    reach, the foot slides less. Bone lengths and the feet's heights are kept exactly in both forms (a rigid
    translation; IK keeps thigh, shin and foot).
    """
    x = np.array(clip, dtype=np.float64)
    start, length = _window(len(x), rng, 12, 30)
    seg = x[start:start + length]
    fwd, left = _horizontal_basis(seg)
    whole = rng.random() < 0.6
    if whole and rng.random() < 0.5:
        theta = 0.0 if rng.random() < 0.5 else np.pi
    else:
        theta = rng.uniform(0.0, 2.0 * np.pi)
    theta = theta + np.deg2rad(rng.uniform(-30.0, 30.0)) * np.linspace(0.0, 1.0, length)
    size = rng.uniform(0.04, 0.12) if whole else rng.uniform(0.04, 0.10)
    shape = size * severity * _out_and_back(length, rng)
    offset = shape[:, None] * (np.cos(theta)[:, None] * fwd + np.sin(theta)[:, None] * left)  # (L, 3)
    new = seg.copy()
    if whole:
        new += offset[:, None, :]
    else:
        name = max(_LEGS, key=lambda k: seg[:, _LEGS[k][2], 1].mean())  # larger y = lower
        hip, knee, ankle, foot = _LEGS[name]
        reach = sum(np.linalg.norm(seg[:, j] - seg[:, i], axis=-1) for i, j in ((hip, knee), (knee, ankle)))
        offset = offset * _within_reach(seg[:, ankle] - seg[:, hip], offset, reach - 1e-6)[:, None]  # a straight leg
        new[:, knee], new[:, ankle] = _leg_ik(seg[:, hip], seg[:, knee], seg[:, ankle], seg[:, ankle] + offset, fwd)
        new[:, foot] = seg[:, foot] + new[:, ankle] - seg[:, ankle]
    out = x.copy()
    out[start:start + length] = new
    return out.astype(np.float32)


def sink_into_floor(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates feet (and body) that go partly through the floor for a stretch.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside a 10-30 frame window; the depth
    (3-7 cm times ``severity`` on the plateau, faded in and out over 15-35 % of the window each, drifting by up to
    +-30 % across it) only moves joints down (``+y``). Two forms: (a, 50 %) the whole body is lowered rigidly -
    bone lengths kept; (b, 50 %) the legs are pushed down as a joint-position generator would: the ankles and
    feet of both legs (or of one, 35 %) sink by the full depth, their knees by 35-65 % of it, and the pelvis,
    upper body and any other leg by 0-40 % of it, so thighs and shins stretch by up to the depth - those bone
    lengths are NOT kept, all others are.
    """
    x = np.array(clip, dtype=np.float64)
    start, length = _window(len(x), rng, 10, 30)
    depth = rng.uniform(0.03, 0.07) * severity
    drift = 1.0 + rng.uniform(-0.3, 0.3) * np.linspace(-1.0, 1.0, length)
    amount = depth * _fade(length, rng) * drift  # (L,) metres down
    share = np.ones(x.shape[1])
    if rng.random() >= 0.5:
        legs = list(_LEGS.values()) if rng.random() >= 0.35 else [_LEGS[("left", "right")[int(rng.integers(2))]]]
        body = rng.uniform(0.0, 0.4)
        share[:] = body
        knee_share = rng.uniform(0.35, 0.65)
        for _, knee, ankle, foot in legs:
            share[knee] = body + (1.0 - body) * knee_share
            share[[ankle, foot]] = 1.0
    out = x.copy()
    out[start:start + length] -= amount[:, None, None] * share[None, :, None] * _UP
    return out.astype(np.float32)


def joint_jitter(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a burst of high-frequency shaking on a limb, the head or the whole body.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside an 8-24 frame window. Each shaken
    joint gets Gaussian noise of 1-2 cm RMS (3D, times ``severity``) on the plateau, faded in and out over 10-30 %
    of the window each; the noise is white or smoothed over up to about 1 frame (still high-frequency), and a
    joint inherits 0-90 % of its parent's noise, so a limb can shake as a whole or joint by joint. The group is
    the whole body (30 %) or one arm, leg or the head. Position noise, as a joint-position generator's: bone
    lengths are NOT kept.
    """
    x = np.array(clip, dtype=np.float64)
    start, length = _window(len(x), rng, 8, 24)
    names = list(_GROUPS)
    name = "whole_body" if rng.random() < 0.3 else names[int(rng.integers(len(names) - 1))]
    group = _GROUPS[name]
    sigma = rng.uniform(0.01, 0.02) * severity / np.sqrt(3.0)  # per axis
    smooth = rng.uniform(0.0, 1.2)  # frames
    inherit = rng.uniform(0.0, 0.9)
    pad = 4
    white = rng.standard_normal((length + 2 * pad, x.shape[1], 3))
    k = np.exp(-0.5 * (np.arange(-pad, pad + 1) / smooth) ** 2) if smooth > 0.3 else np.eye(1, 2 * pad + 1, pad)[0]
    k /= np.sqrt((k * k).sum())  # unit variance kept
    white = sum(w * white[i:i + length] for i, w in enumerate(k))
    noise = np.zeros_like(white)
    for j in group:  # parents come first
        p = _PARENTS[j]
        if p >= 0 and p in group:
            noise[:, j] = inherit * noise[:, p] + np.sqrt(1.0 - inherit * inherit) * white[:, j]
        else:
            noise[:, j] = white[:, j]
    out = x.copy()
    out[start:start + length] += sigma * _fade(length, rng, 0.1, 0.3)[:, None, None] * noise
    return out.astype(np.float32)


MECHANISMS = {
    "hover_above_ground": hover_above_ground,
    "foot_skate": foot_skate,
    "sink_into_floor": sink_into_floor,
    "joint_jitter": joint_jitter,
}
