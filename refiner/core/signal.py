"""Small pure functions on frame sequences: ramps, resampling, linear in-filling, overlapping windows."""
from __future__ import annotations

import numpy as np

__all__ = ["smoothstep", "resample", "linear_infill", "window_starts"]


def smoothstep(u):
    """``3u² - 2u³`` of ``u`` clipped to [0, 1]: a 0 -> 1 ramp with zero slope at both ends."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def resample(x: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Frames at fractional times ``src`` by linear interpolation, ``(len(src), J, 3)``."""
    src = np.clip(src, 0.0, len(x) - 1.0)
    i0 = np.floor(src).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(x) - 1)
    frac = (src - i0)[:, None, None]
    return (1.0 - frac) * x[i0] + frac * x[i1]


def linear_infill(x: np.ndarray, hide: np.ndarray) -> np.ndarray:
    """Replace the ``hide`` frames of ``x (T, J, 3)`` by linear interpolation between the nearest kept
    frames (held constant past the clip's ends); every frame hidden -> unchanged."""
    keep = np.flatnonzero(~hide)
    if keep.size == 0 or keep.size == len(x):
        return x.copy()
    t = np.arange(len(x))
    flat = x.reshape(len(x), -1)
    out = np.empty_like(flat)
    for d in range(flat.shape[1]):
        out[:, d] = np.interp(t, keep, flat[keep, d])
    return out.reshape(x.shape).astype(x.dtype)


def window_starts(n_frames: int, size: int, stride: int) -> list[int]:
    """Starts of overlapping windows of ``size`` frames covering ``n_frames`` (the last one flush with the end)."""
    if n_frames <= size:
        return [0]
    starts = list(range(0, n_frames - size + 1, stride))
    if starts[-1] != n_frames - size:
        starts.append(n_frames - size)
    return starts
