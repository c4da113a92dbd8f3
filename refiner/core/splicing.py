"""Do no harm: a change is spliced in without jumps, and changed frames go back on the input's bones.

Every change is spliced in as a displacement that is zero at the kept frames on both sides and tapered
with a smoothstep, so position *and* velocity are continuous where refined frames meet kept ones;
changed frames are then put back on the input's bone lengths.
"""
from __future__ import annotations

import numpy as np

from refiner.core.signal import smoothstep
from refiner.core.skeletons import joint_bone_lengths, with_bone_lengths

__all__ = ["splice", "project_bone_lengths", "reference_lengths"]


def splice(original: np.ndarray, proposal: np.ndarray, lo: int, hi: int, *, blend: int = 4,
           keep_start: bool = True, keep_end: bool = True) -> np.ndarray:
    """Replace frames ``lo..hi-1`` of ``original`` by ``proposal`` without jumps.

    The displacement ``proposal - original`` is corrected linearly so it is zero at the kept
    frames ``lo - 1`` and ``hi`` (when ``keep_start`` / ``keep_end``), then tapered over ``blend``
    frames at each kept side, so position and velocity are continuous there.

    Parameters
    ----------
    original, proposal : ndarray (T, J, 3)
    lo, hi : int
        Changed frames ``lo <= t < hi``.
    """
    out = original.copy()
    a, b = (lo - 1 if keep_start else lo), (hi if keep_end else hi - 1)
    a, b = max(a, 0), min(b, len(original) - 1)
    disp = (proposal[a : b + 1] - original[a : b + 1]).astype(np.float64)
    n = len(disp)
    tau = np.linspace(0.0, 1.0, n)[:, None, None]
    start_fix = disp[0] if keep_start and lo > 0 else 0.0
    end_fix = disp[-1] if keep_end and hi < len(original) else 0.0
    disp = disp - (1 - tau) * start_fix - tau * end_fix
    w = np.ones(n)
    m = min(blend, (n - 1) // 2)
    if keep_start and lo > 0 and m > 0:
        w[1 : m + 1] = np.minimum(w[1 : m + 1], smoothstep(np.arange(1, m + 1) / (m + 1)))
        w[0] = 0.0
    if keep_end and hi < len(original) and m > 0:
        w[n - 1 - m : n - 1] = np.minimum(w[n - 1 - m : n - 1], smoothstep(np.arange(1, m + 1) / (m + 1))[::-1])
        w[-1] = 0.0
    out[a : b + 1] = original[a : b + 1] + (w[:, None, None] * disp).astype(original.dtype)
    return out


def project_bone_lengths(joints: np.ndarray, lengths: np.ndarray, frames: np.ndarray, skeleton="humanact12") -> np.ndarray:
    """Put ``frames`` of ``joints`` ``(T, J, 3)`` on the given bone lengths, keeping the root and bone directions.

    ``lengths`` is ``(T, J)``: the length of the bone ending at each joint (the root's is unused).
    """
    out = joints.copy()
    out[frames] = with_bone_lengths(joints[frames], lengths[frames], skeleton)
    return out


def reference_lengths(x: np.ndarray, skeleton: str) -> np.ndarray:
    """Bone lengths ``(T, J)`` to restore: where a bone's length is constant over the clip (spread
    under 2 %, as in mocap) its median, so a distorted frame goes back to the true length; elsewhere
    (generators whose bones stretch) each frame's own length."""
    lengths = joint_bone_lengths(x, skeleton)  # (T, J)
    median = np.median(lengths, axis=0)
    rigid = lengths.std(0) < 0.02 * np.maximum(median, 1e-9)
    return np.where(rigid, median, lengths)
