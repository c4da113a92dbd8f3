"""Concept snap (an option, ``Refiner(concept_snap=w)``): every anchor moved onto its action's nearest anchor concept.

The paper's anchor refinement (§3.2.2) in its plainest form: the clip is cut into transitions (Eq. 2,
λ = 200), each anchor's root-relative pose is moved ``w`` of the way onto the nearest K-means concept of
the clip's action, and the moves are carried to the frames between anchors by a natural cubic spline,
so the motion between key poses keeps its own shape and the root keeps its path. The clip is then put
back on its own bone lengths.

It trades fidelity for realism, so it is off by default. On the reference generators' samples (600 per
generator, 5 replications, after the default refinement; ``runs/cp`` figures in the README's table of
choices) it lowers FID where no default step does: ``mdm`` 1.315 -> 0.859, ``a2m`` 4.113 -> 3.291,
recogniser accuracy 87 -> 91 % and 43 -> 61 %; on real clips of subjects 1-10 it *raises* FID a little
(0.546 -> 0.578: it is not a shortcut the recogniser rewards whatever it is given). But it moves every
anchor of a real clip by its distance to the nearest concept (8 cm for the median held-out anchor), so
against the clean clip it is a large change: no gate on that distance kept real clips untouched (on the
flaw benchmark, snapping the 1 % of clips with the farthest anchors touched 9 % of clean clips by
1.0 cm and made every family worse).
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from refiner.concepts.anchors import AnchorConcepts, root_relative
from refiner.concepts.segmentation import DEFAULT_PENALTY, MIN_DURATION, segment
from refiner.refinement.splicing import project_bone_lengths, reference_lengths

__all__ = ["snap_to_concepts", "snapped_to_concepts", "check_strength"]


def check_strength(strength) -> float:
    """``strength`` as a float in [0, 1]; ValueError otherwise."""
    try:
        value = float(strength)
    except (TypeError, ValueError):
        raise ValueError(f"`concept_snap` must be a number in [0, 1]; got {strength!r}.") from None
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"`concept_snap` must be in [0, 1] (the share of the way onto the concept); got {strength!r}.")
    return value


def snap_to_concepts(joints: np.ndarray, action: int, concepts: AnchorConcepts, *, strength: float = 1.0,
                     penalty: float = DEFAULT_PENALTY) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Move a clip's anchors onto the nearest anchor concepts of ``action``.

    Parameters
    ----------
    joints : ndarray of shape (T, J, 3), metres, T > the segmentation's minimum transition
    action : int, an action of ``concepts``
    concepts : fitted AnchorConcepts with J joints
    strength : float in [0, 1], default 1
        Share of the way from each anchor's pose to its concept (1: onto it).

    Returns
    -------
    snapped : ndarray (T, J, 3) float32
        Bone lengths are not restored here (:func:`snapped_to_concepts` does it).
    anchors : ndarray (K,) int
        The anchor frames.
    distance : ndarray (K,) float64
        Each anchor's MPJPE (metres) to its concept before the move.
    """
    x = np.asarray(joints, dtype=np.float32)
    anchors = segment(x, penalty=penalty).anchors
    acts = np.full(len(anchors), int(action))
    index, distance = concepts.predict(x[anchors], acts), concepts.distance(x[anchors], acts)
    target = np.stack([concepts.concept(int(action), int(i)) for i in index])
    move = (check_strength(strength) * (target - root_relative(x[anchors]))).reshape(len(anchors), -1)
    # a natural cubic spline through the anchors' moves: no kink at an anchor (linear carrying of the moves
    # gives the same FID on the reference generators, 0.871 vs 0.859 on mdm, with a velocity jump there)
    frames = np.arange(len(x))
    carried = CubicSpline(anchors, move, axis=0, bc_type="natural")(frames) if len(anchors) > 2 else \
        np.stack([np.interp(frames, anchors, m) for m in move.T], axis=1)
    return (x + carried.reshape(x.shape)).astype(np.float32), anchors, distance


def snapped_to_concepts(refiner, clips: np.ndarray, reports: list) -> np.ndarray:
    """The refiner's concept-snap step: ``clips (B, T, J, 3)`` whose action was *given* snapped with
    ``refiner.concept_snap`` and put back on their bone lengths, each change in its clip's report; returned
    as given when the option is 0 or a clip is too short to segment. An inferred action is not snapped to:
    it would pull the clip toward the refiner's own guess."""
    strength = float(getattr(refiner, "concept_snap", 0.0))
    if strength == 0.0 or clips.shape[1] <= 2 * MIN_DURATION:
        return clips
    out, every = clips.copy(), np.ones(clips.shape[1], bool)
    for b, report in enumerate(reports):
        if report.action is None or report.action_inferred:
            continue
        snapped, anchors, distance = snap_to_concepts(clips[b], report.action, refiner.anchor_concepts,
                                                      strength=strength)
        out[b] = project_bone_lengths(snapped, reference_lengths(clips[b], refiner.skeleton), every, refiner.skeleton)
        moved = 100 * float(np.linalg.norm(out[b] - clips[b], axis=-1).mean())
        report.changes.append({"start": 0, "stop": clips.shape[1], "step": "concept_snap", "repair": "concept_snap",
                               "reason": f"concept snap {strength:g}: {len(anchors)} anchors moved onto the nearest "
                                         f"anchor concepts of the action (they were {100 * distance.mean():.1f} cm "
                                         f"away on average; moved {moved:.1f} cm on average)"})
    return out
