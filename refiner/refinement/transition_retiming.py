"""Transition refinement by re-timing (``Refiner(method="concepts", transition_method="retime")``).

A transition whose frames deviate from their least-squares cubic (:func:`spline_residual`) by more
than the threshold of its duration is flagged; it is re-timed along its own path with the speed
profile of its transition concept (the CVAE's transition between the same anchors, §3.1.3). Given the
flawed transition this cut frozen / reversed / time-warped errors from 7.8 / 6.7 / 5.8 cm to
2.4 / 4.0 / 4.8 cm, but the residual flags too few flawed and too many real transitions, so in the
full pipeline it cost 0.2 cm on clean clips for no gain: ``"network"`` is the default.
"""
from __future__ import annotations

import numpy as np

from refiner.concepts.splines import eval_spline, fit_spline
from refiner.concepts.transitions import arc_length_profile, retime

__all__ = ["TransitionRetimer", "spline_residual", "DURATION_BINS"]

#: Upper ends (frames) of the duration bins of the thresholds: longer transitions fit a cubic less tightly.
DURATION_BINS = (8, 16, 32, 64)
#: A duration bin needs this many calibration transitions; fewer join the next bin.
_MIN_PER_BIN = 20


def spline_residual(frames: np.ndarray) -> float:
    """MPJPE (metres) between a transition's frames ``(L, J, 3)`` and their least-squares cubic."""
    return float(np.linalg.norm(eval_spline(fit_spline(frames), len(frames)) - frames, axis=-1).mean())


class TransitionRetimer:
    """The re-timing transition step: flags by spline residual, proposes a re-timed transition.

    Attributes
    ----------
    thresholds_ : list of [frames, metres]
        Per duration bin, its upper end and the residual above which a transition that long is
        flagged (ascending; the last bin is open). Empty: nothing is flagged. Set by :meth:`calibrate`,
        or from a saved refiner's manifest (:meth:`from_calibration`).
    """

    def __init__(self):
        self.thresholds_: list[list[float]] = []

    @classmethod
    def from_calibration(cls, calibration: dict) -> "TransitionRetimer":
        """The step as a manifest's ``calibration`` entry describes it: ``transition_thresholds`` (bins) or
        ``transition_threshold`` (one value for every duration, set by hand)."""
        step = cls()
        if "transition_threshold" in calibration:
            step.thresholds_ = [[float("inf"), float(calibration["transition_threshold"])]]
        else:
            step.thresholds_ = [[float(u), float(t)] for u, t in calibration.get("transition_thresholds", [])]
        return step

    def to_calibration(self) -> dict:
        """The ``calibration`` entry of a manifest that :meth:`from_calibration` reads back."""
        return {"transition_thresholds": [list(b) for b in self.thresholds_]}

    def calibrate(self, clips, anchors, *, percentile: float = 1.0) -> list[list[float]]:
        """Per duration bin, the ``100 - percentile``-th percentile of the residuals of real transitions
        (``clips`` ``(T_i, J, 3)`` metres between their ``anchors``); returns ``thresholds_``."""
        durations, residuals = [], []
        for clip, a in zip(clips, anchors):
            x = np.asarray(clip, dtype=np.float32)
            durations.extend(np.diff(a))
            residuals.extend(spline_residual(x[a[m] : a[m + 1] + 1]) for m in range(len(a) - 1))
        durations, residuals = np.asarray(durations), np.asarray(residuals)
        bins = []
        lower = 0
        for upper in (*DURATION_BINS, np.inf):
            sel = (durations > lower) & (durations <= upper)
            if sel.sum() >= _MIN_PER_BIN or (upper == np.inf and sel.any()):
                bins.append([float(upper), float(np.percentile(residuals[sel], 100 - percentile))])
                lower = upper
        if bins:
            bins[-1][0] = float("inf")
        self.thresholds_ = bins
        return bins

    def threshold(self, duration: int) -> float:
        """The residual threshold (metres) of a transition of ``duration`` frame intervals."""
        for upper, value in self.thresholds_:
            if duration <= upper:
                return float(value)
        return float("inf")

    def detect(self, joints: np.ndarray, anchors) -> tuple[np.ndarray, np.ndarray]:
        """Residuals and thresholds ``(K - 1,)`` (metres) of the transitions of ``joints (T, J, 3)``
        between its ``anchors (K,)``; a transition is flagged where the residual is above its threshold."""
        residuals = np.array([spline_residual(joints[anchors[m] : anchors[m + 1] + 1]) for m in range(len(anchors) - 1)])
        return residuals, np.array([self.threshold(int(d)) for d in np.diff(anchors)])

    def propose(self, joints: np.ndarray, a: int, b: int, generator) -> np.ndarray:
        """``joints`` with the transition between anchor frames ``a`` and ``b`` re-timed along its own path
        with the speed profile of the transition ``generator`` (a fitted TransitionGenerator) gives them."""
        concept = generator.generate(joints[a][None], joints[b][None], [b - a])[0]
        proposal = joints.copy()
        proposal[a : b + 1] = retime(joints[a : b + 1], arc_length_profile(concept))
        return proposal
