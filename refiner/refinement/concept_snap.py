"""Concept snap (an option of the concepts method, ``Refiner(concept_snap=w)``): every anchor moved onto its action's
nearest anchor concept.

The paper's anchor refinement (§3.2.2) in its plainest form: the clip is cut into transitions (Eq. 2,
λ = 200), each anchor's root-relative pose is moved ``w`` of the way onto the nearest K-means concept of
the clip's action, and the moves are carried to the frames between anchors by a natural cubic spline,
so the motion between key poses keeps its own shape and the root keeps its path. The clip is then put
back on its own bone lengths.

It trades fidelity for realism, so it is off by default; it runs after the concept steps. Measured with the previous
release's learned steps (on the reference generators' samples, 600 per generator, 5 replications, the option after
the flaw repairs, before the last denoising step), it lowered FID where no default step did: ``mdm`` 1.315
(default refinement) -> 0.853, ``a2m`` 4.113 -> 3.155, recogniser accuracy 87 -> 89 % and 43 -> 61 %;
on real clips of subjects 1-10 it *raises* FID a little (0.546 -> 0.578: it is not a shortcut the
recogniser rewards whatever it is given). But it moves every anchor of a real clip by its distance to
the nearest concept (8 cm for the median held-out anchor), so against the clean clip it is a large
change: no gate on that distance kept real clips untouched (on the flaw benchmark, snapping the 1 % of
clips with the farthest anchors touched 9 % of clean clips by 1.0 cm and made every family worse).
The segmentation costs O(T²): about 10 ms for a 60-frame clip, 0.15 s for 320 frames, 2 s for 1,280.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from refiner.concepts.anchors import AnchorConcepts, root_relative
from refiner.concepts.segmentation import DEFAULT_PENALTY, segment
from refiner.core.rotations import rotvec_to_rotmat
from refiner.core.skeletons import get_skeleton
from refiner.core.splicing import project_bone_lengths, reference_lengths

__all__ = ["snap_to_concepts", "snapped_to_concepts", "check_strength", "check_snap", "facing", "turned"]


def check_strength(strength, name: str = "concept_snap", meaning: str = "the share of the way onto the concept") -> float:
    """``strength`` as a float in [0, 1]; ValueError naming the option ``name`` (and what it means) otherwise (bools
    and strings too)."""
    if isinstance(strength, (bool, np.bool_)) or not isinstance(strength, (int, float, np.integer, np.floating)):
        raise ValueError(f"`{name}` must be a number in [0, 1]; got {strength!r}.")
    value = float(strength)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"`{name}` must be in [0, 1] ({meaning}); got {strength!r}.")
    return value


def check_snap(strength, anchor_concepts) -> float:
    """The ``concept_snap`` strength checked with :func:`check_strength`; a ValueError if it is on without
    ``anchor_concepts``."""
    value = check_strength(strength)
    if value and anchor_concepts is None:
        raise ValueError("concept_snap needs `anchor_concepts`, which this refiner lacks.")
    return value


def facing(poses: np.ndarray, skeleton: str) -> np.ndarray:
    """Heading of poses ``(N, J, 3)`` about the skeleton's up axis, ``(N,)`` radians: the angle of the hip
    line (right hip -> left hip) in the horizontal plane, measured from the skeleton's forward axis (a body
    facing forward reads +-90 degrees; only differences of headings are used)."""
    return np.angle(_hip_lines(poses, skeleton))


def _hip_lines(poses: np.ndarray, skeleton: str) -> np.ndarray:
    """Each pose's hip line in the horizontal plane as a complex number ``(N,)`` (forward axis real)."""
    skel = get_skeleton(skeleton)
    up, ahead = skel.up_vector, skel.forward_vector
    hips = poses[:, skel.index("left_hip")] - poses[:, skel.index("right_hip")]
    return hips @ ahead + 1j * (hips @ np.cross(up, ahead))


def turned(poses: np.ndarray, angle: np.ndarray, skeleton: str) -> np.ndarray:
    """Poses ``(N, J, 3)`` rotated by ``angle (N,)`` radians about the skeleton's up axis (through the origin)."""
    rot = rotvec_to_rotmat(get_skeleton(skeleton).up_vector[None] * np.asarray(angle, np.float64)[:, None])
    return np.einsum("nij,nkj->nki", rot, poses)


def _mean_heading(poses: np.ndarray, skeleton: str) -> float:
    """Heading (radians) of the summed hip lines of poses ``(N, J, 3)``: a pose whose hip line is short in
    the horizontal plane (lying on its side) weighs little."""
    return float(np.angle(_hip_lines(poses, skeleton).sum()))


def snap_to_concepts(joints: np.ndarray, action: int, concepts: AnchorConcepts, *, skeleton: str = "humanact12",
                     strength: float = 1.0, penalty: float = DEFAULT_PENALTY) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Move a clip's anchors onto the nearest anchor concepts of ``action``, turned to face as the clip does.

    The concepts hold HumanAct12's headings (its clips start facing within about 25 degrees of one
    direction); a clip may face anywhere, so the concepts are first turned about the up axis by the
    difference of the clip's mean heading (over its anchors' hip lines) and theirs: a clip turned as a
    whole is snapped as it would be unturned. Each anchor then takes its concept's heading relative to
    that mean, so a clip that turns far within itself is twisted toward its mean heading. (Turning each
    concept to each anchor's own heading instead made the snap weaker: docs/decisions.md D15.)

    Parameters
    ----------
    joints : ndarray of shape (T, J, 3), metres, T > the segmentation's minimum transition
    action : int, an action of ``concepts``
    concepts : fitted AnchorConcepts with J joints of ``skeleton``
    skeleton : str, default "humanact12"
    strength : float in [0, 1], default 1
        Share of the way from each anchor's pose to its concept (1: onto it).

    Returns
    -------
    snapped : ndarray (T, J, 3) float32
        Bone lengths are not restored here (:func:`snapped_to_concepts` does it).
    anchors : ndarray (K,) int
        The anchor frames.
    distance : ndarray (K,) float64
        Each anchor's MPJPE (metres) to its (turned) concept before the move.
    """
    x = np.asarray(joints, dtype=np.float32)
    anchors = segment(x, penalty=penalty).anchors
    poses = root_relative(x[anchors]).astype(np.float64)
    centres = np.stack([concepts.concept(int(action), i) for i in range(concepts.n_concepts_[int(action)])])
    turn = _mean_heading(poses, skeleton) - _mean_heading(centres.astype(np.float64), skeleton)
    centres = turned(centres.astype(np.float64), np.full(len(centres), turn), skeleton)  # (C, J, 3) as the clip faces
    gap = np.linalg.norm(poses[:, None] - centres[None], axis=-1).mean(-1)  # (K, C) MPJPE
    index = gap.argmin(1)
    target = centres[index]
    move = (check_strength(strength) * (target - poses)).reshape(len(anchors), -1)
    # a natural cubic spline through the anchors' moves: no kink at an anchor (linear carrying of the moves
    # gives the same FID on the reference generators, 0.871 vs 0.859 on mdm, with a velocity jump there)
    frames = np.arange(len(x))
    carried = CubicSpline(anchors, move, axis=0, bc_type="natural")(frames) if len(anchors) > 2 else \
        np.stack([np.interp(frames, anchors, m) for m in move.T], axis=1)
    return (x + carried.reshape(x.shape)).astype(np.float32), anchors, gap.min(1)


def snapped_to_concepts(refiner, clips: np.ndarray, reports: list, mode: str = "full") -> np.ndarray:
    """The refiner's concept-snap step: ``clips (B, T, J, 3)`` whose action was *given* snapped with
    ``refiner.concept_snap`` and put back on their (median) bone lengths, each change in its clip's report; returned as
    given when the option is 0 or ``mode`` is "transition" (this is an anchor refinement). An inferred action is not
    snapped to: it would pull the clip toward the refiner's own guess."""
    strength = float(getattr(refiner, "concept_snap", 0.0))
    if strength == 0.0 or mode == "transition":
        return clips
    out, every = clips.copy(), np.ones(clips.shape[1], bool)
    for b, report in enumerate(reports):
        if report.action is None or report.action_inferred:
            continue
        snapped, anchors, distance = snap_to_concepts(clips[b], report.action, refiner.anchor_concepts,
                                                      skeleton=refiner.skeleton, strength=strength)
        out[b] = project_bone_lengths(snapped, reference_lengths(clips[b], refiner.skeleton), every, refiner.skeleton)
        moved = 100 * float(np.linalg.norm(out[b] - clips[b], axis=-1).mean())
        report.changes.append({"start": 0, "stop": clips.shape[1], "step": "concept_snap",
                               "reason": f"concept snap {strength:g}: {len(anchors)} anchors moved onto the nearest "
                                         f"anchor concepts of the action (they were {100 * distance.mean():.1f} cm "
                                         f"away on average; moved {moved:.1f} cm on average)"})
    return out
