"""Refinement with the concept steps (``method="concepts"``): recognise anchors, score them, refine anchors and transitions.

Defaults chosen by measurement on held-out HumanAct12 subjects (11-12) with seeded flaws
(``motion-refiner bench refiner`` and ``bench flaws``); the paper's variants stay available:

- ``quality="pose"``: anchors are scored by a per-action Gaussian mixture over root-relative,
  proportion-normalised poses (:class:`~refiner.refinement.anchor_quality.AnchorQuality`), thresholded on
  held-out *subjects*. The paper's GMM over encoder features (``"encoder"``) separates drifted
  anchors from real ones with ROC AUC 0.55, the pose mixture with 0.93.
- ``anchor_method="posterior"``: a flagged anchor moves to its posterior-mean pose under that
  mixture (observation noise ``anchor_noise`` = 2 cm), spread over the neighbouring transitions
  with a smoothstep weight, so their detail is kept. The paper's route (``"concept"``: masked
  encoder, concept classifier, MLP decoder, CVAE-regenerated transitions) predicts held-out real
  anchors only to 18 cm median error with the shipped weights, and changed clean clips by 2.6 cm.
- ``transition_method="network"``: the paper's transition refinement module, applied only to
  transitions whose refined frames differ from the input by more than on 99 % of real ones.
  ``"retime"`` re-times a transition along its own path with the speed profile of its transition
  concept (:class:`refiner.refinement.transition_refinement.TransitionRetimer`).

Each step owns its threshold: the anchor scorer's ``threshold_`` (``AnchorQuality`` or, with
``quality="encoder"``, ``AnchorRecognizer``), the transition refiner's ``threshold_`` and the
re-timing step's per-duration ``thresholds_``; :func:`calibrate` sets the first and the last.
Only flagged anchors and transitions change (:mod:`refiner.core.splicing`), but for the concept-snap option
(``concept_snap``, off by default, :mod:`refiner.refinement.concept_snap`), which runs last and moves every anchor of a
clip whose action is given.
"""
from __future__ import annotations

import numpy as np

from refiner.refinement.concept_snap import snapped_to_concepts
from refiner.refinement.inputs import MIN_FRAMES
from refiner.refinement.report import RefinementReport, start_reports
from refiner.core.splicing import project_bone_lengths, reference_lengths, splice

__all__ = ["QUALITY", "ANCHOR_METHODS", "TRANSITION_METHODS", "refine_clips", "calibrate"]

QUALITY = ("pose", "encoder")
ANCHOR_METHODS = ("posterior", "concept")
TRANSITION_METHODS = ("network", "retime")


def refine_clips(refiner, clips: np.ndarray, actions: list, mode: str, batched: bool
                 ) -> tuple[list[np.ndarray], list[RefinementReport]]:
    """Refine ``clips (B, T, J, 3)`` one by one with ``refiner``'s concept steps (then its concept snap, if on); a
    batch's errors name the clip."""
    reports = start_reports(clips.shape[1], actions, mode, refiner.action_names, batched=batched)
    outs = []
    for i, (clip, report) in enumerate(zip(clips, reports)):
        try:
            outs.append(_refine_clip(refiner, np.array(clip, dtype=np.float32, copy=True), report, mode))
        except ValueError as e:
            if not batched:
                raise
            raise ValueError(f"clip {i} of {len(clips)}: {e}") from e
    if getattr(refiner, "concept_snap", 0.0) and clips.shape[1] >= MIN_FRAMES:  # the option, after the concept steps
        outs = list(snapped_to_concepts(refiner, np.stack(outs), reports, mode))
    return outs, reports


def calibrate(refiner, clips, actions, *, percentile: float = 1.0, transition_clips=None) -> dict:
    """Set the anchor and re-timing thresholds from real clips, using ``refiner``'s own recognised anchors.

    Anchors: the ``percentile``-th percentile of real anchors' pose scores (use clips the pose
    model was not fitted on), into ``refiner.anchor_quality``. Transitions: per duration bin, the
    ``100 - percentile``-th percentile of real transitions' spline residuals (metres), into
    ``refiner.transition_retimer``; ``transition_clips`` (default ``clips``) supplies them.
    Returns what was set (the record the refiner keeps in ``manifest["calibration"]``).
    """
    def recognized(group):
        group = [np.asarray(c, dtype=np.float32) for c in group]
        return group, [refiner.recognizer.recognize(x).anchors for x in group]

    clips, anchors = recognized(clips)
    transitions = (clips, anchors) if transition_clips is None else recognized(transition_clips)
    bins = refiner.transition_retimer.calibrate(*transitions, percentile=percentile)
    calibration = {"percentile": percentile, "clips": len(clips), "transition_thresholds": [list(b) for b in bins]}
    if refiner.anchor_quality is not None and clips:
        poses = np.concatenate([x[a] for x, a in zip(clips, anchors)])
        pose_actions = np.concatenate([np.full(len(a), int(action)) for a, action in zip(anchors, actions)])
        calibration["anchor_threshold"] = refiner.anchor_quality.calibrate(poses, pose_actions, percentile=percentile)
    return calibration


def _refine_clip(refiner, x: np.ndarray, report: RefinementReport, mode: str) -> np.ndarray:
    """Recognise, score and refine one clip ``x (T, J, 3)`` float32, filling ``report``."""
    if len(x) < MIN_FRAMES:  # returned as given (the report says so)
        return x
    rec = refiner.recognizer.recognize(x)
    if report.action is None:
        report.action, report.action_inferred = int(np.argmax(rec.action_probability)), True
    report.action_name = refiner.action_names[report.action] if refiner.action_names else None
    anchors = rec.anchors
    report.anchors = anchors.tolist()
    report.anchor_probability = [round(float(p), 4) for p in rec.probability]
    if refiner.quality == "encoder":
        scores, flagged, threshold = rec.scores, rec.flagged, rec.threshold
    else:
        scores, flagged = refiner.anchor_quality.detect(x[anchors], report.action)
        threshold = refiner.anchor_quality.threshold_
    report.anchor_scores = [round(float(v), 3) for v in scores]
    report.threshold = round(float(threshold), 3)
    report.flagged_anchors = anchors[flagged].tolist()
    y = x.copy()
    changed = np.zeros(len(x), dtype=bool)
    touched: set[int] = set()
    if mode in ("full", "anchor"):
        for k in np.flatnonzero(flagged):
            if refiner.anchor_method == "posterior":
                y = _posterior_anchor(refiner, y, anchors, int(k), report, changed)
            else:
                y = _concept_anchor(refiner, y, anchors, int(k), report, changed)
                touched.update({int(k) - 1, int(k)} & set(range(len(anchors) - 1)))
    if mode in ("full", "transition"):
        y = _refine_transitions(refiner, y, anchors, report, changed, touched if mode == "full" else set())
    if changed.any():
        y = project_bone_lengths(y, reference_lengths(x, refiner.skeleton), changed, refiner.skeleton)
    return y


def _posterior_anchor(refiner, y, anchors, k: int, report, changed) -> np.ndarray:
    frame = int(anchors[k])
    y, weight, moved = refiner.anchor_quality.propose(y, anchors, k, report.action, refiner.anchor_noise)
    window = weight > 0
    changed |= window
    start, stop = int(np.argmax(window)), int(len(window) - np.argmax(window[::-1]))
    report.refined_anchors.append({"frame": frame, "method": "posterior", "moved_cm": round(moved, 3)})
    report.changes.append({"start": start, "stop": stop, "step": "anchor",
                           "reason": f"anchor {frame} pose scored below the threshold; moved {moved:.1f} cm "
                                     "toward the action's pose distribution"})
    return y


def _concept_anchor(refiner, y, anchors, k: int, report, changed) -> np.ndarray:
    frame = int(anchors[k])
    proposal, (lo, hi), concept, moved_cm = refiner.anchor_refiner.propose(y, anchors, k, report.action,
                                                                           refiner.transition_generator)
    y = splice(y, proposal, lo, hi, blend=refiner.blend, keep_start=k > 0, keep_end=k + 1 < len(anchors))
    changed[lo:hi] = True
    report.refined_anchors.append({"frame": frame, "concept": int(concept), "moved_cm": round(moved_cm, 3)})
    report.changes.append({"start": lo, "stop": hi, "step": "anchor",
                           "reason": f"anchor {frame} scored below the threshold; replaced by concept {concept}"})
    return y


def _refine_transitions(refiner, y, anchors, report, changed, touched: set) -> np.ndarray:
    if refiner.transition_method == "network":
        refined, residuals = refiner.transition_refiner.refine_transitions(y, anchors)
        thresholds = np.full(len(anchors) - 1, float(refiner.transition_refiner.threshold_))
    else:
        refined = None
        residuals, thresholds = refiner.transition_retimer.detect(y, anchors)
    report.transition_residuals_cm = [round(100 * float(r), 3) for r in residuals]
    report.transition_thresholds_cm = [round(100 * float(t), 3) for t in thresholds]
    flagged = set(np.flatnonzero(residuals > thresholds).tolist()) | touched
    for m in sorted(flagged):
        a, b = int(anchors[m]), int(anchors[m + 1])
        if b - a < 2:
            continue
        why = ("after anchor refinement" if m in touched
               else f"frames deviate {100 * residuals[m]:.2f} cm from their spline > {100 * thresholds[m]:.2f} cm")
        if refined is None:
            proposal = refiner.transition_retimer.propose(y, a, b, refiner.transition_generator)
            why += "; re-timed along its path with its transition concept's speed profile"
        else:
            proposal = refined
        y = splice(y, proposal, a + 1, b, blend=refiner.blend)
        changed[a + 1 : b] = True
        report.flagged_transitions.append([a, b])
        report.changes.append({"start": a + 1, "stop": b, "step": "transition", "reason": why})
    return y
