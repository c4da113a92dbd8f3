"""Blind timing flaw mechanisms: stutters, tempo drift and dropped frames, made by re-timing a clip.

Written from a description of how 3D human-motion generators (diffusion models such as MDM, VAEs such as
ACTOR / Action2Motion, autoregressive models) get the *timing* of motion wrong, without looking at how any refiner
detects it. Each maps a clean HumanAct12 clip ``(T, 24, 3)`` (metres, y down, facing -z, 20 fps) to a new float32
copy that differs from it only inside one random window of 8-30 frames; the input is never modified.

Inside the window, output frame ``t`` shows the clip at a warped time ``tau(t) = t + lag(t)``; the lag is zero
just before and just after the window, so the motion leaves and rejoins its own timeline (the warp is built from
per-frame playback speeds whose extra over 1 sums to zero). A pose at a fractional time is interpolated so that
bone lengths are kept: root position linearly, every bone's direction by slerp between the two neighbouring
frames, and each bone given the length it has in the output frame's own original pose - every frame keeps its
own bone lengths exactly (tempo_drift's residual noise is a small rotation of bones, which keeps them too).
Windows are placed preferably where the body moves, since re-timing a still stretch changes nothing visible.
``severity`` scales the time warp (0 leaves the clip unchanged); the window does not depend on it.
"""
from __future__ import annotations

import numpy as np

from refiner.evaluation.blind_geometry import (PARENTS as _PARENTS, bones as _bones, rotate as _rotate, slerp as _slerp,
                                               unit as _unit)

__all__ = ["MECHANISMS", "stutter", "tempo_drift", "dropped_frames_crawl"]

_MAX_WINDOW = 30


def _window_start(x: np.ndarray, length: int, margin: int, rng: np.random.Generator) -> int:
    """Start of a ``length``-frame window leaving the first and last frame (and ``margin`` more) untouched,
    drawn with weight on how much the body moves in it."""
    n = len(x)
    energy = np.append(np.linalg.norm(np.diff(x, axis=0), axis=-1).mean(1), 0.0)
    starts = np.arange(1 + margin, n - length - margin)
    if starts.size == 0:  # a short clip: the warp may then be clipped at the clip's ends
        starts = np.arange(1, n - length)
    e = np.convolve(energy, np.ones(length), "valid")[starts]
    p = e + 0.1 * e.mean() + 1e-12  # still stretches stay possible, just rarer
    return int(rng.choice(starts, p=p / p.sum()))


def _retime(x: np.ndarray, extra: np.ndarray, rng: np.random.Generator, margin: int = 0, wobble=None):
    """The clip re-timed inside one window: ``extra`` ``(L+1,)`` is each step's playback speed minus 1 (step k
    goes from window frame k-1 to k; the last step rejoins the timeline), ``wobble`` ``(L, J, 3)`` optional
    small bone rotation vectors (radians). Returns float32 ``(T, J, 3)``."""
    lag = np.cumsum(extra)[:-1]  # frames each window frame is behind (<0) or ahead (>0) of its own time
    length = len(lag)
    start = _window_start(x, length, margin, rng)
    tau = np.clip(start + np.arange(length) + lag, 0.0, len(x) - 1.0)
    dirs, lengths = _bones(x)
    i0 = np.clip(np.floor(tau).astype(int), 0, len(x) - 2)
    f = tau - i0
    d = _slerp(dirs[i0], dirs[i0 + 1], np.broadcast_to(f[:, None], dirs[i0].shape[:-1]))
    if wobble is not None:
        angle = np.linalg.norm(wobble, axis=-1)
        d = _rotate(d, _unit(wobble), angle)
    new = np.zeros((length,) + x.shape[1:])
    new[:, 0] = x[i0, 0] * (1.0 - f)[:, None] + x[i0 + 1, 0] * f[:, None]
    own = lengths[start:start + length]  # each output frame keeps its own bone lengths
    for j in range(1, x.shape[1]):  # parents come first
        new[:, j] = new[:, _PARENTS[j]] + own[:, j, None] * d[:, j]
    out = x.copy()
    out[start:start + length] = new
    return out.astype(np.float32)


def _bump(n: int) -> np.ndarray:
    """A sin^2 bump ``(n,)`` summing to 1, zero just outside both ends: a smooth burst of extra speed."""
    b = np.sin(np.pi * np.arange(1, n + 1) / (n + 1)) ** 2
    return b / b.sum()


def stutter(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a playback hitch: the motion briefly runs a few frames backwards, replays them and goes on.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside an 8-30 frame window. At its start
    the clip plays backwards for 1-3 frames at 0.6-1.2 times normal speed (a reversal, as an autoregressive or
    windowed-diffusion generator makes when a new chunk starts from a slightly earlier pose), then forward again
    at normal speed for 1-3 frames, replaying the reversed poses; 35 % of the time a second such hitch follows.
    The lag this builds (about 2-13 frames) is made up by a smooth sin^2 burst of speed over the rest of the
    window (1.5-3 times the lag in frames), so the clip rejoins its own timeline. ``severity`` scales every
    frame's speed change (below about 0.6 the reversal becomes a slow hitch). Bone lengths are kept exactly.
    """
    x = np.array(clip, dtype=np.float64)
    cap = min(_MAX_WINDOW, len(x) - 2)
    hitch: list[float] = []
    for _ in range(1 + int(rng.random() < 0.35)):
        back, rate = int(rng.integers(1, 4)), rng.uniform(0.6, 1.2)
        hitch += [-(1.0 + rate)] * back + [0.0] * int(rng.integers(1, 4))  # backwards, then replayed forwards
    lag = -sum(hitch)
    catch = int(np.clip(round(lag * rng.uniform(1.5, 3.0)), max(4, 9 - len(hitch)), cap + 1 - len(hitch)))
    extra = np.concatenate([hitch, lag * _bump(catch)]) * severity
    return _retime(x, extra, rng, margin=8)  # room for the reversal to reach back before the window


def tempo_drift(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates a tempo drift: a stretch eases into near-still slow motion, then the clip speeds up to catch up.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside an 8-30 frame window. Playback speed
    eases down (raised cosine over 30-50 % of a 6-18 frame slow stretch, the way a diffusion or VAE generator
    loses tempo rather than freezing) to 8-30 % of normal, holds, eases back over 15-30 % of it, and a smooth
    sin^2 burst over the next 50-90 % as many frames (at least 4) recovers exactly the lost time. It is never a
    hard freeze: the speed stays at least 3 % and each bone keeps a small residual wobble (smoothed random
    rotations of 0.3-1.0 degrees RMS, times ``severity``, faded with the slowdown). ``severity`` scales the
    slowdown (capped at 97 %) and the wobble. Bone lengths are kept exactly.
    """
    x = np.array(clip, dtype=np.float64)
    cap = min(_MAX_WINDOW, len(x) - 2)
    slow = min(int(rng.integers(6, 19)), cap - 3)
    fast = int(np.clip(round(slow * rng.uniform(0.5, 0.9)), 4, cap + 1 - slow))
    floor = rng.uniform(0.08, 0.3)
    r_in, r_out = (max(2, int(round(slow * rng.uniform(lo, hi)))) for lo, hi in ((0.3, 0.5), (0.15, 0.3)))
    k = np.arange(slow)
    ease = lambda z, r: 0.5 - 0.5 * np.cos(np.pi * np.clip(z / (r + 1), 0.0, 1.0))  # noqa: E731
    a = np.minimum(ease(k + 1.0, r_in), ease(slow - k, r_out))  # (slow,) in (0, 1]: the slowdown's shape
    depth = min((1.0 - floor) * severity, 0.97)
    extra = np.concatenate([-depth * a, depth * a.sum() * _bump(fast)])
    length = slow + fast - 1
    sigma = np.deg2rad(rng.uniform(0.3, 1.0)) * severity / np.sqrt(3.0)  # per axis
    pad, width = 4, rng.uniform(0.7, 2.0)
    kern = np.exp(-0.5 * (np.arange(-pad, pad + 1) / width) ** 2)
    kern /= np.sqrt((kern * kern).sum())  # unit variance kept
    white = rng.standard_normal((length + 2 * pad, x.shape[1], 3))
    noise = sum(w * white[i:i + length] for i, w in enumerate(kern))  # smooth residual wobble, not white jitter
    fade = np.zeros(length)
    fade[:slow] = a[:length]
    return _retime(x, extra, rng, wobble=sigma * fade[:, None, None] * noise)


def dropped_frames_crawl(clip: np.ndarray, rng: np.random.Generator, severity: float = 1.0) -> np.ndarray:
    """Imitates dropped frames: the motion jumps a few frames ahead, then crawls until its timeline catches up.

    ``clip`` ``(T, 24, 3)`` metres -> ``(T, 24, 3)`` float32, changed inside an 8-30 frame window. At its start
    2.5-7 frames (times ``severity``) are skipped in one step (70 %) or two; then, instead of a hard wait, the
    clip plays slowly, at a speed rising from its slowest (10-50 % of normal at severity 1) back to normal along
    ``1 - c (1 - s)^p`` (``s`` the share of the crawl done, ``p`` 0.3-1.5: from a near-constant crawl that
    resumes abruptly to one that quickly eases back), over as many frames as recover exactly the skipped time.
    ``severity`` scales the skip; the crawl's slowest speed is kept at least 5 % (never a hard wait).
    Bone lengths are kept exactly.
    """
    x = np.array(clip, dtype=np.float64)
    cap = min(_MAX_WINDOW, len(x) - 2)
    skip, slowest, power = rng.uniform(2.5, 7.0), rng.uniform(0.1, 0.5), rng.uniform(0.3, 1.5)
    jump = 1 + int(rng.random() < 0.3)
    crawl = int(np.clip(round(skip * (power + 1.0) / (1.0 - slowest)), 9 - jump, cap + 1 - jump))
    h = (1.0 - (np.arange(crawl) + 0.5) / crawl) ** power  # (crawl,) share of the slowdown left at each step
    c = min(skip * severity / h.sum(), 0.95)  # the slowest speed stays at least 5 %
    extra = np.concatenate([np.full(jump, c * h.sum() / jump), -c * h])
    return _retime(x, extra, rng)


MECHANISMS = {
    "stutter": stutter,
    "tempo_drift": tempo_drift,
    "dropped_frames_crawl": dropped_frames_crawl,
}
