"""The motion model's step: flawed frames and parts found, in-filled from their context, kept where verified.

``detect``: a part (bone or root) is flagged where the motion model's flaw probability stays above the calibrated
threshold for ``min_run`` frames, widened by ``margin``. ``propose``: the flagged parts are hidden and in-filled by
the model (anchor refinement where the run holds a key frame, transition refinement between), only those parts
change, on the clip's own bone lengths; a root run is integrated from its in-filled velocity and joined to the
frames after it. ``verify``: each run is kept only where the model finds it more real and no physical figure
(jerk, foot slide, penetration, floating) gets worse (:func:`~refiner.refinement.steps.base.harms`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from refiner.core.bone_directions import from_bone_directions
from refiner.refinement.motion_model import ROOT_SCALE, MotionModel, ground_context, motion_features, part_features
from refiner.refinement.steps.base import dilated, harms, runs, window_figures
from refiner.core.contact import contact_joints, heights

__all__ = ["InfillConfig", "InfillStep", "flagged_parts", "clip_scores"]


@dataclass(frozen=True)
class InfillConfig:
    """Options of :class:`InfillStep`; ``threshold`` is calibrated (the manifest's), the others are choices.
    ``jerk_share``, ``slide_pairs`` and ``ground_tolerance_m`` (metres per frame of the window, penetration and
    floating) take the no-harm suite's tolerances for what verification calls worse in a window."""

    threshold: float
    min_run: int = 2
    margin: int = 2
    jerk_share: float = 0.05
    ground_tolerance_m: float = 0.0005
    slide_pairs: float = 0
    min_gain: float = 0.0


def clip_scores(probability, min_run: int) -> np.ndarray:
    """``(N,)``: per clip, the highest flaw probability a part holds for ``min_run`` frames in a row (what a clean
    clip's threshold is calibrated on)."""
    p = np.asarray(probability)
    if min_run > 1:
        p = np.min(np.stack([p[:, k:p.shape[1] - min_run + 1 + k] for k in range(min_run)]), 0)
    return p.reshape(len(p), -1).max(1)


def flagged_parts(probability, config: InfillConfig) -> np.ndarray:
    """``(..., T, P)`` bool from ``probability (..., T, P)``: runs of ``min_run`` frames above the threshold, widened
    by ``margin``."""
    above = np.asarray(probability) > config.threshold
    m, n = max(1, config.min_run), above.shape[-2]
    if n < m:
        return np.zeros_like(above)
    full = np.ones(above.shape[:-2] + (n - m + 1, above.shape[-1]), bool)  # the run of m frames starting here is all above
    for k in range(m):
        full &= above[..., k:n - m + 1 + k, :]
    keep = np.zeros_like(above)
    for k in range(m):
        keep[..., k:n - m + 1 + k, :] |= full
    return np.moveaxis(dilated(np.moveaxis(keep, -2, 0), config.margin), 0, -2)


class InfillStep:
    """The motion model's detect / propose / verify / report on a batch of clips of one skeleton."""

    name = "infill"
    #: Whether ``propose`` moves every part of a flagged run's frames (then the report names them all).
    moves_whole_body = False

    def __init__(self, model: MotionModel, config: InfillConfig):
        self.model, self.config = model, config

    def detect(self, clips, actions) -> tuple[np.ndarray, np.ndarray]:
        """``clips (N, T, J, 3)`` -> flaw ``probability (N, T, P)`` and ``flagged (N, T, P)`` bool."""
        _, prob = self.model.scan(clips, actions)
        flagged = flagged_parts(prob, self.config)
        flagged[:, 0] = flagged[:, -1] = False  # the first and last frame anchor the in-fill
        return prob, flagged

    def propose(self, clips, actions, flagged, infill=None) -> np.ndarray:
        """The clips with their flagged parts in-filled (unflagged frames exactly as given); ``infill(features,
        flagged) -> features`` replaces the model's in-fill (a stand-in to compare with)."""
        skel = self.model.skeleton
        feats, root, lengths = motion_features(clips, skel)
        context = ground_context(clips, skel)
        clean = self.model.predict(feats, flagged, actions, context)[0] if infill is None else infill(feats, flagged)
        cols = part_features(self.model.config.n_bones)
        out = np.array(clips, dtype=np.float64)
        for i in range(len(clips)):
            if not flagged[i].any():
                continue
            new = feats[i].astype(np.float64)
            hid = flagged[i][:, np.arange(cols.shape[0]).repeat(3)]
            new[hid] = clean[i][hid]
            new_root = _joined_root(root[i], clean[i][:, -3:] / ROOT_SCALE, flagged[i][:, -1])
            n_bones = self.model.config.n_bones
            joints = from_bone_directions(new_root, new[:, :3 * n_bones].reshape(-1, n_bones, 3), lengths[i], skel)
            frames = flagged[i].any(1)
            out[i, frames] = joints[frames]
        return out

    def refine(self, clips, actions) -> tuple[np.ndarray, list[list[dict]], np.ndarray]:
        """Detect, propose and verify on ``clips (N, T, J, 3)``: the kept clips, each clip's change entries, and the
        flaw ``probability (N, T, P)``; clips with nothing flagged skip the in-fill."""
        prob, flagged = self.detect(clips, actions)
        return self.repaired(clips, actions, prob, flagged)

    def repaired(self, clips, actions, prob, flagged) -> tuple[np.ndarray, list[list[dict]], np.ndarray]:
        """Propose and verify the ``flagged (N, T, P)`` parts of ``clips``, as :meth:`refine` returns them."""
        out, changes = np.array(clips, dtype=np.float64), [[] for _ in clips]
        todo = np.flatnonzero(flagged.any((1, 2)))
        if len(todo):
            acts = [actions[i] for i in todo]
            proposed = self.propose(out[todo], acts, flagged[todo])
            out[todo], kept = self.verify(out[todo], proposed, acts, flagged[todo], prob[todo])
            for i, entries in zip(todo, kept):
                changes[i] = entries
        return out, changes, prob

    def verify(self, given, proposed, actions, flagged, probability) -> tuple[np.ndarray, list[list[dict]]]:
        """Keep each run of changed frames only where the model's flaw probability falls by ``min_gain`` and
        :func:`harms` finds nothing worse; returns the kept clips and, per clip, the change entries."""
        skel = self.model.skeleton
        _, after = self.model.scan(proposed, actions)
        out = np.array(given, dtype=np.float64)
        changes = []
        for i in range(len(given)):
            entries = []
            ground = float(heights(given[i][:, list(contact_joints(skel))], skel).min())
            for s, e in runs(flagged[i].any(1)):
                before_p, after_p = float(probability[i, s:e].max()), float(after[i, s:e].max())
                worse = harms(window_figures(given[i], s, e, skel, ground), window_figures(proposed[i], s, e, skel, ground),
                              jerk_share=self.config.jerk_share,
                              ground_tolerance_m=self.config.ground_tolerance_m, slide_pairs=self.config.slide_pairs)
                kept = after_p < before_p - self.config.min_gain and not worse
                parts = np.flatnonzero(flagged[i, s:e].any(0) | self.moves_whole_body).tolist()
                entries.append({"step": self.name, "start": s, "stop": e, "parts": parts, "kept": kept,
                                "flaw_probability": [round(before_p, 3), round(after_p, 3)], "worse": worse})
                if kept:
                    out[i, s:e] = proposed[i, s:e]
            changes.append(entries)
        return out, changes


def _joined_root(root, velocity, hidden) -> np.ndarray:
    """``root (T, 3)`` with its ``hidden`` runs rebuilt from the in-filled ``velocity (T, 3)`` (metres per frame), the
    mismatch with the frame after each run spread evenly over its steps, so the frames outside stay where they were."""
    out = np.array(root, dtype=np.float64)
    for s, e in runs(hidden):
        steps = velocity[s:e + 1].copy()  # the steps into frames s..e (frame e is kept)
        steps += ((root[e] - root[s - 1]) - steps.sum(0)) / len(steps)
        out[s:e] = root[s - 1] + np.cumsum(steps[:-1], axis=0)
    return out
