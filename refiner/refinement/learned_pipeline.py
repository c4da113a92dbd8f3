"""Refinement with the learned steps (``method="learned"``, the default): recognise, repair, splice, make rigid.

0. **Blended poses** taken out where the exact bones show them (:mod:`refiner.refinement.blended_pose`); then the
   **rigid skeleton**: where a clip's bones vary in length more than mocap's
   (``rigid_tolerance``, coefficient of variation; real HumanAct12 clips: under 0.001 %), its frames are put
   back on the clip's median bone lengths (with ``rigid_core``, a mocap clip edited in places keeps its exact
   frames and those whose bones only shorten, until the last step), so the detectors judge the motion, not the bones.
1. **Recognition**: per-frame flaw probability from the kinematic flaw classifier
   (:class:`~refiner.refinement.flaw_classifier.FlawClassifier`, the default detector), anchor probability and
   the action from the recognition network (:class:`~refiner.refinement.learned_refinement.FlawRecognizer`,
   whose own flaw probability and the repair network's whole-clip correction are optional extra
   detectors, ``detect``), each for the whole batch in one forward pass. Frames where a detector
   stays above its threshold (each calibrated on held-out subjects' real clips) for ``min_run``
   frames are flagged, widened by ``margin`` frames of context on each side.
2. **Anchor and transition refinement**: flagged retraces have their loop cut (:mod:`refiner.refinement.retrace`),
   then each flagged run gets the repair for the flaw group the classifier recognises (:data:`TYPED_REPAIRS`): timing flaws are re-timed
   along their own path where they stall (:mod:`refiner.refinement.repair_candidates`), a body that glides or
   floats is corrected by the repair network (:class:`~refiner.refinement.learned_refinement.FlawRepairer`,
   one forward pass for the batch) and moved back over its planted feet
   (:mod:`refiner.core.contact`), noise is filtered; root and pose repairs are kept only when the flaw classifier
   finds the result more real (:data:`VERIFY_TYPED`). Only the flagged runs are spliced in (displacement zero at the
   kept frames, smoothstep taper), and changed frames go back on the input's bone lengths. A run that contains a
   recognised anchor is reported as an anchor refinement, the others as transition refinements. A body that glides
   over its planted feet is moved back (:mod:`refiner.refinement.skating`), and legs that show each other's motion
   are swapped back to their sides (:mod:`refiner.refinement.swapped_sides`). Last, the noise steps
   (:func:`filtered_noise`), the pose prior (:func:`prior_posed`), the texture filter
   (:func:`~refiner.refinement.texture_filter.filtered_texture`), the repeats of dropped frames put back in time
   (:mod:`refiner.refinement.repeated_frames`) and the kept frames of a rigid core's clip put on its lengths.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from refiner.core.skeletons import get_skeleton
from refiner.refinement.amplitude import restored_amplitude
from refiner.refinement.blended_pose import unblended_poses
from refiner.refinement.anchor_recognition import anchor_peaks
from refiner.refinement.concept_snap import snapped_to_concepts
from refiner.refinement.inputs import MIN_FRAMES
from refiner.refinement.repair_candidates import CANDIDATES, stall_window
from refiner.refinement.repeated_frames import unrepeated
from refiner.refinement.retrace import cut_retraces
from refiner.refinement.skating import deskated
from refiner.refinement.rigid_step import natural_bones_back, noisy_bones, rigid_at_last, rigid_first
from refiner.refinement.noise_filter import filtered_noise
from refiner.refinement.pose_prior import prior_posed
from refiner.refinement.swapped_sides import unblended_sides, unswapped
from refiner.refinement.timing_estimation import estimated_retiming
from refiner.refinement.texture_filter import filtered_texture
from refiner.refinement.report import RefinementReport, repair_words, start_reports
from refiner.refinement.splicing import project_bone_lengths, reference_lengths, splice
from refiner.refinement.training_flaws import GROUPS

__all__ = ["flag_runs", "noise_ratio", "NOISE_RATIO", "refine_clips", "refine_batch", "check_detect", "REPAIRS", "DETECTORS", "STAND_INS"]

#: ``repair="typed"``: per flagged run, the repair for the flaw group the classifier recognises
#: (:data:`TYPED_REPAIRS`); ``"select"``: the candidate (the repair network's two proposals, the hand-written
#: repairs of :mod:`refiner.refinement.repair_candidates`, or no change) the flaw classifier finds most real;
#: ``"given"``: the network sees the flagged frames; ``"infill"``: they are hidden and in-filled from the context.
REPAIRS = ("typed", "select", "given", "infill")
_GROUP_NAMES = tuple(GROUPS)
#: ``repair="typed"``: the repair for the flaw group the classifier sees most in a run, and how many frames its window
#: is widened on each side; ``"a+b"`` applies ``a``, then ``b`` to its result (a network proposal can only come first);
#: ``"a|b"`` offers both to the flaw classifier, which keeps the more real (the group must be in :data:`VERIFY_TYPED`).
#: Chosen by measurement (``examples/measure_typed_repairs.py``, which takes each variant below as
#: JSON) on the calibration subjects 9-10 of the train split (every 2nd clip, the
#: benchmark's five training families at severity 2 and clean clips; the two held-out families were
#: printed but not used to choose), share of the flaws' MPJPE removed, mean of the 7 families:
#:
#: - previous table (timing: retime, root and pose: network, noise: smooth widened by 4), classifier
#:   trained on raw flawed crops: +6.0 % (wrong_anchor -1.1, anchor_drift -1.3, jitter +13.0,
#:   frozen +28.2, time_warp -8.6); clean clips 0.020 cm, 4.7 % touched;
#: - classifier trained on rigid-projected crops (as it sees them here): detection of jitter rose
#:   from 4 to 31 of 85 clips, of wrong anchors from 16 to 48; with the planted-feet repair after the
#:   network: +9.2 %, but wrong_anchor -12.0 % (the network moved wrong poses further away);
#: - pose -> planted feet only, root -> network then planted feet: wrong_anchor still -14.3 % (a
#:   wrong walking pose makes the feet skate too); both *verified* (:data:`VERIFY_TYPED`): +12.6 %,
#:   wrong_anchor -2.1, time_warp -1.5, clean clips untouched;
#: - timing -> re-time only where the run stalls (``stall_retime``): time_warp -0.1 %, frozen +42.2 %;
#: - noise -> Gaussian smoothing sigma 1 frame, not widened: unverified it removed +23.6 % of jitter
#:   (the smoothing spline: +24.4 %, twice the time), but on the a2m reference generator's samples
#:   it smoothed 72 % of the frames and FID rose 4.343 -> 4.498 (accuracy 42.3 -> 41.6 %): the
#:   classifier's "noise" there is motion the recogniser expects. Verified, as the other groups:
#:   jitter +17.7 % (the rigid-skeleton step), a2m untouched; **+12.5 %** in all (wrong_anchor -1.8,
#:   anchor_drift -0.9, jitter +17.7, frozen +42.2, time_warp -0.1; clean clips untouched);
#: - the stall re-timing's window widened by 2 / 4 / 6 / 8 / 12 frames each side (a stall starts at the anchor,
#:   before the detector is sure): frozen +45.9 / **+49.5** / +41.2 / +36.2 / +26.4 %, time_warp -0.1 %: **+13.5 %**.
#: - the flaw denoiser (:class:`~refiner.refinement.flaw_denoiser.FlawDenoiser`, classifier retrained with
#:   limb flaws that never move the root): the shipped table +13.6 % (jitter +17.7, foot_sliding +37.8);
#:   noise -> ``denoise``, verified or not, widened by 4 or not: jitter +17.6 to +17.8 %, the same mean
#:   (unverified smoothing: +24.7 %); adding the denoiser's whole-clip correction as a detector
#:   (``detect="classifier+denoiser"``, threshold 2.6 cm at 3 % of clean clips) flagged no more drift
#:   (-0.9 %); pose -> ``denoise+planted_feet`` verified: foot_sliding 0.0 %, mean +8.2 %; unverified with
#:   that detector: anchor_drift -6.6 %, mean +12.1 %. So the denoiser stays an option, not the default.
#: - noise verified by the classifier repaired nothing: it found every smoothed run of the jittered clips
#:   *less* real than the noisy one (68 runs; mean flaw probability 0.62 -> 0.76, error 0.96 -> 0.68 cm), so
#:   noise runs are smoothed unverified where they are :data:`NOISE_RATIO` times noisier than their clip
#:   (jitter +17.7 -> +22.7 %; a2m reference generator FID 4.285 -> 4.286, 600 samples, 5 % of frames smoothed). A learned judge instead (a temporal convolution trained to estimate each frame's true
#:   error after random flaws and random hand-written repairs, 3.5 min) verified noise as well (+21.6 %) but
#:   refused good re-timings (frozen +30.9 %) and, choosing among all candidates, made time_warp -8.9 %;
#: - the stall re-timing's window grown over the stall before it and the rush after it
#:   (:func:`~refiner.refinement.repair_candidates.stall_window`, widened by 2): frozen +42.7 -> +58.9 %
#:   (widened by 0 / 2 / 4 / 6: 57.3 / 58.9 / 50.6 / 44.5 %; rush 1.2 / 1.5 / 2 times the median speed:
#:   48.6 / 50.6 / 49.6 % at widening 4); growing to the recognised anchors or to the flawed clip's own
#:   segmentation anchors instead: 42.6 / 40.4 %; **+16.6 %** in all.
#: - the rigid skeleton on bone lengths drawn toward learned proportions (``Refiner(rigid_lengths=)``):
#:   anchor_drift -0.9 -> +12.6 %, wrong_anchor -2.1 -> -1.7 %, **+18.6 %** in all; then the stall
#:   re-timing only where a rush follows the stop (``stall_retime_run(rush=1.5)``): every figure here unchanged (its
#:   reason lies in the benchmark subjects: a time-warped clip ending at rest was re-timed over it, +4.7 cm; -1.1 -> -0.4 %).
#: - noise -> the learned noise filter (:mod:`refiner.refinement.noise_filter`): jitter +22.7 -> +23.0 %; with its last step (clips noisy throughout) 22.3 %, **+18.3 %** in all (README).
#: - root -> the network then planted feet, or the body put back on the ground (``grounded``): ``"a|b"`` gives the
#:   classifier both to choose from (a verified group). The network's proposal never looked more real on a floating
#:   body (``examples/measure_body_recipes.py``, subjects 11-12): raised 10 cm over 15-40 frames -0.2 -> +40.5 %,
#:   sunk 5 cm +0.8 -> +16.0 %; calibration wrong_anchor 2.6 -> 2.1 %, the others within 0.1; bench wrong_anchor
#:   1.07 -> 0.93 %, mean of 7 40.47 -> 40.46 %. ``grounded`` from the lowest foot alone: calibration wrong_anchor 1.3 %.
TYPED_REPAIRS = {"timing": ("stall_retime", 2), "root": ("network+planted_feet|grounded", 0), "pose": ("planted_feet", 0),
                 "noise": ("noise_filter", 0)}
#: Groups whose typed repair is kept only when the flaw classifier finds the result more real than the given frames
#: (:func:`_select` with the one candidate): a body moved back over skating feet or a network correction is right for
#: gliding and floating bodies and wrong for a wrong pose, which skates too. Re-timing stays unverified: the classifier
#: rejected most re-timed stalls, which remove 42 % there; so does smoothing, which it cannot judge (:data:`NOISE_RATIO`).
VERIFY_TYPED = ("root", "pose")
#: A noise run is repaired only where it is this many times noisier (jitter residual: distance from a
#: Gaussian smoothing of sigma 1 frame) than its clip's median frame: noise is a local flaw, and a
#: clip that is as rough everywhere has that texture from its generator (see :func:`noise_ratio`).
NOISE_RATIO = 1.3
#: A timing run is grown over the stall before it and the rush after it (:func:`stall_window`) before it is re-timed; False: the widened run alone (frozen 58.9 % vs 50.6 %).
STALL_WINDOW = True
#: Detectors that can flag frames (``detect="classifier+recognizer"``: the union): the kinematic flaw classifier,
#: the recognition network's flaw probability, the repair network's or the denoiser's correction.
DETECTORS = ("classifier", "recognizer", "correction", "denoiser")


def check_detect(detect: str) -> str:
    """Validate a ``"+"``-joined list of :data:`DETECTORS`."""
    names = str(detect).split("+")
    if not detect or any(n not in DETECTORS for n in names):
        raise ValueError(f"unknown detect {detect!r}; use one or more of {', '.join(DETECTORS)} joined by '+'.")
    return detect


#: The hand-written repair that stands in for a network's proposal when the weights lack that network.
STAND_INS = {"denoise": "smooth", "motion_infill": "network_infill", "noise_filter": "smooth"}
_ANCHOR_THRESHOLD = 0.3
#: Frames on each side of a run that the selection's flaw score also covers (the seams); frames by which
#: the hand-written repairs' window is also widened on each side.
_SCORE_CONTEXT, _WIDEN = 4, (0, 4, 8)


def noise_ratio(y: np.ndarray, lo: int, hi: int) -> float:
    """Jitter residual of frames ``lo..hi-1`` of ``y (T, J, 3)`` over the clip's median frame's.

    The flaw classifier cannot verify a smoothing: on the calibration subjects' jittered clips it
    found the smoothed runs *less* real than the noisy ones in every one of 68 runs (mean flaw
    probability 0.62 -> 0.76) while they were nearer the clean clip (0.96 -> 0.68 cm). This ratio
    tells the seeded noise (median 1.5, 75 % of runs above 1.3) from the a2m reference generator's
    texture (the classifier sees noise in 68 % of its frames; median ratio 1.1, 90 % under 1.3)."""
    res = np.linalg.norm(y - gaussian_filter1d(y.astype(np.float64), 1.0, axis=0, mode="nearest"), axis=-1).mean(-1)
    return float(res[lo:hi].mean() / max(float(np.median(res)), 1e-9))


def flag_runs(prob: np.ndarray, threshold: float, *, min_run: int = 2, margin: int = 2,
              low: float | None = None) -> list[tuple[int, int]]:
    """Runs ``[start, stop)`` of at least ``min_run`` frames with ``prob (T,)`` above ``threshold``,
    extended on both sides while ``prob`` stays above ``low`` (hysteresis; default ``threshold``),
    widened by ``margin`` frames each side and merged where they touch."""
    low = threshold if low is None else min(low, threshold)
    above = np.r_[False, prob > threshold, False]
    edges = np.flatnonzero(np.diff(above.astype(np.int8)))
    runs = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_run]
    out: list[list[int]] = []
    for a, b in runs:
        while a > 0 and prob[a - 1] > low:
            a -= 1
        while b < len(prob) and prob[b] > low:
            b += 1
        a, b = max(a - margin, 0), min(b + margin, len(prob))
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def _select(refiner, y, spliced: dict, lo: int, hi: int, penalty: float | None = None) -> tuple[str, str]:
    """The candidate the flaw classifier finds most real around ``[lo, hi)``, with a small price per
    centimetre moved (``penalty``, default ``refiner.change_penalty``); "keep" (no change) is a candidate too."""
    names = ["keep", *spliced]
    clips = np.stack([y, *spliced.values()])
    prob = refiner.flaw_classifier.predict(clips)
    w0, w1 = max(lo - _SCORE_CONTEXT, 0), min(hi + _SCORE_CONTEXT, len(y))
    moved = 100 * np.linalg.norm(clips[:, lo:hi] - y[lo:hi], axis=-1).mean((1, 2))
    score = prob[:, w0:w1].mean(1) + (refiner.change_penalty if penalty is None else penalty) * moved
    best = int(np.argmin(score))
    note = f"; chosen among {len(names)} candidates, flaw probability {prob[0, w0:w1].mean():.2f} -> " \
           f"{prob[best, w0:w1].mean():.2f}"
    if best == 0:
        return "keep", "no candidate looked more real than the given frames; kept"
    return names[best], note


def _repair_run(refiner, y, lo, hi, proposals: dict, groups, original, skel):
    """Repair one flagged run; returns ``(repair name, (start, stop), new clip, note)``."""

    def spliced(proposal, a, c):
        return splice(y, proposal, a, c, blend=refiner.blend, keep_start=a > 0, keep_end=c < len(y))

    if refiner.repair == "typed":
        share = groups[lo:hi].mean(0)
        group = _GROUP_NAMES[int(np.argmax(share))]
        name, widen = TYPED_REPAIRS[group]
        if group == "noise" and (ratio := noise_ratio(y, lo, hi)) < NOISE_RATIO:
            return "keep", (lo, hi), y, (f"looks like noise, but no noisier than the rest of the clip (jitter "
                                         f"{ratio:.2f} times the clip's median, under {NOISE_RATIO}); kept")
        a, c = max(lo - widen, 0), min(hi + widen, len(y))
        if group == "timing" and STALL_WINDOW:
            a, c = stall_window(y, a, c)
        options = {}
        for option in name.split("|"):  # alternatives: the flaw classifier chooses (the group is verified)
            option = "+".join(p if p in proposals else STAND_INS.get(p, p) for p in option.split("+"))  # weights without it
            proposal = y
            for k, part in enumerate(option.split("+")):  # applied left to right
                if part in proposals and k > 0:
                    raise ValueError(f"typed repair {option!r}: a network proposal ({part!r}) can only come first.")
                proposal = proposals[part] if part in proposals else CANDIDATES[part](proposal, a, c, skel)
            options[option + (f" (widened by {widen})" if widen else "")] = spliced(proposal, a, c)
        note = f"; looks like a {group} flaw (group probability {share.max():.2f})"
        if len(options) > 1 and group not in VERIFY_TYPED:
            raise ValueError(f"typed repair {name!r}: alternatives need the group {group!r} verified (VERIFY_TYPED).")
        name, new = next(iter(options.items()))
        if group in VERIFY_TYPED:
            chosen, why = _select(refiner, y, options, a, c)
            if chosen == "keep":
                return "keep", (a, c), y, f"the {' or '.join(options)} repair did not look more real than the given frames; kept"
            name, new, note = chosen, options[chosen], note + why
        return name, (a, c), new, note
    if refiner.repair != "select":
        name = next(iter(proposals))
        return name, (lo, hi), spliced(proposals[name], lo, hi), ""
    # the hand-written repairs on the run and on the run widened (a stall or a reversal spans a whole
    # transition; the detector may see only part of it), scored on the input's bone lengths
    windows, candidates = {}, {n: spliced(p, lo, hi) for n, p in proposals.items()}
    for w in _WIDEN:
        a, c = max(lo - w, 0), min(hi + w, len(y))
        if (a, c) not in windows.values():
            windows[f" (widened by {w})" if w else ""] = (a, c)
    for suffix, (a, c) in windows.items():
        for name, fn in CANDIDATES.items():
            candidates[name + suffix] = spliced(fn(y, a, c, skel), a, c)
    span = (min(a for a, _ in windows.values()), max(c for _, c in windows.values()))
    touched = np.zeros(len(y), bool)
    touched[span[0] : span[1]] = True
    reference = reference_lengths(original, refiner.skeleton)
    candidates = {n: project_bone_lengths(c, reference, touched, refiner.skeleton) for n, c in candidates.items()}
    name, note = _select(refiner, y, candidates, *span)
    if name == "keep":
        return name, (lo, hi), y, note
    window = windows.get(name[len(name.split(" (")[0]):], (lo, hi))
    return name, window, candidates[name], note


def refine_clips(refiner, clips: np.ndarray, actions: list, mode: str, batched: bool
                 ) -> tuple[list[np.ndarray], list[RefinementReport]]:
    """Refine ``clips (B, T, J, 3)`` with ``refiner``'s learned steps, the whole batch at once; their
    given ``actions`` (None: to infer) are checked first (a batch's errors name the clip)."""
    reports = start_reports(clips.shape[1], actions, mode, refiner.action_names, batched=batched)
    x = np.array(clips, dtype=np.float32, copy=True)
    if x.shape[1] < MIN_FRAMES:  # returned as given (the reports say so)
        return list(x), reports
    return list(refine_batch(refiner, x, [r.action for r in reports], mode, reports)), reports


def refine_batch(refiner, clips: np.ndarray, actions: list, mode: str, reports: list) -> np.ndarray:
    """Refine ``clips (B, T, J, 3)`` float32 with ``refiner``'s learned steps, filling ``reports`` in place."""
    clips = unblended_sides(refiner, clips, reports, mode)  # before the rigid step rebuilds crossed hips
    clips = unblended_poses(refiner, clips, reports, mode)  # ... or puts blended bones back on their lengths
    given, (clips, cored, drifting) = clips, rigid_first(refiner, clips, reports)
    rigid = clips
    clips = restored_amplitude(refiner, clips, actions, reports)  # a damped clip: every detector misjudges it
    clips = estimated_retiming(refiner, clips, reports, mode)  # timing first
    use_rec, use_cor, use_clf, use_den = (n in refiner.detect.split("+") for n in ("recognizer", "correction", "classifier", "denoiser"))
    clf_all = (refiner.flaw_classifier.predict_all(clips) if use_clf or refiner.repair == "typed" or (refiner.denoising in ("filter", "runs")
               and getattr(refiner, "flaw_classifier", None) is not None) else None)  # noise runs: filtered_noise
    cut = cut_retraces(refiner, clips, reports, mode, None if clf_all is None else clf_all[..., 0])
    if clf_all is not None and (again := np.flatnonzero((cut != clips).any(axis=(1, 2, 3)))).size:
        clf_all[again] = refiner.flaw_classifier.predict_all(cut[again])  # a cut clip is judged anew
    misread = getattr(refiner, "misread_snap", 0.0) > 0 and mode != "transition"  # the snap reads every clip's action
    clips, rec, threshold = cut, refiner.flaw_recognizer.predict(cut, actions, estimate_action=misread), float(refiner.flaw_recognizer.threshold_)
    if use_clf:
        clf, clf_threshold = clf_all[..., 0], float(refiner.flaw_classifier.threshold_)
    if use_cor:
        correction = refiner.flaw_repairer.correction(clips, actions)
        cor_threshold = float(refiner.flaw_repairer.correction_threshold_)
    if use_den:
        denoised, den_threshold = refiner.flaw_denoiser.correction(clips), float(refiner.flaw_denoiser.threshold_)
    runs_per_clip, suspect = [], np.zeros(clips.shape[:2], bool)
    for b, report in enumerate(reports):
        if report.action is None:
            report.action, report.action_inferred = int(np.argmax(rec["action"][b])), True
        elif misread:
            report.recognized_action, report.action_probability = int(np.argmax(rec["action"][b])), round(float(rec["action"][b][report.action]), 4)
        report.action_name = refiner.action_names[report.action] if refiner.action_names else None
        anchors = anchor_peaks(rec["anchor"][b], _ANCHOR_THRESHOLD)
        report.anchors, report.anchor_probability = anchors.tolist(), [round(float(p), 4) for p in rec["anchor"][b]]
        primary = clf[b] if use_clf else rec["flaw"][b]
        report.flaw_probability = [round(float(p), 4) for p in primary]
        report.anchor_scores = [round(float(1 - rec["flaw"][b][a]), 3) for a in anchors]
        report.threshold = round(clf_threshold if use_clf else threshold, 4)
        # a frame is flagged by either detector; flag_runs on the max of the two normalised scores
        score = np.zeros(clips.shape[1])
        if use_rec:
            score = np.maximum(score, rec["flaw"][b] / max(threshold, 1e-9))
        if use_clf:
            score = np.maximum(score, clf[b] / max(clf_threshold, 1e-9))
        if use_cor:
            report.correction_cm = [round(100 * float(c), 3) for c in correction[b]]
            score = np.maximum(score, correction[b] / max(cor_threshold, 1e-9))
        if use_den:
            report.denoiser_correction_cm = [round(100 * float(c), 3) for c in denoised[b]]
            score = np.maximum(score, denoised[b] / max(den_threshold, 1e-9))
        runs = flag_runs(score, 1.0, min_run=refiner.min_run, margin=refiner.margin, low=refiner.hysteresis)
        kinds = []
        for lo, hi in runs:
            has_anchor = bool(((anchors >= lo) & (anchors < hi)).any())
            kinds.append("anchor" if has_anchor else "transition")
        runs = [(r, k) for r, k in zip(runs, kinds) if mode == "full" or mode == k]
        runs_per_clip.append(runs)
        for (lo, hi), _ in runs:
            suspect[b, lo:hi] = True
    out = clips.copy()
    todo = np.flatnonzero(suspect.any(1))
    if todo.size:
        acts = [reports[b].action for b in todo]
        proposals = {}
        groups = clf_all[..., 1:] if refiner.repair == "typed" else None
        typed = {p for name, _ in TYPED_REPAIRS.values() for p in name.split("+")} if refiner.repair == "typed" else set()
        if refiner.repair in ("given", "select") or "network" in typed:
            proposals["network"] = refiner.flaw_repairer.repair(clips[todo], suspect[todo], acts)
        stand_in = "motion_infill" in typed and refiner.motion_infiller is None
        if refiner.repair in ("infill", "select") or "network_infill" in typed or stand_in:
            proposals["network_infill"] = refiner.flaw_repairer.repair(clips[todo], suspect[todo], acts, hide=True)
        if "denoise" in typed and refiner.flaw_denoiser is not None:
            proposals["denoise"] = refiner.flaw_denoiser.denoise(clips[todo], suspect[todo])
        if "noise_filter" in typed and getattr(refiner, "noise_filter", None) is not None:  # clips with noise runs only
            noisy = [k for k, b in enumerate(todo) if any(_GROUP_NAMES[int(np.argmax(groups[b][lo:hi].mean(0)))] == "noise"
                                                          for (lo, hi), _ in runs_per_clip[b])]
            proposals["noise_filter"] = clips[todo].copy()
            if noisy:
                proposals["noise_filter"][noisy] = refiner.noise_filter.denoise(
                    clips[todo][noisy], residual=getattr(refiner, "noise_residual", None))
        if "motion_infill" in typed and refiner.motion_infiller is not None:
            proposals["motion_infill"] = refiner.motion_infiller.infill(clips[todo], suspect[todo])
        skel = get_skeleton(refiner.skeleton)
        for k, b in enumerate(todo):
            y, changed = clips[b].copy(), np.zeros(len(clips[b]), bool)
            report = reports[b]
            for (lo, hi), kind in runs_per_clip[b]:
                evidence = []
                if use_clf:
                    evidence.append(f"kinematic flaw probability up to {float(np.max(clf[b][lo:hi])):.2f} "
                                    f"(threshold {clf_threshold:.2f})")
                if use_rec:
                    evidence.append(f"flaw probability up to {float(np.max(rec['flaw'][b][lo:hi])):.2f} "
                                    f"(threshold {threshold:.2f})")
                if use_cor:
                    evidence.append(f"repair correction up to {100 * float(np.max(correction[b][lo:hi])):.1f} cm "
                                    f"(threshold {100 * cor_threshold:.1f} cm)")
                if use_den:
                    evidence.append(f"denoiser correction up to {100 * float(np.max(denoised[b][lo:hi])):.2f} cm "
                                    f"(threshold {100 * den_threshold:.2f} cm)")
                name, (lo, hi), y_new, note = _repair_run(refiner, y, lo, hi, {n: p[k] for n, p in proposals.items()},
                                                          None if groups is None else groups[b], clips[b], skel)
                if name != "keep" and np.array_equal(y_new, y):  # e.g. a timing run with no stall to re-time
                    name, note = "keep", f"the {name} repair changed nothing; kept"
                if name == "keep":
                    report.notes.append(f"frames {lo}-{hi - 1} flagged ({', '.join(evidence)}); {note}")
                    continue
                y = y_new
                changed[lo:hi] = True
                moved = 100 * float(np.linalg.norm(y[lo:hi] - clips[b][lo:hi], axis=-1).mean())
                report.changes.append({"start": lo, "stop": hi, "step": kind, "repair": name, "reason":
                                       f"flagged: {', '.join(evidence)}; {repair_words(name)} "
                                       f"(moved {moved:.1f} cm on average){note}"})
                if kind == "anchor":
                    inside = [a for a in report.anchors if lo <= a < hi]
                    report.flagged_anchors.extend(inside)
                    report.refined_anchors.extend({"frame": a, "method": name} for a in inside)
                else:
                    report.flagged_transitions.append([lo, hi])
            out[b] = project_bone_lengths(y, reference_lengths(clips[b], refiner.skeleton), changed, refiner.skeleton)
    out = deskated(refiner, out, reports, mode)  # a body gliding over its planted feet
    out = unswapped(refiner, out, reports, mode, _select)  # after the run repairs: a reversed run's turn swaps legs too
    noise = None if clf_all is None else np.maximum(clf_all[..., 1 + _GROUP_NAMES.index("noise")],  # before any snap
                                                    noisy_bones(refiner, given, cored))  # bones too
    out, noisy = filtered_noise(refiner, snapped_to_concepts(refiner, out, reports, mode), reports, noise, (out != clips).any((2, 3)), mode)
    out = filtered_texture(refiner, prior_posed(refiner, out, reports, drifting, noisy), reports, noisy)
    out = unrepeated(refiner, out, reports, mode)  # last: re-timing steps read its in-between frames as mistimed
    return natural_bones_back(refiner, rigid_at_last(refiner, out, reports, cored), given, rigid, reports)

