"""Candidate repairs of one flagged run of frames, for the learned pipeline's selection step.

Each function takes a clip ``y (T, J, 3)`` metres and a flagged run ``[lo, hi)`` and returns a new
clip in which only those frames differ. They encode what a flaw of each kind needs, so that the
refiner can choose, per run, the candidate that its flaw classifier finds most real:

- :func:`retime_run`: the frames keep their path but are re-timed along it with a speed that
  joins the neighbours' speeds smoothly (stalls, rushes, warped timing);
- :func:`forward_retime_run`: the same along the run's *progress* toward its end pose, so motion
  that goes back and forth is replayed forward only (reversals);
- :func:`smooth_run`: Gaussian smoothing in time (jitter, bursts);
- :func:`root_infill_run`: the root path is linearly in-filled and the pose kept (the whole body
  floating or gliding).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from refiner.transitions import arc_length_profile

__all__ = ["retime_run", "forward_retime_run", "smooth_run", "root_infill_run", "CANDIDATES"]


def _bounds(n: int, lo: int, hi: int) -> tuple[int, int]:
    """Kept frames on each side of the run (or the run's own ends at the clip's edges)."""
    return max(lo - 1, 0), min(hi, n - 1)


def _speed_profile(y: np.ndarray, a: int, b: int, length: float) -> np.ndarray:
    """Cumulative share of ``length`` covered at frames ``a..b``: a cubic Hermite curve whose slopes
    are the mean-joint speeds just outside the run, made non-decreasing."""
    n_steps = b - a
    v0 = np.linalg.norm(y[a] - y[a - 1], axis=-1).mean() if a > 0 else length / max(n_steps, 1)
    v1 = np.linalg.norm(y[b + 1] - y[b], axis=-1).mean() if b + 1 < len(y) else length / max(n_steps, 1)
    tau = np.linspace(0.0, 1.0, n_steps + 1)
    s = ((-2 * tau**3 + 3 * tau**2) * length + (tau**3 - 2 * tau**2 + tau) * v0 * n_steps
         + (tau**3 - tau**2) * v1 * n_steps)
    s = np.maximum.accumulate(np.clip(s, 0.0, length))
    return s / length if length > 1e-9 else tau


def _resample_path(frames: np.ndarray, progress: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Frames at the times where the non-decreasing ``progress (L,)`` reaches ``target (L,)``."""
    progress = progress + np.arange(len(progress)) * 1e-9  # strictly increasing for interpolation
    idx = np.interp(target * progress[-1], progress, np.arange(len(frames)))
    i0 = np.floor(idx).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(frames) - 1)
    w = (idx - i0)[:, None, None]
    return frames[i0] * (1 - w) + frames[i1] * w


def retime_run(y: np.ndarray, lo: int, hi: int, root: int = 0) -> np.ndarray:
    """Re-time frames ``lo..hi-1`` along their own path (arc length) with a smooth speed profile."""
    a, b = _bounds(len(y), lo, hi)
    if b - a < 2:
        return y.copy()
    frames = y[a : b + 1].astype(np.float64)
    s = arc_length_profile(frames)
    length = float(np.linalg.norm(np.diff(frames, axis=0), axis=-1).mean(-1).sum())
    out = y.copy()
    out[a : b + 1] = _resample_path(frames, s, _speed_profile(y, a, b, length)).astype(y.dtype)
    out[a], out[b] = y[a], y[b]
    return out


def forward_retime_run(y: np.ndarray, lo: int, hi: int, root: int = 0) -> np.ndarray:
    """Re-time frames ``lo..hi-1`` by their progress from the first kept frame toward the last one
    (projection on that chord, kept only where it advances), with a smooth speed profile."""
    a, b = _bounds(len(y), lo, hi)
    if b - a < 2:
        return y.copy()
    frames = y[a : b + 1].astype(np.float64)
    chord = (frames[-1] - frames[0]).reshape(-1)
    norm2 = float(chord @ chord)
    if norm2 < 1e-8:
        return y.copy()
    u = ((frames - frames[0]).reshape(len(frames), -1) @ chord) / norm2
    progress = np.maximum.accumulate(np.clip(u, 0.0, 1.0))
    progress[-1] = 1.0
    length = float(np.sqrt(norm2 / frames.shape[1]))
    out = y.copy()
    out[a : b + 1] = _resample_path(frames, progress, _speed_profile(y, a, b, length)).astype(y.dtype)
    out[a], out[b] = y[a], y[b]
    return out


def smooth_run(y: np.ndarray, lo: int, hi: int, root: int = 0, sigma: float = 1.5) -> np.ndarray:
    """Frames ``lo..hi-1`` replaced by a Gaussian smoothing (``sigma`` frames) of the clip."""
    out = y.copy()
    out[lo:hi] = gaussian_filter1d(y.astype(np.float64), sigma, axis=0, mode="nearest")[lo:hi].astype(y.dtype)
    return out


def root_infill_run(y: np.ndarray, lo: int, hi: int, root: int = 0) -> np.ndarray:
    """Root path over ``lo..hi-1`` linearly in-filled between the kept frames; each frame's pose kept."""
    a, b = _bounds(len(y), lo, hi)
    out = y.copy()
    if b - a < 2:
        return out
    t = (np.arange(a, b + 1) - a) / (b - a)
    path = (1 - t)[:, None] * y[a, root] + t[:, None] * y[b, root]
    out[a : b + 1] = y[a : b + 1] - y[a : b + 1, root : root + 1] + path[:, None]
    return out.astype(y.dtype)


#: Hand-written candidates by name (the network's proposals join them in the pipeline).
CANDIDATES = {"retime": retime_run, "forward_retime": forward_retime_run, "smooth": smooth_run,
              "root_infill": root_infill_run}
