"""Re-timing: each flagged run of frames played again along its own path at an even pace (the paper's transition
re-timing), kept where verified.

Generators stall, skip ahead and catch up: the poses are right and their timing is wrong. ``detect`` starts from the
motion model's flags (:class:`~refiner.refinement.steps.infill.InfillStep`) and adds the freezes it missed where a
jump near them catches up the time they lost (:func:`caught_up_freezes`, D29); every run then grows over the frames
beside it in which the body stands stiller than all but ``still_share`` of clean capture (``still_m``, calibrated on
clean clips): a freeze is where the lost time went, so it belongs to the run (D27). Only the runs in which the body
stands still somewhere are kept (:func:`holding_still`, D31): a run that never stops has lost no time, and re-timing
it would only move a pose flaw or natural motion along its path. ``propose`` re-samples the
frames of each run, between the kept frames that bound it, at even steps of the body's path length (mean joint
displacement); every frame keeps its own bone lengths. Chosen over the in-fill on the calibration subjects (D20).
``verify`` is the model's (:meth:`InfillStep.verify`), and counts each run's frozen frames for the report.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from refiner.concepts.transitions import arc_length_profile
from refiner.core.bone_directions import from_bone_directions, retimed, to_bone_directions
from refiner.core.signal import pace
from refiner.core.skeletons import get_skeleton
from refiner.refinement.steps.base import grown, runs
from refiner.refinement.steps.infill import InfillConfig, InfillStep

__all__ = ["RetimeConfig", "RetimeStep", "even_pace", "still_grown", "caught_up_freezes", "holding_still",
           "calibrated_stillness"]


@dataclass(frozen=True)
class RetimeConfig(InfillConfig):
    """Options of :class:`RetimeStep`: those of :class:`InfillConfig`, and for its freezes ``still_m`` (calibrated,
    the manifest's ``"retime"``: metres per frame; 0 leaves freezes alone, as an :class:`InfillConfig` does),
    ``freeze_frames`` (the fewest still steps a freeze the detector missed needs), ``reach`` (how far from such a
    freeze its jump may be, in freeze lengths) and ``catch_up`` (the share of the freeze's lost path the jump must
    make up)."""

    still_m: float = 0.0
    freeze_frames: int = 2
    reach: float = 2.0
    catch_up: float = 0.5

    def __post_init__(self):
        if not (math.isfinite(self.still_m) and self.still_m >= 0):
            raise ValueError(f"`still_m` must be a finite pace of 0 or more metres per frame; got {self.still_m}.")
        if self.freeze_frames < 1 or not self.reach > 0 or not self.catch_up > 0:
            raise ValueError("`freeze_frames` must be at least 1 and `reach` and `catch_up` above 0; got "
                             f"{self.freeze_frames}, {self.reach}, {self.catch_up}.")


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


def _frames_of(joints, frames) -> np.ndarray:
    f = np.asarray(frames, bool)
    if np.shape(joints)[:-2] != f.shape:
        raise ValueError(f"`frames` must be (..., T) as `joints` (..., T, J, 3); got {f.shape} and {np.shape(joints)}.")
    return f


def still_grown(joints, frames, still_m: float, *, speeds=None) -> np.ndarray:
    """``frames (..., T)`` bool with every run grown back and forward over the frames next to it whose :func:`pace`
    (``speeds``, when already computed) is below ``still_m``; growth stops short of the first and last frame."""
    f = _frames_of(joints, frames)
    n = f.shape[-1]
    p = (pace(joints) if speeds is None else np.asarray(speeds)).reshape(-1, n)
    given, out = f.reshape(-1, n), f.reshape(-1, n).copy()
    for i in np.flatnonzero(given.any(-1)):
        still = p[i] < still_m
        for s, e in runs(given[i]):
            s, e = grown(s, e, still)
            out[i, s:e] = True
    return out.reshape(f.shape)


def caught_up_freezes(joints, config: RetimeConfig, *, speeds=None) -> np.ndarray:
    """``joints (..., T, J, 3)`` -> ``(..., T)`` bool: the freezes that a jump near them catches up, from the jump to
    the freeze's last frame.

    A freeze is a run of ``config.freeze_frames`` or more frames whose :func:`pace` (``speeds``, when already
    computed) is below ``config.still_m``: ``n`` still steps, frames ``a .. a+n-1``, each as far as it got from the
    frame before (the frame before ``a`` is where it froze, and stays as given). Its jump is the fastest frame among
    the ``reach * n + 1`` frames before ``a`` and after the freeze (never frame 0); its step beyond the faster of the
    steps beside it must make up ``catch_up`` of the path the body would have travelled in those ``n`` steps at its
    usual pace (the median pace of the moving frames in that reach, the jump among them), as a body that froze and
    then caught up does. The first and last frame stay out."""
    x = np.asarray(joints, dtype=np.float64)
    n_frames = x.shape[-3] if x.ndim >= 3 else 0
    p = (pace(x) if speeds is None else np.asarray(speeds)).reshape(-1, n_frames)
    out, still = np.zeros(p.shape, bool), p < config.still_m
    if config.still_m <= 0:
        return out.reshape(x.shape[:-2])
    m = config.freeze_frames
    long_enough = np.ones_like(still[:, m - 1:])  # clips with a run of m still frames, the only ones to look at
    for k in range(m):
        long_enough &= still[:, k:n_frames - m + 1 + k]
    for i in np.flatnonzero(long_enough.any(-1)):
        q = p[i]
        for a, b in runs(still[i]):
            n = b - a
            if n < m:
                continue
            span = int(config.reach * n) + 1
            near = np.r_[max(1, a - span):a, b:min(n_frames, b + span)]
            moving = q[near][q[near] >= config.still_m]
            if not len(moving):
                continue
            jump = int(near[np.argmax(q[near])])
            beside = q[[t for t in (jump - 1, jump + 1) if 1 <= t < n_frames]].max()
            if q[jump] - beside >= np.median(moving) * n * config.catch_up:  # a jump, not the top of a ramp
                out[i, max(1, min(jump, a)):min(n_frames - 1, max(jump, b - 1) + 1)] = True
    return out.reshape(x.shape[:-2])


def holding_still(frames, still) -> np.ndarray:
    """``frames (..., T)`` bool with only the runs that hold a frame where ``still (..., T)`` bool is True."""
    f, st = np.asarray(frames, bool), np.asarray(still, bool)
    if st.shape != f.shape:
        raise ValueError(f"`still` must have the shape of `frames` {f.shape}; got {st.shape}.")
    n = f.shape[-1]
    given, out = f.reshape(-1, n), np.zeros((int(np.prod(f.shape[:-1], dtype=int)), n), bool)
    st = st.reshape(-1, n)
    for i in np.flatnonzero(given.any(-1)):
        for s, e in runs(given[i]):
            out[i, s:e] = st[i, s:e].any()
    return out.reshape(f.shape)


def calibrated_stillness(clips, *, share: float) -> float:
    """``still_m``: the pace (metres per frame) that only ``share`` of the frames of the clean ``clips`` (each ``(T,
    J, 3)`` metres, T >= 2, real and unseen by the model) stay below."""
    steps = []
    for c in clips:
        if np.ndim(c) != 3 or len(c) < 2:
            raise ValueError(f"each clip must be (T, J, 3) with T >= 2; got shape {np.shape(c)}.")
        steps.append(pace(c)[1:])
    if not steps:
        raise ValueError("no clips to calibrate `still_m` on.")
    return float(np.quantile(np.concatenate(steps), share))


class RetimeStep(InfillStep):
    """Detect, propose, verify and report of the re-timing (see the module docstring); an :class:`InfillConfig`
    given in place of a :class:`RetimeConfig` leaves freezes alone."""

    name = "retime"
    moves_whole_body = True

    def __init__(self, model, config: InfillConfig):
        super().__init__(model, config if isinstance(config, RetimeConfig) else RetimeConfig(**asdict(config)))

    def candidates(self, clips, actions) -> tuple[np.ndarray, np.ndarray]:
        """The motion model's flags (:meth:`InfillStep.detect`) and the :func:`caught_up_freezes`, each run grown over
        the still frames next to it (:func:`still_grown`); frames the model did not flag are flagged for every part."""
        prob, flagged = super().detect(clips, actions)
        if self.config.still_m > 0:
            speeds = pace(clips)
            seeds = flagged.any(-1) | caught_up_freezes(clips, self.config, speeds=speeds)
            grown = still_grown(clips, seeds, self.config.still_m, speeds=speeds)
            flagged |= (grown & ~flagged.any(-1))[..., None]
        return prob, flagged

    def timed(self, clips, flagged) -> np.ndarray:
        """``flagged (N, T, P)`` with only the runs in which the body stands still (:func:`holding_still`): a run
        that never stops has lost no time, so re-timing cannot repair it (D31). ``still_m`` 0 keeps every run."""
        if self.config.still_m <= 0:
            return flagged
        frames = flagged.any(-1)
        todo = np.flatnonzero(frames.any(-1))
        keep = np.zeros_like(frames)
        if len(todo):
            keep[todo] = holding_still(frames[todo], pace(np.asarray(clips)[todo]) < self.config.still_m)
        return flagged & keep[..., None]

    def detect(self, clips, actions) -> tuple[np.ndarray, np.ndarray]:
        """The flaw probability and the :meth:`candidates` that are :meth:`timed`."""
        prob, flagged = self.candidates(clips, actions)
        return prob, self.timed(clips, flagged)

    def refine(self, clips, actions) -> tuple[np.ndarray, list[list[dict]], np.ndarray]:
        """:meth:`InfillStep.refine` on the :meth:`detect` runs; the candidates passed over (never still) are
        reported as not kept."""
        prob, found = self.candidates(clips, actions)
        flagged = self.timed(clips, found)
        out, changes, prob = self.repaired(clips, actions, prob, flagged)
        passed = found.any(-1) & ~flagged.any(-1)
        for i in np.flatnonzero(passed.any(-1)):
            changes[i] = sorted(changes[i] + [
                {"step": self.name, "start": s, "stop": e, "parts": np.flatnonzero(found[i, s:e].any(0)).tolist(),
                 "kept": False, "worse": [], "passed_over": True,
                 "flaw_probability": [round(float(prob[i, s:e].max()), 3)] * 2}
                for s, e in runs(passed[i])], key=lambda entry: entry["start"])
        return out, changes, prob

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
