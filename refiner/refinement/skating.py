"""Skating: a body that glides over its planted feet, found and moved back.

A foot on the ground does not slide. Where the body and its planted feet move together further than real clips
ever do (:func:`refiner.core.contact.skating` over :data:`~refiner.core.contact.SKATING_WINDOW` steps past the
weights' ``skating_threshold_m``), the run, widened by that window on each side, is moved back by the glide
(:func:`~refiner.refinement.repair_candidates.planted_feet_run`) and spliced in. The flaw classifier needs no
opinion: the evidence is physical, and no flaw the detectors were trained on moves the whole body sideways
(``foot_sliding`` is a held-out family of ``bench flaws``), so on the CMU weights they saw almost none of it.

The threshold is the largest skating of all but :data:`SKATING_CLIP_RATE` of the weight set's clean clips (a rule,
not a model: every clip of its split serves, :func:`calibrate_skating`; 11.2 cm for HumanAct12's train split, 9.4 cm
for CMU's). A run's correction is kept only where it leaves the root's horizontal path no rougher than it was
(:data:`SMOOTHER_ROOT`): a wrong pose slips a planted foot while the root walks on, and moving the body back by
that slip stops the walk. Chosen on the training families of the calibration subjects (severity 2):

- CMU 122 and 127 (69 clips, action unknown): wrong_anchor 0.0 % without the step, -14.0 % unchecked, 0.0 % checked;
  frozen -46.0 / -46.3 / -46.0 %, the other training families unchanged; foot_sliding 6.5 -> 50.3 / 50.2 %;
- HumanAct12 9-10 (every 2nd clip): wrong_anchor 4.5 / 4.1 / 4.5 %, frozen 72.9 / 72.8 / 72.9 %; foot_sliding
  39.3 -> 63.3 / 51.5 %.

It was written after ``foot_sliding``, a held-out family, stood at 3 % on the CMU weights, so that family no longer
tests it blind. On sliding recipes of our own (``examples/measure_sliding_recipes.py``) it does little: a slow glide
(15 cm over 2 s) or a one-way drift (12 cm over 1 s) stays under the threshold, and one foot skating alone is not a
glide of the body. ``Refiner(skating=0)`` turns the step off.
"""
from __future__ import annotations

import numpy as np

from refiner.core.contact import SKATING_WINDOW, horizontal, skating
from refiner.core.skeletons import get_skeleton
from refiner.refinement.repair_candidates import planted_feet_run
from refiner.refinement.splicing import splice

__all__ = ["deskated", "calibrate_skating", "skating_threshold", "SKATING_KEY", "SKATING_CLIP_RATE"]

#: The manifest's ``learned`` entry holding the threshold, metres.
SKATING_KEY = "skating_threshold_m"
#: Share of the weight set's clean clips whose largest skating may pass the threshold.
SKATING_CLIP_RATE = 0.01
#: Keep a run's correction only where it leaves the root's horizontal path no rougher than it was.
SMOOTHER_ROOT = True


def _root_roughness(y: np.ndarray, lo: int, hi: int, skel) -> float:
    """Sum of squared horizontal root accelerations (m / frame²) over frames ``lo..hi-1`` and one each side."""
    acc = horizontal(np.diff(y[max(lo - 1, 0) : hi + 1, skel.root].astype(np.float64), 2, axis=0), skel)
    return float((acc ** 2).sum())


def calibrate_skating(clips, skeleton: str, clip_rate: float = SKATING_CLIP_RATE) -> float:
    """The threshold, metres: the ``1 - clip_rate`` quantile of the largest :func:`~refiner.core.contact.skating`
    of each clean clip ``(T, J, 3)`` metres (clips under two windows long are skipped)."""
    peaks = [float(skating(c, skeleton).max()) for c in clips if len(c) > 2 * SKATING_WINDOW]
    if not peaks:
        raise ValueError(f"calibrate_skating needs clips longer than {2 * SKATING_WINDOW} frames.")
    return float(np.quantile(peaks, 1.0 - clip_rate))


def skating_threshold(manifest: dict, skating_option: float | None) -> float:
    """The step's threshold, metres: the option if given, else the weights' (0, off, where they have none)."""
    value = manifest.get("learned", {}).get(SKATING_KEY, 0.0) if skating_option is None else skating_option
    if isinstance(value, bool) or not np.isfinite(value) or value < 0:
        raise ValueError(f"`skating` must be a non-negative threshold in metres (0: off); got {value!r}.")
    return float(value)


def deskated(refiner, clips: np.ndarray, reports: list, mode: str) -> np.ndarray:
    """``clips (B, T, J, 3)`` metres with their skating runs moved back over the planted feet (a transition
    refinement: skipped in ``mode="anchor"``); each change goes in the clip's report."""
    threshold = getattr(refiner, "skating", 0.0)
    if not threshold or mode == "anchor" or clips.shape[1] < 2:
        return clips
    skel = get_skeleton(refiner.skeleton)
    glide = skating(clips, skel)  # (B, T-1)
    out = clips
    for b in np.flatnonzero(glide.max(1) > threshold):
        above = np.r_[False, glide[b] > threshold, False]
        edges = np.flatnonzero(np.diff(above.astype(np.int8)))
        y = out[b]
        for lo, hi in zip(edges[::2] - SKATING_WINDOW, edges[1::2] + SKATING_WINDOW + 1):
            lo, hi = max(int(lo), 0), min(int(hi), len(y))
            new = splice(y, planted_feet_run(y, lo, hi, skel), lo, hi, blend=refiner.blend,
                         keep_start=lo > 0, keep_end=hi < len(y))
            if np.array_equal(new, y) or (SMOOTHER_ROOT and _root_roughness(new, lo, hi, skel)
                                          > _root_roughness(y, lo, hi, skel)):  # a wrong pose's slip, not a glide
                continue
            if out is clips:
                out = clips.copy()
            moved = 100 * float(np.linalg.norm(new[lo:hi] - y[lo:hi], axis=-1).mean())
            reports[b].changes.append({"start": lo, "stop": hi, "step": "transition", "repair": "planted_feet", "reason":
                                       f"the body glides up to {100 * glide[b][max(lo, 0):hi].max():.1f} cm over its planted "
                                       f"feet in {SKATING_WINDOW} frames (99 % of the weights' clean clips stay under {100 * threshold:.1f} cm); "
                                       f"moved back by the glide (moved {moved:.1f} cm on average)"})
            reports[b].flagged_transitions.append([lo, hi])
            y = new
        out[b] = y
    return out
