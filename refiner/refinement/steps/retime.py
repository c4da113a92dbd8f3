"""Re-timing: each flagged run of frames played again along its own path at an even pace (the paper's transition
re-timing), kept where verified.

Generators stall, skip ahead and catch up: the poses are right and their timing is wrong. ``detect`` and ``verify``
are the motion model's (:class:`~refiner.refinement.steps.infill.InfillStep`); ``propose`` re-samples the frames of
each flagged run, between the kept frames that bound it, at even steps of the body's path length (mean joint
displacement); every frame keeps its own bone lengths. Chosen over the in-fill on the calibration subjects (``docs/decisions.md`` D20).
A flagged run first grows over the frames next to it in which the body stands stiller than real capture does
(``still_m``, calibrated on clean clips): a freeze is where the lost time went, so it belongs to the run (D27). A
freeze the detector missed is flagged too where a jump near it makes up the time it lost (:func:`caught_up_freezes`, D29).
"""
from __future__ import annotations

import numpy as np

from refiner.concepts.transitions import arc_length_profile
from refiner.core.bone_directions import from_bone_directions, retimed, to_bone_directions
from refiner.core.skeletons import get_skeleton
from refiner.refinement.steps.base import runs
from refiner.refinement.steps.infill import InfillStep

__all__ = ["RetimeStep", "even_pace", "pace", "still_grown", "caught_up_freezes", "calibrated_stillness"]


def even_pace(joints, frames, skeleton) -> np.ndarray:
    """``joints (T, J, 3)`` metres with each run of ``frames (T,)`` bool re-timed so that the body covers its path from
    the kept frame before the run to the kept frame after it in equal steps (poses taken from the path, bone lengths
    each frame's own); other frames exactly as given."""
    x = np.asarray(joints, dtype=np.float64)
    out = x.copy()
    root, lengths = get_skeleton(skeleton).root, to_bone_directions(x, skeleton)[2]
    for s, e in runs(frames):
        a, b = max(s - 1, 0), min(e, len(x) - 1)
        if b - a < 2 or not (x[a + 1:b + 1] != x[a]).any():  # nothing to pace, or the body stands still
            continue
        path = arc_length_profile(x[a:b + 1])
        times = np.interp(np.linspace(0.0, 1.0, b - a + 1), path, np.arange(a, b + 1, dtype=np.float64))
        moved = retimed(x, times[1:-1], skeleton)
        _, dirs, _ = to_bone_directions(moved, skeleton)  # each frame keeps its own bone lengths
        out[a + 1:b] = from_bone_directions(moved[:, root], dirs, lengths[a + 1:b], skeleton)
    return out


def pace(joints) -> np.ndarray:
    """``joints (..., T, J, 3)`` metres -> ``(..., T)`` metres per frame: the mean joint displacement from the frame
    before (frame 0: infinite, it has none)."""
    x = np.asarray(joints, dtype=np.float64)
    d = np.diff(x, axis=-3)
    step = np.sqrt(np.einsum("...i,...i->...", d, d)).mean(-1)
    return np.concatenate([np.full(step.shape[:-1] + (1,), np.inf), step], -1)


def still_grown(joints, frames, still_m: float) -> np.ndarray:
    """``frames (..., T)`` bool with every run grown back and forward over the frames next to it whose :func:`pace`
    is below ``still_m`` (the body stands stiller than that); growth stops short of the first and last frame."""
    f = np.asarray(frames, bool)
    p = pace(joints).reshape(-1, f.shape[-1])
    out = f.reshape(-1, f.shape[-1]).copy()
    n = out.shape[-1]
    for i in np.flatnonzero(out.any(-1)):
        still = p[i] < still_m
        for s, e in runs(f.reshape(out.shape)[i]):
            while s > 1 and still[s - 1]:
                s -= 1
            while e < n - 1 and still[e]:
                e += 1
            out[i, s:e] = True
    return out.reshape(f.shape)


def caught_up_freezes(joints, still_m: float, min_run: int = 2) -> np.ndarray:
    """``joints (..., T, J, 3)`` -> ``(..., T)`` bool: each run of ``min_run`` or more frames stiller than ``still_m``
    (see :func:`still_grown`) that a jump near it catches up, with the frames between them. The jump is the fastest
    frame within twice the freeze's length of it; its step beyond the faster of the steps beside it must cover at least
    half the path the body would have travelled during the freeze at its usual pace (the median pace of the moving
    frames that near), as a body that froze and then caught up does; the first and last frame stay out."""
    x = np.asarray(joints, dtype=np.float64)
    p = pace(x).reshape(-1, x.shape[-3])
    out, still = np.zeros(p.shape, bool), p < still_m
    n_frames = p.shape[-1]
    paired = still[:, 1:] & still[:, :-1] if min_run > 1 else still
    for i in np.flatnonzero(paired.any(-1)):  # most clips have no freeze to look at
        q = p[i]
        for a, b in runs(still[i]):
            n = b - a
            near = np.r_[max(1, a - 2 * n - 1):a, b:min(n_frames, b + 2 * n + 1)]
            moving = q[near][q[near] >= still_m]
            if n < min_run or not len(moving):
                continue
            jump = int(near[np.argmax(q[near])])
            beside = q[[t for t in (jump - 1, jump + 1) if 1 <= t < n_frames]].max()
            if q[jump] - beside >= np.median(moving) * n / 2:  # a jump, not the top of a ramp
                out[i, max(1, min(jump, a)):min(n_frames - 1, max(jump, b - 1) + 1)] = True
    return out.reshape(x.shape[:-2])


def calibrated_stillness(clips, *, share: float = 0.01) -> float:
    """``still_m``: the pace (metres per frame) that only ``share`` of the frames of the clean ``clips ((T, J, 3)
    metres each, real, unseen by the model)`` stay below: real capture never stands stiller than that."""
    return float(np.quantile(np.concatenate([pace(c)[1:] for c in clips]), share))


class RetimeStep(InfillStep):
    """The motion model's detect / verify around :func:`even_pace` (see the module docstring)."""

    name = "retime"
    moves_whole_body = True

    def detect(self, clips, actions) -> tuple[np.ndarray, np.ndarray]:
        """The motion model's flags (:meth:`InfillStep.detect`) and, where ``still_m`` is set, the
        :func:`caught_up_freezes`, each run grown over the still frames next to it (:func:`still_grown`); frames the
        model did not flag are flagged for every part."""
        prob, flagged = super().detect(clips, actions)
        if self.config.still_m > 0:
            seeds = flagged.any(-1) | caught_up_freezes(clips, self.config.still_m, self.config.min_run)
            grown = still_grown(clips, seeds, self.config.still_m)
            flagged |= (grown & ~flagged.any(-1))[..., None]
        return prob, flagged

    def verify(self, given, proposed, actions, flagged, probability) -> tuple[np.ndarray, list[list[dict]]]:
        """:meth:`InfillStep.verify`; each entry also counts the run's ``still_frames`` (stiller than ``still_m``), so
        the report can say that a freeze was re-timed."""
        out, changes = super().verify(given, proposed, actions, flagged, probability)
        if self.config.still_m > 0:
            still = pace(given) < self.config.still_m
            for i, entries in enumerate(changes):
                for e in entries:
                    e["still_frames"] = int(still[i, e["start"]:e["stop"]].sum())
        return out, changes

    def propose(self, clips, actions, flagged, infill=None) -> np.ndarray:
        """The clips with each run of flagged frames (any part) re-timed by :func:`even_pace`; ``infill``, given, makes
        this the in-fill's proposal instead (the benchmark's stand-ins)."""
        if infill is not None:
            return super().propose(clips, actions, flagged, infill=infill)
        return np.stack([even_pace(c, f.any(1), self.model.skeleton) for c, f in zip(clips, flagged)])
