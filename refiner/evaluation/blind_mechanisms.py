"""Flaw mechanisms that imitate what 3D human-motion generators get wrong, on HumanAct12 joints.

Each mechanism maps a clean clip ``(T, 24, 3)`` (metres, y down, facing -z) to a flawed copy inside one
random window of 8-30 frames with smooth edges; the two here keep every frame's own bone lengths exactly.
``MECHANISMS`` also holds the ground-contact and jitter ones of :mod:`refiner.evaluation.blind_ground_mechanisms`
(hover, foot skate, sink, jitter; the last two change some bone lengths, as their docstrings say) and the
timing ones of :mod:`refiner.evaluation.blind_timing_mechanisms` (stutter, tempo drift, dropped frames with a crawl;
re-timings that keep every frame's own bone lengths exactly) and the gait and limb ones of
:mod:`refiner.evaluation.blind_gait_mechanisms` (same foot twice and a lagging limb, bones kept exactly; bone stretch,
which by design does not keep them).
"""
from __future__ import annotations

import numpy as np

from refiner.evaluation.blind_geometry import (PARENTS as _PARENTS, bones as _bones, rotate as _rotate, slerp as _slerp,
                                               unit as _unit)
from refiner.evaluation import blind_gait_mechanisms, blind_ground_mechanisms, blind_timing_mechanisms
from refiner.evaluation.blind_gait_mechanisms import bone_stretch, lagging_limb, same_foot_twice
from refiner.evaluation.blind_ground_mechanisms import foot_skate, hover_above_ground, joint_jitter, sink_into_floor
from refiner.evaluation.blind_timing_mechanisms import dropped_frames_crawl, stutter, tempo_drift

__all__ = ["MECHANISMS", "wrong_limb_pose", "freeze_catch_up", "hover_above_ground", "foot_skate", "sink_into_floor",
           "joint_jitter", "stutter", "tempo_drift", "dropped_frames_crawl", "same_foot_twice", "bone_stretch",
           "lagging_limb"]

# limb name -> (pivot joint, joints moved with it, torso frame: lateral pair, up pair)
_LIMBS = {
    "left_arm": (16, (18, 20, 22), (16, 17), (9, 12)),
    "right_arm": (17, (19, 21, 23), (16, 17), (9, 12)),
    "left_leg": (1, (4, 7, 10), (1, 2), (0, 3)),
    "right_leg": (2, (5, 8, 11), (1, 2), (0, 3)),
}


def _profile(length: int, rng: np.random.Generator) -> np.ndarray:
    """Weights over a window: raised-cosine ramp in, plateau at 1, raised-cosine ramp out."""
    ramp = max(2, int(round(length * rng.uniform(0.2, 0.35))))
    w = np.ones(length)
    up = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, ramp + 1) / (ramp + 1))
    w[:ramp] = up
    w[length - ramp:] = np.minimum(w[length - ramp:], up[::-1])
    return w


def _torso_frame(x: np.ndarray, lateral: tuple, up: tuple) -> np.ndarray:
    """Per-frame orthonormal frame ``(T, 3, 3)`` with columns (left, up, forward) of a torso segment."""
    e1 = _unit(x[:, lateral[0]] - x[:, lateral[1]])
    b = x[:, up[1]] - x[:, up[0]]
    e2 = _unit(b - (b * e1).sum(-1, keepdims=True) * e1)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def _rebuild(base: np.ndarray, dirs: np.ndarray, lengths: np.ndarray, joints) -> np.ndarray:
    """Place ``joints`` (parents first) at their parent plus length times direction; others from ``base``."""
    out = base.copy()
    for j in joints:
        out[:, j] = out[:, _PARENTS[j]] + lengths[:, j, None] * dirs[:, j]
    return out


def _window(n_frames: int, rng: np.random.Generator, lo: int = 8, hi: int = 30, energy=None):
    """A random window (start, length) fully inside the clip, starts weighted by ``energy`` if given."""
    length = int(rng.integers(lo, min(hi, n_frames - 2) + 1))
    starts = np.arange(1, n_frames - length)
    p = None
    if energy is not None:
        e = np.convolve(energy, np.ones(length), "valid")[starts]
        p = (e + 0.1 * e.mean() + 1e-12) / (e + 0.1 * e.mean() + 1e-12).sum()
    return int(rng.choice(starts, p=p)), length


def wrong_limb_pose(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a limb reaching a wrong key pose and holding it (kick too low, arm raised wrongly or left up)."""
    x = np.array(clip, dtype=np.float64)
    n_frames = len(x)
    names = list(_LIMBS)
    ends = [_LIMBS[n][1][-1] for n in names]
    rel = np.stack([x[:, e] - x[:, _LIMBS[n][0]] for n, e in zip(names, ends)], 1)
    activity = np.linalg.norm(np.diff(rel, axis=0), axis=-1).mean(0)
    p = activity + 0.5 * activity.mean() + 1e-12
    name = names[int(rng.choice(len(names), p=p / p.sum()))]
    _, moved, lateral, up = _LIMBS[name]
    energy = np.linalg.norm(np.diff(rel[:, names.index(name)], axis=0), axis=-1)
    start, length = _window(n_frames, rng, energy=np.append(energy, 0.0))
    sl = slice(start, start + length)
    w = _profile(length, rng)
    seg = x[sl]
    frame = _torso_frame(seg, lateral, up)
    dirs, lengths = _bones(seg)
    local = np.einsum("tij,tkj->tki", frame.transpose(0, 2, 1), dirs)  # bone directions in the torso frame
    held = None
    if rng.random() < 0.5:
        # a pose of this limb from elsewhere in the clip, the most unlike the window's among a few draws
        all_dirs = np.einsum("tij,tkj->tki", _torso_frame(x, lateral, up).transpose(0, 2, 1), _bones(x)[0])
        cand = rng.choice(n_frames, size=min(n_frames, 12), replace=False)
        size = lengths[:, list(moved)].mean(0)
        gap = [(np.linalg.norm(all_dirs[c, list(moved)] - local[:, list(moved)], axis=-1) * size).sum(1).mean()
               for c in cand]  # roughly how far the limb's end would move, in metres
        held = all_dirs[cand[int(np.argmax(gap))]] if max(gap) >= 0.3 else None  # else too like the window
    if held is not None:
        target, weight = np.broadcast_to(held, local.shape), w * min(1.0, severity)
    else:
        # the window's own pose rotated about the pivot: swung forward/back and/or out/in
        phi = rng.uniform(0.0, 2.0 * np.pi)
        limb = _unit((local[:, list(moved)] * lengths[:, list(moved), None]).sum(1).mean(0))
        for axis in (np.array([np.cos(phi), 0.0, np.sin(phi)]), np.array([-np.sin(phi), 0.0, np.cos(phi)])):
            axis = axis - (axis @ limb) * limb  # a mix of lateral (flexion) and forward (abduction) axes,
            if np.linalg.norm(axis) > 0.5:  # made a swing, not a twist, of the limb
                break
        axis = _unit(axis)
        angle = np.deg2rad(rng.uniform(30.0, 55.0)) * severity
        target, weight = _rotate(local, axis, np.full(local.shape[:-1], angle)), w
    new_local = local.copy()
    new_local[:, list(moved)] = _slerp(local[:, list(moved)], target[:, list(moved)], weight[:, None])
    new_dirs = np.einsum("tij,tkj->tki", frame, new_local)
    out = x.copy()
    out[sl] = _rebuild(seg, new_dirs, lengths, moved)
    return out.astype(np.float32)


def _sample(x: np.ndarray, dirs: np.ndarray, lengths: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Poses at fractional times ``tau``: root linear, bone directions by slerp, ``lengths`` ``(len(tau), J)``."""
    i0 = np.clip(np.floor(tau).astype(int), 0, len(x) - 2)
    f = (tau - i0)[:, None]
    root = x[i0, 0] * (1 - f) + x[i0 + 1, 0] * f
    d = _slerp(dirs[i0], dirs[i0 + 1], np.broadcast_to(f, dirs[i0].shape[:-1]))
    base = np.zeros((len(tau),) + x.shape[1:])
    base[:, 0] = root
    return _rebuild(base, d, lengths, range(1, x.shape[1]))


def freeze_catch_up(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a motion that stalls for a moment then catches up too fast to rejoin its own timeline."""
    x = np.array(clip, dtype=np.float64)
    n_frames = len(x)
    dirs, lengths = _bones(x)
    speed = np.append(np.linalg.norm(np.diff(x, axis=0), axis=-1).mean(1), 0.0)
    depth = float(np.clip(severity, 0.0, 1.0))
    cap = 0.10 * max(severity, 1e-3)
    freeze = min(20, int(rng.integers(5, 17) * max(1.0, severity)))
    share, edge = rng.uniform(0.35, 0.6), rng.uniform(0.2, 0.35)
    catch = lambda f: int(np.clip(round(f * share), max(3, 9 - f), 31 - f))  # noqa: E731
    start, _ = _window(n_frames, rng, lo=freeze + catch(freeze), hi=freeze + catch(freeze), energy=speed)
    while True:  # shorten the stall, then soften it, until the window's mean displacement is within the cap
        length = freeze + catch(freeze)
        ramp = max(1, int(round(freeze * edge)))
        up = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, ramp + 1) / (ramp + 1))
        a = np.zeros(length)
        a[:freeze] = 1.0
        a[:ramp] = up
        a[freeze - ramp:freeze] = np.minimum(a[freeze - ramp:freeze], up[::-1])
        b = np.zeros(length)
        b[freeze:] = np.sin(np.pi * np.arange(1, length - freeze + 1) / (length - freeze + 1)) ** 2
        v = 1.0 - depth * a + depth * a.sum() / b.sum() * b  # stall, then a burst that recovers the lag
        tau = start + np.concatenate([[0.0], np.cumsum(v)[:-1]])
        new = _sample(x, dirs, lengths[start:start + length], tau)
        disp = np.linalg.norm(new - x[start:start + length], axis=-1).mean()
        if disp <= cap or depth < 0.3:
            break
        if freeze > 5:
            freeze -= 1
        else:
            depth *= 0.85
    out = x.copy()
    out[start + 1:start + length] = new[1:]
    return out.astype(np.float32)


MECHANISMS = {"wrong_limb_pose": wrong_limb_pose, "freeze_catch_up": freeze_catch_up,
              **blind_ground_mechanisms.MECHANISMS, **blind_timing_mechanisms.MECHANISMS,
              **blind_gait_mechanisms.MECHANISMS}
