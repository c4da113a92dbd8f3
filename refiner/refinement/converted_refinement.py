"""Refinement of a skeleton without weights of its own, through another skeleton's refiner.

A clip on skeleton S (e.g. the 18-joint ``uestc`` layout) is converted to the refiner's skeleton R
(the 24 HumanAct12 joints) by :func:`refiner.core.skeletons.convert`, refined there, and only the
*change* comes back: ``out = x + convert(refined_R, R, S) - convert(x_R, R, S)`` on the frames the
refiner changed, so the frames it left alone are returned exactly as given, and the joints that the
conversion has to estimate (on ``uestc``: the nose, heels and head top from SMPL joints; on the way
in, spine, collars, feet, hands and head from the 18) affect the result only through the change.
The action is unknown unless given as one of HumanAct12's action names (``uestc``'s 40 labels are not
HumanAct12's 12): the recognition network's "unknown" entry handles it, and the flaw classifier is
action-agnostic. Noise that stretches and shrinks bones frame by frame is judged in the clip's own layout
(converted, the clip is on rigid bones and the base cannot see it): ``bench skeletons`` uestc / humanml3d jitter
23.2 / 36.1 -> 27.7 / 43.5 % of the added error removed.
"""
from __future__ import annotations

import copy

import numpy as np

from refiner.core.motion import Motion
from refiner.core.output_kind import like_input
from refiner.core.skeleton_conversion import convert, estimated_joints
from refiner.core.rigid import FLEXIBLE_BONES, bending_bones, rough_bones
from refiner.core.skeletons import BoneProportions, get_skeleton, rigid_skeleton
from refiner.core.validation import check_joints
from refiner.refinement import blended_pose
from refiner.refinement.blended_pose import blend_change, unblended_pose
from refiner.refinement.inputs import MIN_FRAMES, check_metres_each, thread_limits
from refiner.refinement.noise_filter import denoised_noise_runs
from refiner.refinement.pose_prior import drifting_skeleton, prior_posed
from refiner.refinement import rigid_step
from refiner.refinement.texture_filter import filtered_texture

__all__ = ["ConvertedRefiner", "FLEXIBLE_BONES", "converts_with_humanact12"]

class ConvertedRefiner:
    """Refine clips of ``skeleton`` with ``base`` (a :class:`~refiner.refinement.pipeline.Refiner` of another skeleton).

    Parameters
    ----------
    base : Refiner
    skeleton : str
        A registered skeleton that :func:`refiner.core.skeletons.convert` connects with ``base.skeleton``.
    rigid_tolerance : float, default=0.005
        The rigid-skeleton step runs here, on ``skeleton``'s own bones (a clip whose bones vary more
        than this is put back on rigid bones); ``base`` should not repeat it
        (``rigid_tolerance=inf``), since the joints the conversion estimates do not keep their lengths.
    proportions : BoneProportions, optional
        Human bone proportions in ``skeleton``'s layout, toward which drifting bones are drawn
        (:func:`~refiner.core.skeletons.robust_bone_lengths`); None: the clip's medians. The converted
        clip is put on rigid bones with ``base``'s own proportions when it uses them.

    Attributes
    ----------
    base, skeleton, action_names : as given / ``base``'s
    estimated : tuple of str
        The joints of ``skeleton`` that the way back estimates (see the module docstring).
    rigid_bones : ndarray of bool
        The bones the rigid-skeleton step judges and enforces (all but :data:`FLEXIBLE_BONES`).
    """

    def __init__(self, base, skeleton: str, *, rigid_tolerance: float = 0.005, proportions: BoneProportions | None = None):
        self.base = base
        if isinstance(rigid_tolerance, bool) or not isinstance(rigid_tolerance, (int, float)) or rigid_tolerance < 0:
            raise ValueError(f"`rigid_tolerance` must be a number >= 0; got {rigid_tolerance!r}.")
        self.rigid_tolerance = float(rigid_tolerance)
        self.skeleton = get_skeleton(skeleton).name
        self.action_names = base.action_names
        self.estimated = estimated_joints(base.skeleton, self.skeleton)
        skel = get_skeleton(self.skeleton)
        self.rigid_bones = ~bending_bones(self.skeleton)
        estimated_joints(self.skeleton, base.skeleton)  # refuses skeletons the conversion cannot reach
        if proportions is not None and proportions.mean.shape != (len(skel.bones),):
            raise ValueError(f"`proportions` must have one share per {self.skeleton} bone ({len(skel.bones)}); "
                             f"got {proportions.mean.size}.")
        self.proportions = proportions

    def __repr__(self) -> str:
        return f"ConvertedRefiner({self.skeleton!r} through {self.base.skeleton!r})"

    @property
    def threads(self):
        """``base``'s thread setting, which :meth:`refine` runs under (see :class:`~refiner.refinement.pipeline.Refiner`)."""
        return self.base.threads

    @property
    def concept_snap(self) -> float:
        """``base``'s concept-snap strength (applied with a HumanAct12 action name only, see :meth:`refine`)."""
        return self.base.concept_snap

    def threads_for(self, seq) -> int | None:
        """The torch / BLAS threads :meth:`refine` uses for ``seq``."""
        return self.base.threads_for(seq)

    def refine(self, seq, *, action=None, mode: str | None = None, return_report: bool = False):
        """Refine one clip or a batch of ``skeleton``; returns the same kind as given (see :func:`refiner.refine`).

        ``action``: a name among ``base``'s actions (HumanAct12's) is used; any other action (an index
        or name of this skeleton's own dataset, e.g. UESTC's 40 labels or NTU13's 13) or None refines
        action-agnostic, and the report says so. A :class:`~refiner.core.motion.Motion`'s own action is
        such a label too.
        """
        with thread_limits(self.threads_for(seq)):
            return self._refine(seq, action, mode, return_report)

    def _refine(self, seq, action, mode, return_report):
        if isinstance(seq, Motion):
            if seq.skeleton != self.skeleton:
                raise ValueError(f"this refiner is for skeleton {self.skeleton!r}; got a {seq.skeleton!r} motion.")
            out, report = self._refine(seq.joints, seq.action if action is None else action, mode, True)
            result = seq.with_joints(out)
            return (result, report) if return_report else result
        batched = len(getattr(seq, "shape", np.shape(seq))) == 4
        x = check_joints(seq, skeleton=self.skeleton, batched=batched)
        clips = x if batched else x[None]
        check_metres_each(clips, get_skeleton(self.skeleton), batched)
        actions = list(action) if batched and isinstance(action, (list, tuple, np.ndarray)) else [action] * len(clips)
        if len(actions) != len(clips):
            raise ValueError(f"`action` must have one entry per clip ({len(clips)}); got {len(actions)}.")
        known = [a if isinstance(a, str) and a in self.action_names else None for a in actions]
        long_enough = clips.shape[1] >= MIN_FRAMES  # shorter clips come back exactly as given
        core = bool(getattr(self.base, "rigid_core", False))  # mocap edited in places: on its exact frames' lengths
        # blended poses are read from the clip's own exact bones (bending chains held to their ends' lengths)
        unblend = long_enough and (mode or self.base.mode) != "transition" and blended_pose.UNBLEND
        blends = [unblended_pose(c, self.skeleton, self.rigid_bones) if unblend else (c, []) for c in clips]
        clips = np.stack([c for c, _ in blends]).astype(clips.dtype, copy=False)
        rigid = [rigid_skeleton(c, self.skeleton, self.rigid_tolerance, bones=self.rigid_bones,
                                proportions=self.proportions, keep_core=core, spikes=core) if long_enough else (c, 0.0)
                 for c in clips]
        given = np.stack([r[0] for r in rigid]).astype(np.float32)
        # the joints the conversion estimates do not keep their lengths, and the flaw classifier reads
        # bone-length changes as flaws (it flagged every frame of converted clean clips): make them rigid
        inner_prior = self.base.bone_proportions if getattr(self.base, "rigid_lengths", None) == "proportions" else None
        inner = np.stack([rigid_skeleton(c, self.base.skeleton, self.rigid_tolerance, proportions=inner_prior)[0]
                          for c in convert(given, self.skeleton, self.base.skeleton)]).astype(np.float32)
        base = copy.copy(self.base)  # its pose prior and texture filter run below, once, with this clip's own drift gate
        base.posing, base.texture = "keep", "off"
        if batched:
            refined, reports = base.refine(inner, action=known, mode=mode, return_report=True)
        else:
            one, report = base.refine(inner[0], action=known[0], mode=mode, return_report=True)
            refined, reports = one[None], [report]
        refined = self._noisy_bones_denoised(clips, rigid, inner, refined, reports, mode)
        # the pose prior's drift gate reads this clip's own bones (the base's rigid step is off: tolerance inf)
        drifting = (drifting_skeleton(clips, self.skeleton, self.rigid_tolerance, bones=self.rigid_bones) if long_enough
                    else np.zeros(len(clips), bool))
        drifting &= ~np.array([v > self.rigid_tolerance and (j == c).all(axis=(1, 2)).any()  # a rigid core's exact frames:
                               for (j, v), c in zip(rigid, clips)])  # edited in places, not drifting throughout
        if getattr(self.base, "method", "learned") == "learned":  # the concepts pipeline has no pose-prior step
            noisy = np.array([r.noisy_throughout for r in reports], bool)
            refined = filtered_texture(self.base, prior_posed(self.base, refined, reports, drifting, noisy), reports, noisy)
        changed = ~(refined == inner).reshape(*refined.shape[:2], -1).all(-1)  # (B, T)
        delta = convert(refined, self.base.skeleton, self.skeleton) - convert(inner, self.base.skeleton, self.skeleton)
        out = given.copy()
        out[changed] = (given[changed] + delta[changed]).astype(np.float32)
        note = (f"refined as {self.base.skeleton!r} through refiner.core.skeletons.convert; only the change came back"
                + (f" (estimated on the way back: {', '.join(self.estimated)})" if self.estimated else ""))
        for report, (joints, variation), clip, asked, used, (_, found) in zip(reports, rigid, clips, actions, known, blends):
            report.notes.append(note)
            report.changes[:0] = [blend_change(blend) for blend in found]
            if asked is not None and used is None:
                report.notes.append(f"action {asked!r} is not one of the refiner's actions; refined action-agnostic")
            if variation > self.rigid_tolerance:
                moved = int((joints != clip).reshape(len(clip), -1).any(-1).sum())
                lengths = (f"its rigid core's {self.skeleton} bone lengths ({len(clip) - moved} exact frames kept)"
                           if moved < len(clip) else f"the clip's median {self.skeleton} bone lengths"
                           + (", drawn toward human proportions where they drift" if self.proportions is not None else ""))
                report.changes.insert(len(found), {"start": 0, "stop": x.shape[-3], "step": "skeleton", "reason":
                                          f"bone lengths varied by up to {100 * variation:.1f} % (std / mean; mocap: "
                                          f"0 %); {moved} frames put back on {lengths} (bones that span a bending "
                                          "chain left free)"})
        out = out if batched else out[0]
        result = like_input(out, seq, x)
        if return_report:
            return result, (reports if batched else reports[0])
        return result


    def _noisy_bones_denoised(self, clips, rigid, inner, refined, reports, mode):
        """``refined (B, T, J_R, 3)`` with the frames whose own-layout bones leave the clip's rigid core roughly
        (:func:`~refiner.core.rigid.rough_bones` over ``NOISY_BONES``: clips with a core only, bending chains left out)
        denoised as the base's noise runs, where no step of the base changed them: converted to the base's layout a
        clip is put on rigid bones and has no core, so the base cannot see them."""
        rough = np.zeros(clips.shape[:2])
        for b, ((joints, variation), clip) in enumerate(zip(rigid, clips)):
            if rigid_step.NOISY_BONES is not None and variation > self.rigid_tolerance and (joints == clip).all(axis=(1, 2)).any():
                rough[b] = rough_bones(clip, self.skeleton, bones=self.rigid_bones) > rigid_step.NOISY_BONES
        if not rough.any() or getattr(self.base, "noise_filter", None) is None or self.base.denoising not in ("filter", "runs"):
            return refined
        changed = (refined != inner).any((2, 3))
        return denoised_noise_runs(self.base, refined, reports, rough, changed, mode or self.base.mode)


def converts_with_humanact12(skeleton: str) -> bool:
    """Whether :func:`refiner.core.skeletons.convert` connects ``skeleton`` with HumanAct12 both ways."""
    try:
        estimated_joints(skeleton, "humanact12"), estimated_joints("humanact12", skeleton)
    except ValueError:
        return False
    return get_skeleton(skeleton).name != "humanact12"
