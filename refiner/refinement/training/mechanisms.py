"""Flaw mechanisms for training and for the held-out benchmark: independent ways a clip goes wrong.

Each mechanism is ``fn(clip, rng, severity=1.0) -> flawed``: ``clip (T, J, 3)`` float32 metres of any registered
skeleton (the skeleton is passed by keyword), a new flawed array back, the input untouched. Four families, each with
mechanisms in both folds (:data:`MECHANISMS`), so every learned part and every threshold can be fitted on one fold and
scored on the other (leave-one-fold-out: a mechanism is never seen by the weights that score it):

- ``angle``: a limb or the trunk turned at its joint, by forward kinematics on the clip's own bones (lengths exact);
- ``position``: joint positions moved (bones change, as in a position-space generator);
- ``time``: frames held, re-timed, reversed or skipped;
- ``root``: the whole body moved (float, sink, glide).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from refiner.core.bone_directions import blend_directions, from_bone_directions, retimed, subtree_bones, to_bone_directions
from refiner.core.rotations import rotvec_to_rotmat
from refiner.core.signal import smoothstep
from refiner.core.skeletons import get_skeleton

__all__ = ["Mechanism", "MECHANISMS", "FAMILIES", "mechanisms_of", "flaw_window", "envelope"]

#: Joints whose subtree a pose mechanism may turn, by name fragment (limbs at hip, knee, shoulder, elbow; the trunk).
_TURNABLE = ("hip", "knee", "shoulder", "elbow", "spine", "neck", "thorax", "collar")


def flaw_window(n_frames: int, rng: np.random.Generator, low: int = 10, high: int = 28) -> tuple[int, int]:
    """A random window ``[start, stop)`` of ``low..high`` frames inside the clip, clear of its first and last 2 frames."""
    length = int(rng.integers(low, high + 1))
    length = max(2, min(length, n_frames - 4))
    start = int(rng.integers(2, max(3, n_frames - length - 1)))
    return start, min(start + length, n_frames - 1)


def envelope(n_frames: int, start: int, stop: int, ramp: int) -> np.ndarray:
    """``(T,)`` weight: 0 outside ``[start, stop)``, rising over ``ramp`` frames (smoothstep) to 1 and back."""
    t = np.arange(n_frames, dtype=np.float64)
    ramp = max(1, min(ramp, (stop - start) // 2))
    up = np.clip((t - start + 1) / ramp, 0, 1)
    down = np.clip((stop - t) / ramp, 0, 1)
    return smoothstep(np.minimum(up, down))


def _turnable_joints(skel) -> np.ndarray:
    return np.array([j for j, n in enumerate(skel.joint_names) if any(k in n for k in _TURNABLE) and skel.parents[j] >= 0])


def _setup(clip, rng, skeleton):
    skel = get_skeleton(skeleton)
    x = np.asarray(clip, dtype=np.float64)
    start, stop = flaw_window(len(x), rng)
    return skel, x, start, stop, envelope(len(x), start, stop, int(rng.integers(3, 7)))


def _pose_edit(clip, rng, skeleton, edit):
    """Replace the directions of a random subtree's bones by ``edit(dirs, bones, weight, start, stop)``; bones exact."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    root, dirs, lengths = to_bone_directions(x, skel)
    bones = subtree_bones(skel, int(rng.choice(_turnable_joints(skel))))
    new = dirs.copy()
    new[:, bones] = edit(dirs[:, bones], w, start, stop)
    return from_bone_directions(root, new, lengths, skel).astype(np.float32)


def angle_turn(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """A limb or the trunk turned about its joint by 20-45 degrees (times severity) about a random axis, ramped in and out."""
    axis = rng.normal(size=3)
    angle = np.deg2rad(rng.uniform(20, 45)) * severity

    def edit(d, w, start, stop):
        rot = rotvec_to_rotmat((axis / np.linalg.norm(axis) * angle)[None] * w[:, None])
        return np.einsum("tij,tbj->tbi", rot, d)
    return _pose_edit(clip, rng, skeleton, edit)


def angle_freeze(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """A limb held in the pose it had when the window began (an arm that never comes down), ramped out at the end."""
    def edit(d, w, start, stop):
        return blend_directions(d, np.broadcast_to(d[start], d.shape), np.clip(w * severity, 0, 1)[:, None])
    return _pose_edit(clip, rng, skeleton, edit)


def angle_key(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """A limb's key pose taken from a distant frame of the same clip (a wrong key pose), blended in and out."""
    n = len(clip)

    def edit(d, w, start, stop):
        far = np.array([t for t in range(n) if abs(t - (start + stop) // 2) > (stop - start)] or [0])
        src = d[int(rng.choice(far))]
        return blend_directions(d, np.broadcast_to(src, d.shape), np.clip(w * severity, 0, 1)[:, None])
    return _pose_edit(clip, rng, skeleton, edit)


def angle_damp(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """A limb's swing damped toward its mean direction over the window (too little amplitude)."""
    def edit(d, w, start, stop):
        mean = d[start:stop].mean(0)
        mean = mean / np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-9)
        return blend_directions(d, np.broadcast_to(mean, d.shape), np.clip(0.8 * w * severity, 0, 1)[:, None])
    return _pose_edit(clip, rng, skeleton, edit)


def position_jitter(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """White noise of 1-3 cm (times severity) on a random third of the joints over the window."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    joints = rng.random(skel.n_joints) < 1 / 3
    noise = rng.normal(size=x.shape) * rng.uniform(0.01, 0.03) * severity
    return (x + noise * joints[None, :, None] * (w > 0)[:, None, None]).astype(np.float32)


def position_offset(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The joints of a random subtree pushed by a smooth 5-12 cm offset (bones at its joint stretch)."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    bones = subtree_bones(skel, int(rng.choice(_turnable_joints(skel))))
    joints = np.unique(skel.bones[bones, 1])
    offset = rng.normal(size=3)
    offset *= rng.uniform(0.05, 0.12) * severity / np.linalg.norm(offset)
    out = x.copy()
    out[:, joints] += w[:, None, None] * offset
    return out.astype(np.float32)


def position_blend(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The whole pose (root-relative joint positions) blended toward a distant frame's over the window."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    far = [t for t in range(len(x)) if abs(t - (start + stop) // 2) > (stop - start)] or [0]
    src = x[int(rng.choice(far))] - x[int(rng.choice(far)), skel.root]
    rel = x - x[:, skel.root:skel.root + 1]
    k = np.clip(0.7 * w * severity, 0, 1)[:, None, None]
    return (x[:, skel.root:skel.root + 1] + (1 - k) * rel + k * src).astype(np.float32)


def time_hold(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The window's first pose held, then a jump to where the motion is (a freeze)."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    out = x.copy()
    out[start:stop] = x[start]
    return out.astype(np.float32)


def time_stall(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The window slowed to a near stop then rushed to catch up (time map t -> t^p on the window)."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    u = np.linspace(0, 1, stop - start + 1)
    times = np.arange(len(x), dtype=np.float64)
    times[start:stop + 1] = start + (stop - start) * u ** (1 + 2 * severity)
    return retimed(x, times, skel).astype(np.float32)


def time_reverse(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """A part of the window played backwards (the motion goes back and forth)."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    half = (stop - start) // 2
    times = np.arange(len(x), dtype=np.float64)
    times[start:start + half] = start + np.arange(half)
    times[start + half:stop] = start + half - 1 - np.arange(stop - start - half) * min(1.0, severity)
    return retimed(x, times, skel).astype(np.float32)


def time_skip(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """Frames skipped ahead then held until the clip catches up (a dropped run of frames)."""
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    jump = max(2, int(round((stop - start) * 0.5 * min(1.0, severity))))
    times = np.arange(len(x), dtype=np.float64)
    times[start:stop] = np.minimum(np.arange(start, stop) + jump, stop)
    return retimed(x, times, skel).astype(np.float32)


def _root_move(clip, rng, skeleton, direction_fn, metres):
    skel, x, start, stop, w = _setup(clip, rng, skeleton)
    return (x + (w[:, None] * direction_fn(skel) * metres)[:, None, :]).astype(np.float32)


def root_float(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The whole body raised 5-12 cm (times severity) off the floor over the window."""
    return _root_move(clip, rng, skeleton, lambda s: s.up_vector, rng.uniform(0.05, 0.12) * severity)


def root_sink(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The whole body sunk 3-8 cm (times severity) into the floor over the window."""
    return _root_move(clip, rng, skeleton, lambda s: -s.up_vector, rng.uniform(0.03, 0.08) * severity)


def root_glide(clip, rng, severity=1.0, *, skeleton="humanact12"):
    """The whole body slid 8-20 cm (times severity) sideways and back over the window, feet and all."""
    angle = rng.uniform(0, 2 * np.pi)

    def sideways(s):
        up = s.up_vector
        a = np.cross(up, [1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.cross(up, [0.0, 0.0, 1.0])
        a /= np.linalg.norm(a)
        return np.cos(angle) * a + np.sin(angle) * np.cross(up, a)
    return _root_move(clip, rng, skeleton, sideways, rng.uniform(0.08, 0.2) * severity)


@dataclass(frozen=True)
class Mechanism:
    """A flaw mechanism: its function, family and fold (0 or 1)."""

    fn: Callable
    family: str
    fold: int

    def __call__(self, clip, rng, severity=1.0, *, skeleton="humanact12") -> np.ndarray:
        return self.fn(clip, rng, severity, skeleton=skeleton)


MECHANISMS = {
    "angle_turn": Mechanism(angle_turn, "angle", 0), "angle_freeze": Mechanism(angle_freeze, "angle", 0),
    "angle_key": Mechanism(angle_key, "angle", 1), "angle_damp": Mechanism(angle_damp, "angle", 1),
    "position_jitter": Mechanism(position_jitter, "position", 0),
    "position_offset": Mechanism(position_offset, "position", 1), "position_blend": Mechanism(position_blend, "position", 1),
    "time_hold": Mechanism(time_hold, "time", 0), "time_stall": Mechanism(time_stall, "time", 0),
    "time_reverse": Mechanism(time_reverse, "time", 1), "time_skip": Mechanism(time_skip, "time", 1),
    "root_float": Mechanism(root_float, "root", 0), "root_sink": Mechanism(root_sink, "root", 1),
    "root_glide": Mechanism(root_glide, "root", 1),
}
FAMILIES = ("angle", "position", "time", "root")


def mechanisms_of(fold: int | None) -> dict:
    """The mechanisms of ``fold`` (None: all)."""
    return {k: m for k, m in MECHANISMS.items() if fold is None or m.fold == fold}
