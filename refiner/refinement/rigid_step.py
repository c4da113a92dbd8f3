"""The refiner's rigid-skeleton step (step 0 and the last step of the learned method): a clip whose bones vary in length
more than mocap's is put back on rigid bones before the flaw steps judge it, and the frames of a rigid core's clip
that it kept for them go on the core's lengths at last (:mod:`refiner.core.rigid` does the geometry)."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation

from refiner.core.rigid import bone_variation, rigid_skeleton, rough_bones
from refiner.core.skeletons import bone_lengths
from refiner.refinement.pose_prior import drifting_skeleton

__all__ = ["rigid_first", "rigid_at_last", "natural_bones_back", "noisy_bones", "NATURAL_BONES_KEY", "NOISY_BONES"]

#: The manifest entry (``manifest["learned"]``) of the bone variation the weights' own clean data shows.
NATURAL_BONES_KEY = "natural_bone_variation"
#: A clip whose bones vary more than the weights' data's own (``refiner.natural_bones``: a flaw in some of its frames)
#: still gets back the frames whose every bone is within this many times that variation of the clip's median length,
#: where no later step changed them: the flaw's frames stay rigid, the rest keep the bones the data have. None: such
#: a clip stays rigid throughout (the release before). Chosen on CMU's calibration subjects (122, 127; 26 clips,
#: severity 2): mean 20.08 % (None) / 20.50 / **20.51** / 20.10 % at 2 / 3 / 5 (jitter 27.8 / 29.8 / 29.8 / 27.0,
#: wrong_anchor -1.9 / -1.2 / -1.1 / -1.2); clean clips unchanged (all within the variation).
NATURAL_FRAME_BAND = 3.0
#: A frame off a clip's rigid core whose bones leave it this roughly (:func:`refiner.core.rigid.rough_bones`) is noisy:
#: the noise step denoises it as it does the flaw classifier's noise runs (:func:`noisy_bones`). None: the classifier
#: alone (the release before). Calibration subjects 9-10 (severity 2): jitter 29.0 % (None) / 33.6 / 33.6 / **33.8** /
#: 34.0 / 33.8 % at 0.003 / 0.01 / 0.02 / 0.03 / 0.05 (wrong_anchor 4.6 / 4.2 / 4.4 / 4.5 / 4.5 / 4.6 %), every other
#: family and the clean clips unchanged; 0.02 leaves room for lighter noise.
NOISY_BONES = 0.02



def rigid_first(refiner, clips: np.ndarray, reports: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``clips (B, T, J, 3)`` float32 put on rigid bones where they vary (``refiner.rigid_tolerance``), each change in
    its clip's report; returns ``(clips, cored, drifting)``: ``cored (B,)`` the clips whose rigid core kept frames for
    the flaw steps (:func:`rigid_at_last` puts those on its lengths), ``drifting (B,)`` the clips whose input skeleton
    deforms slowly throughout (the pose prior's gate), which a clip with exact bones in some frames never does: it was
    edited in places (a pose blended toward another), and the prior's refit of its every frame moved them."""
    prior = _proportions(refiner)
    rigid, variations = rigid_skeleton(clips, refiner.skeleton, refiner.rigid_tolerance, proportions=prior,
                                       keep_core=refiner.rigid_core, keep_shortened=refiner.rigid_core, spikes=True)
    drifting = drifting_skeleton(clips, refiner.skeleton, refiner.rigid_tolerance, variation=variations)  # the input's bones
    lengths = "the clip's median bone lengths" + ("" if prior is None else ", drawn toward human proportions where they drift")
    out, cored = clips.copy(), np.zeros(len(clips), bool)
    for b, (report, variation) in enumerate(zip(reports, variations)):  # first the bones: not a motion flaw
        if variation <= refiner.rigid_tolerance:
            continue
        moved = np.flatnonzero((rigid[b] != clips[b]).any((1, 2)))
        cored[b] = (kept := clips.shape[1] - moved.size) > 0  # only a rigid core's clip keeps frames here
        if moved.size:
            where = f"its rigid core's bone lengths ({kept} frames of the core or with bones that only shorten kept for now)"
            out[b] = rigid[b]
            report.changes.append({"start": int(moved[0]), "stop": int(moved[-1]) + 1, "step": "skeleton", "reason":
                                   f"bone lengths varied by up to {100 * variation:.1f} % (std / mean; mocap: "
                                   f"0 %); {moved.size} frames put back on {where if kept else lengths}"})
    return out, cored, drifting & ~cored


def rigid_at_last(refiner, clips: np.ndarray, reports: list, cored: np.ndarray) -> np.ndarray:
    """``clips (B, T, J, 3)`` with the frames the first step kept off the rigid core of the ``cored (B,)`` clips (bones that
    only shorten) and no repair changed put on the core's bone lengths, each change reported: the output's bones are rigid."""
    if not cored.any():
        return clips
    out = clips.copy()
    out[cored] = rigid_skeleton(clips[cored], refiner.skeleton, refiner.rigid_tolerance, proportions=_proportions(refiner),
                                keep_core=True)[0]
    for b in np.flatnonzero((out != clips).any((1, 2, 3))):
        moved = np.flatnonzero((out[b] != clips[b]).any((1, 2)))
        reports[b].changes.append({"start": int(moved[0]), "stop": int(moved[-1]) + 1, "step": "skeleton", "reason":
                                   f"{moved.size} frames off the clip's rigid core whose bones shortened, which no repair "
                                   f"changed, put back on the core's bone lengths (moved "
                                   f"{100 * float(np.linalg.norm(out[b][moved] - clips[b][moved], axis=-1).mean()):.2f} cm on average)"})
    return out


def natural_bones_back(refiner, clips: np.ndarray, given: np.ndarray, rigid: np.ndarray, reports: list) -> np.ndarray:
    """``clips (B, T, J, 3)`` (refined) with the ``given`` frames back where the clip's bones vary no more than
    ``refiner.natural_bones`` (the weights' clean data's own variation: CMU's processed joints, up to 5.5 %), no step
    after the first (``rigid``: its output) changed the frame, nor any frame within ``refiner.blend`` frames of it (a
    repair was joined to rigid neighbours). The flaw steps judge rigid bones, as they were trained; the output keeps
    the bones the data have, so a clean clip without a rigid core comes back as given. A clip over that variation
    gets back only its frames within :data:`NATURAL_FRAME_BAND` of its medians (a flaw's frames stay rigid).
    Limit: a bone stretched in a few frames by less than that variation comes back stretched too (CMU test clips
    with a 5-30 % limb stretch that stays under 5.5 %: 0.61 cm from the clean clip, rigid 0.55 cm); a rule on each
    frame's deviation from the clip's median (3 / 8 robust deviations) fixed it but gave back 0 / 39 % of clean
    clips instead of 89 %, CMU's processed bones being heavy-tailed frame by frame."""
    if not refiner.natural_bones:
        return clips
    out = clips.copy()
    variation = bone_variation(given, refiner.skeleton)
    band = None if NATURAL_FRAME_BAND is None else NATURAL_FRAME_BAND * refiner.natural_bones
    natural = variation <= refiner.natural_bones
    for b in np.flatnonzero((natural | (band is not None)) & (rigid != given).any((1, 2, 3))):
        differs = (clips[b] != given[b]).any((1, 2))
        stays = differs & ~(clips[b] == rigid[b]).all((1, 2))
        if not natural[b]:  # the frames a flaw took out of the band stay rigid too
            lengths = bone_lengths(given[b], refiner.skeleton)
            stays |= differs & (np.abs(lengths / np.maximum(np.median(lengths, 0), 1e-9) - 1) > band).any(-1)
        same = differs & ~binary_dilation(stays, iterations=max(int(refiner.blend), 1))
        if not same.any():  # every frame the rigid step moved stays rigid or was changed again by a flaw step
            continue
        out[b][same] = given[b][same]
        first = next(c for c in reports[b].changes if c["step"] == "skeleton")  # rigid_first's: the first step
        words = (f"bones varying {100 * variation[b]:.1f} % (std / mean), within the weights' data's own "
                 f"{100 * refiner.natural_bones:.1f} %: {int(same.sum())} frames no later step changed given back"
                 if natural[b] else
                 f"bones varying {100 * variation[b]:.1f} % (std / mean), over the weights' data's own "
                 f"{100 * refiner.natural_bones:.1f} %: {int(same.sum())} frames whose bones stay within "
                 f"{100 * band:.1f} % of the clip's medians, which no later step changed, given back")
        rest = np.flatnonzero((out[b] != given[b]).any((1, 2)) & (rigid[b] != given[b]).any((1, 2)))
        if not rest.size:
            reports[b].changes.remove(first)
            reports[b].notes.append(f"{words}, so their bones are as given")
        else:
            first.update(start=int(rest[0]), stop=int(rest[-1]) + 1, reason=f"{first['reason']}; {words}")
    return out


def noisy_bones(refiner, clips: np.ndarray, cored: np.ndarray) -> np.ndarray:
    """``(B, T)`` bool: the frames of ``clips (B, T, J, 3)`` (as given) whose bones leave their clip's rigid core
    roughly (:data:`NOISY_BONES`): noise on a mocap clip edited in places. Only the ``cored (B,)`` clips
    (:func:`rigid_first`'s) are looked at, unless the weights' data have bones that vary (``refiner.natural_bones``
    over ``refiner.rigid_tolerance``: CMU): then every clip, a clip with no core against its own median lengths.
    All False with ``NOISY_BONES = None``."""
    out = np.zeros(clips.shape[:2], bool)
    natural = bool(getattr(refiner, "natural_bones", 0.0) > refiner.rigid_tolerance)
    for b in (np.arange(len(clips)) if natural else np.flatnonzero(cored)) if NOISY_BONES is not None else ():
        out[b] = rough_bones(clips[b], refiner.skeleton, natural=natural) > NOISY_BONES
    return out


def _proportions(refiner):
    """The human bone proportions the refiner's rigid lengths lean on, or None (``rigid_lengths="median"``)."""
    return refiner.bone_proportions if refiner.rigid_lengths == "proportions" else None
