"""Spline segmentation of motion clips by dynamic programming (paper §3.1.1, Eq. 2).

``Error_n = min_k [Error_k + fit(P[k:n]) + penalty]`` where ``fit`` is the squared residual of one
least-squares cubic per joint and axis over frames ``k..n`` (both ends included: neighbouring
transitions share their anchor frame).

Units: ``fit`` is the squared joint-position error in **cm², summed over frames and averaged over
joints** (sum of squared per-axis residuals / J), so ``penalty`` (the paper's λ) is in cm² per
joint. With that unit the paper's λ = 100 gives exactly its Table 2 fitting error on HumanAct12
(0.89 cm MPJPE); a unit without the joint average needs λ 24 times larger for the same cut.
See ``motion-refiner bench concepts`` for the λ table.

The fit costs of all ``(k, n)`` pairs come in closed form from running sums: for a start ``k``,
prefix sums of ``t**p * y`` over the rest of the clip give every normal equation at once, so there
is no per-pair fit.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np

from refiner.concepts.splines import eval_spline, fit_spline
from refiner.core.validation import check_joints

__all__ = ["Segmentation", "segment", "fit_costs", "DEFAULT_PENALTY", "MIN_DURATION"]

#: λ in cm², chosen by ``motion-refiner bench concepts`` (see README).
DEFAULT_PENALTY = 200.0
#: Shortest transition in frame intervals: a cubic needs 4 frames to be a fit, not an interpolation.
MIN_DURATION = 3


@dataclass(frozen=True)
class Segmentation:
    """A clip cut into cubic-spline transitions.

    Attributes
    ----------
    anchors : ndarray of int, shape (K,)
        Anchor frames in increasing order: first frame, junctions, last frame.
    coeffs : ndarray of shape (K-1, 4, J, 3), float32
        Spline coefficients of every transition (``refiner.concepts.splines`` convention), metres.
    fit_cost : float
        Sum of squared fit residuals over frames, averaged over joints, cm².
    penalty : float
        λ used, cm² per joint.
    """

    anchors: np.ndarray
    coeffs: np.ndarray
    fit_cost: float
    penalty: float

    @property
    def n_transitions(self) -> int:
        return len(self.anchors) - 1

    @property
    def durations(self) -> np.ndarray:
        """Frame intervals of each transition, ``(K-1,)``."""
        return np.diff(self.anchors)

    @property
    def n_frames(self) -> int:
        return int(self.anchors[-1]) + 1

    @property
    def cost(self) -> float:
        """The DP objective: fit cost plus λ per transition."""
        return self.fit_cost + self.penalty * self.n_transitions

    def anchor_mask(self) -> np.ndarray:
        """Boolean ``(T,)``, True at anchor frames."""
        mask = np.zeros(self.n_frames, dtype=bool)
        mask[self.anchors] = True
        return mask

    def reconstruct(self) -> np.ndarray:
        """The clip as its splines, ``(T, J, 3)`` float32.

        Each transition gives its frames ``k..n-1``; the last one also gives the final frame.
        """
        parts = []
        for i, (k, n) in enumerate(zip(self.anchors[:-1], self.anchors[1:])):
            frames = eval_spline(self.coeffs[i], int(n - k) + 1)
            parts.append(frames if i == self.n_transitions - 1 else frames[:-1])
        return np.concatenate(parts).astype(np.float32)


def segment(
    joints,
    *,
    penalty: float = DEFAULT_PENALTY,
    min_duration: int = MIN_DURATION,
    max_duration: int | None = None,
) -> Segmentation:
    """Cut a clip into cubic-spline transitions by dynamic programming (Eq. 2).

    Parameters
    ----------
    joints : array-like of shape (T, J, 3)
        Joint positions in metres, T >= ``min_duration + 1``.
    penalty : float, default=200.0
        λ, the cost of one more transition, in cm² per joint (see module docstring). ``inf`` gives one
        transition.
    min_duration, max_duration : int
        Bounds on a transition's length in frame intervals.

    Returns
    -------
    Segmentation

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 40)[:, None, None]
    >>> clip = np.concatenate([t**3, t**2, t], axis=2).repeat(24, axis=1)   # one cubic
    >>> segment(clip).anchors.tolist()
    [0, 39]
    """
    if not isinstance(min_duration, (int, np.integer)) or min_duration < 1:
        raise ValueError(f"`min_duration` must be a positive int; got {min_duration!r}.")
    if max_duration is not None and (not isinstance(max_duration, (int, np.integer)) or max_duration < min_duration):
        raise ValueError(f"`max_duration` must be an int >= min_duration={min_duration}; got {max_duration!r}.")
    try:
        penalty = float(penalty)
    except (TypeError, ValueError):
        raise ValueError(f"`penalty` must be a non-negative number; got {penalty!r}.") from None
    if not penalty >= 0:
        raise ValueError(f"`penalty` must be a non-negative number; got {penalty!r}.")
    x = check_joints(joints, name="joints", min_frames=min_duration + 1)
    costs = fit_costs(x, min_duration=min_duration, max_duration=max_duration)
    anchors, fit_cost = _dynamic_programming(costs, penalty)
    coeffs = np.stack([fit_spline(x[k : n + 1]) for k, n in zip(anchors[:-1], anchors[1:])])
    return Segmentation(anchors, coeffs, fit_cost, penalty)


def fit_costs(joints, *, min_duration: int = MIN_DURATION, max_duration: int | None = None) -> np.ndarray:
    """Squared residual of the least-squares cubic over every frame range.

    Parameters
    ----------
    joints : ndarray of shape (T, J, 3), metres

    Returns
    -------
    ndarray of shape (T, T), float64, cm² per joint
        ``C[k, n]`` = fit cost of frames ``k..n``; ``inf`` where ``n - k`` is outside
        ``[min_duration, max_duration]``.
    """
    n_joints = np.shape(joints)[1]
    y = np.asarray(joints, dtype=np.float64).reshape(len(joints), -1) * 100.0  # cm
    n_frames = len(y)
    costs = np.full((n_frames, n_frames), np.inf)
    ginv = _gram_inverse(n_frames)  # (T, 4, 4): inverse normal matrix of frames 0..l
    powers = np.arange(n_frames, dtype=np.float64)[:, None] ** np.arange(4)  # (T, 4)
    for k in range(n_frames - min_duration):
        stop = n_frames if max_duration is None else min(n_frames, k + max_duration + 1)
        z = y[k:stop] - y[k]  # local offsets keep the sums small (less cancellation)
        length = len(z)
        b = np.cumsum(powers[:length, :, None] * z[:, None, :], axis=0)  # (L, 4, D)
        sq = np.cumsum(np.einsum("ld,ld->l", z, z))
        quad = np.einsum("lpd,lpd->l", ginv[:length] @ b, b)
        sse = np.maximum(sq - quad, 0.0)
        costs[k, k + min_duration : stop] = sse[min_duration:] / n_joints
    return costs


def _dynamic_programming(costs: np.ndarray, penalty: float) -> tuple[np.ndarray, float]:
    """Eq. 2 over a cost table; returns the anchors and the fit cost of the optimum."""
    n_frames = len(costs)
    best = np.full(n_frames, np.inf)
    best[0] = 0.0
    back = np.zeros(n_frames, dtype=np.int64)
    for n in range(1, n_frames):
        total = best[:n] + costs[:n, n]
        k = int(np.argmin(total))
        best[n], back[n] = total[k] + penalty, k
    anchors = [n_frames - 1]
    while anchors[-1] != 0:
        anchors.append(int(back[anchors[-1]]))
    anchors = np.array(anchors[::-1], dtype=np.int64)
    fit_cost = float(sum(costs[k, n] for k, n in zip(anchors[:-1], anchors[1:])))
    return anchors, fit_cost


@lru_cache(maxsize=8)
def _gram_inverse(n_frames: int) -> np.ndarray:
    """Inverse of ``sum_{t=0..l} [t^p t^q]`` for every l, computed in scaled time for accuracy."""
    t = np.arange(n_frames, dtype=np.float64)
    moments = np.cumsum(t[:, None] ** np.arange(7), axis=0)  # (T, 7)
    p = np.arange(4)
    gram = moments[:, p[:, None] + p[None, :]]  # (T, 4, 4)
    inv = np.full_like(gram, np.nan)
    scale = np.maximum(t, 1.0)[:, None] ** -p  # diag(l^-p) keeps the scaled Gram well conditioned
    scaled = gram * scale[:, :, None] * scale[:, None, :]
    ok = t >= 3  # at least 4 frames for a unique cubic
    inv[ok] = np.linalg.inv(scaled[ok]) * scale[ok][:, :, None] * scale[ok][:, None, :]
    inv.flags.writeable = False
    return inv


def _segment_naive(joints, *, penalty: float, min_duration: int = MIN_DURATION) -> tuple[np.ndarray, float]:
    """Brute force over every set of cut points, one ``np.polyfit`` per transition (tests only)."""
    y = np.asarray(joints, dtype=np.float64).reshape(len(joints), -1) * 100.0
    y = y / np.sqrt(np.shape(joints)[1])  # cost per joint, as in fit_costs
    n_frames = len(y)
    best = (np.inf, None)
    inner = range(1, n_frames - 1)
    for n_cuts in range(0, n_frames):
        for cuts in combinations(inner, n_cuts):
            anchors = (0, *cuts, n_frames - 1)
            if min(np.diff(anchors)) < min_duration:
                continue
            total = 0.0
            for k, n in zip(anchors[:-1], anchors[1:]):
                t = np.arange(n - k + 1, dtype=np.float64)
                _, res, *_ = np.polyfit(t, y[k : n + 1], 3, full=True)
                total += float(res.sum()) if res.size else 0.0
            total += penalty * (len(anchors) - 1)
            if total < best[0] - 1e-9:
                best = (total, np.array(anchors))
    return best[1], best[0]
