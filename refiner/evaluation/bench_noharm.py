"""``motion-refiner bench noharm``: does refinement do harm? Generated clips measured before and after refining.

**Sets** (each a list of clips on one skeleton, with recogniser labels where known):

- ``a2m_humanact12_xyz``: Action2Motion's xyz-VAE samples (20 x 60 frames), converted by the ``action2motion``
  adapter (``representation="xyz"``, frame-0 root subtracted) as ``bench samples`` does; refined with their labels.
- ``a2m_humanact12_lie``: the Lie-VAE samples decoded by the adapter (``representation="lie"``, forward kinematics
  with its default bone lengths). Their label file was rewritten by a resumed run and may not match the clips:
  accuracy is reported all the same, and the refiner is told no action (``None``).
- ``a2m_ntu13``: the 18-joint NTU13 samples on skeleton ``uestc``, the NTU13 recogniser; action unknown to the
  refiner (NTU13 classes are not HumanAct12's).
- ``a2m_cmu``: the CMU-Mocap xyz-VAE samples (20 x 100 frames, skeleton ``cmu_mocap``): frame-0 root subtracted,
  then times ``20 * _CMU_UNIT_METRES`` (they are at the CMU recogniser's scale, raw CMU units / 20; the project
  keeps CMU motion in metres, :func:`refiner.io.datasets.load_cmu_mocap`, and the recogniser scales back by
  ``1 / (20 * _CMU_UNIT_METRES)``). Refined with their labels (CMU classes).
- ``gen_<kind>``: each shipped reference generator (:data:`refiner.reference.GENERATOR_KINDS`), 5 samples per
  HumanAct12 action (quick: 1; a diffusion generator with 10 sampling steps in quick mode only), refined with
  the sampled action.

**Figures** (mean over clips of per-clip values; every clip at 20 fps):

- ``jerk``: :func:`~refiner.evaluation.physics.jerk`, mean joint jerk magnitude (third difference x fps³), m/s³.
- ``foot_skating``: :func:`~refiner.evaluation.ground_metrics.foot_skating_ratio` (GMD), share of frame pairs in
  which a foot slides. A foot (HumanAct12 ``left/right_foot``, uestc heels, CMU toes) is *in contact* in a frame
  pair when its height above the ground is under **5 cm** in both frames; it *slides* when, in contact, its
  horizontal speed is over **0.5 m/s** (2.5 cm per frame) both in that pair and averaged over a centred window of
  **5** pairs. Real HumanML3D scores about 0.05, not 0.
- ``penetration_cm`` / ``floating_cm``: :func:`~refiner.evaluation.ground_metrics.penetration` /
  :func:`~refiner.evaluation.ground_metrics.floating` (PhysDiff, on joints): per frame how far the lowest joint is
  below the ground / above it less a **5 mm** tolerance, mean over frames, cm. The **ground** of a clip is the
  lowest height its contact joints (ankles and feet) reach over the clip (:func:`ground_height`); an *after*
  clip is judged against its *before* clip's ground (skating too), so a refiner that sinks or lifts a clip shows.
  Against its own ground a clip's feet never penetrate.
- ``bone_length_variation_pct``: :func:`~refiner.evaluation.physics.bone_length_variation`, per bone std / mean
  of its length over the clip, mean over bones, %.
- ``accuracy_pct``: the set's Action2Motion recogniser (HumanAct12, NTU13 or CMU) on its labels, mean (and std)
  over 20 random N(0, 1) GRU hidden states (quick: 5), seeds shared by before and after; start crops of 60 frames
  (CMU 100); real clips random crops (the protocol).
- after only: ``cm_moved`` (mean per-joint displacement from before, all frames), ``cm_moved_changed_frames``
  (the same over changed frames only), ``frames_changed`` / ``clips_changed`` (shares; a frame is changed when a
  joint moved more than :data:`CHANGED_M`), ``seconds`` (refinement wall time of the set, weights loaded before).

**Real rows** (``real``): the same figures on real clips of each skeleton: HumanAct12 subjects 11-12 (test split),
CMU-Mocap's held-out subjects (``load_cmu_mocap().split("test")``); quick: every 8th clip; clips under 4 frames
(jerk's minimum; two CMU ones) left out and counted. None for uestc / NTU13.

**Verdict** per set (:data:`TOLERANCES`): a figure is *worse* when after exceeds before beyond its tolerance:
jerk by more than 5 %; foot skating at all (above 1e-9, float noise); penetration or floating by more than
0.05 cm (half a millimetre: rigid-bone corrections move the lowest joint by fractions of one); bone-length
variation when it rises and ends at 1 % or more; accuracy when it drops by more than 1 point. ``violated`` lists
the worse figures.

**The refiner**: ``refine(clips (B, T, J, 3), skeleton, actions) -> (B, T, J, 3)``, called once per set and clip
length; default :class:`DefaultRefine`, ``MotionRefiner.pretrained(skeleton, weights=weights)`` (a set whose
skeleton has no motion model is ``skipped``).

The record (``noharm.json``): ``sets`` (name -> ``skeleton``, ``clips``, ``recognizer``, ``refine_actions``,
``note``, ``before``, ``after``, ``verdict``), ``real`` (skeleton -> figures and ``clips``, or ``none``),
``skipped`` (set -> why), ``thresholds``, ``units``, ``tolerances``, ``n_hidden``, ``refiner``, ``quick``, ``seconds``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from refiner.evaluation.bench_setup import Progress, ignore_progress, one_thread, write_record
from refiner.evaluation.ground_metrics import floating, foot_skating_ratio, ground_height, penetration
from refiner.evaluation.physics import bone_length_variation, jerk
from refiner.io.data_sources import missing_message
from refiner.io.datasets import _CMU_UNIT_METRES, default_data_dir

__all__ = ["bench_noharm", "ClipSet", "DefaultRefine", "physical_figures", "movement", "verdict", "refine_by_length",
           "TOLERANCES", "THRESHOLDS", "UNITS", "CHANGED_M", "A2M_SETS"]

#: ``refine(clips (B, T, J, 3), skeleton, actions) -> (B, T, J, 3)``: the refiner measured.
RefineFn = Callable[[np.ndarray, str, list], np.ndarray]

#: A joint moved more than this (metres) marks its frame as changed.
CHANGED_M = 1e-5
#: The metrics' thresholds (their defaults), as written into the record.
THRESHOLDS = {
    "contact_height_m": 0.05, "skating_speed_m_s": 0.5, "skating_window_frames": 5,
    "ground": "per clip, the lowest height its contact joints reach; after clips use their before clip's",
    "floating_tolerance_m": 0.005, "changed_frame_m": CHANGED_M, "fps": 20.0,
}
#: What each figure is, as written into the record.
UNITS = {"jerk": "m/s^3, mean joint jerk magnitude", "foot_skating": "share of frame pairs with a sliding foot",
         "penetration_cm": "cm, lowest joint below the ground, mean over frames",
         "floating_cm": "cm, lowest joint above the ground less the tolerance, mean over frames",
         "bone_length_variation_pct": "%, per bone std / mean length over the clip, mean over bones",
         "accuracy_pct": "%, recogniser accuracy on the labels, mean over random hidden states",
         "cm_moved": "cm, mean per-joint displacement, all frames", "cm_moved_changed_frames": "cm, changed frames",
         "frames_changed": "share of frames", "clips_changed": "share of clips", "seconds": "refinement wall time"}
#: Verdict rules: (figure, kind, tolerance). ``relative``: worse when after > before * (1 + tol); ``up``: when
#: after > before + tol; ``level``: when after > before and after >= tol; ``down``: when after < before - tol.
TOLERANCES = (("jerk", "relative", 0.05), ("foot_skating", "up", 1e-9), ("penetration_cm", "up", 0.05),
              ("floating_cm", "up", 0.05), ("bone_length_variation_pct", "level", 1.0), ("accuracy_pct", "down", 1.0))
#: The Action2Motion sample sets: name -> (file stem, representation, skeleton, recogniser).
A2M_SETS = {"a2m_humanact12_xyz": ("humanact12_xyz_vae", "xyz", "humanact12", "humanact12"),
            "a2m_humanact12_lie": ("humanact12_lie_vae", "lie", "humanact12", "humanact12"),
            "a2m_ntu13": ("ntu13_xyz_vae", "xyz", "uestc", "ntu13"),
            "a2m_cmu": ("cmu_xyz_vae", "xyz", "cmu_mocap", "cmu_mocap")}


@dataclass
class ClipSet:
    """Clips of one skeleton: ``labels`` for the recogniser (None: none), ``actions`` for the refiner."""

    skeleton: str
    clips: list
    labels: np.ndarray | None
    actions: list
    recognizer: str | None
    note: str = ""


class DefaultRefine:
    """``MotionRefiner.pretrained(skeleton, weights=weights).refine(clips, action=actions)``, one
    refiner per skeleton, loaded on first use or by :meth:`load`."""

    def __init__(self, weights: Path | None = None) -> None:
        self.weights, self._refiners = weights, {}

    def load(self, skeleton: str):
        if skeleton not in self._refiners:
            # imports torch: here, so that importing the suites stays cheap
            from refiner.refinement.motion_refiner import MotionRefiner

            self._refiners[skeleton] = MotionRefiner.pretrained(skeleton, weights=self.weights)
        return self._refiners[skeleton]

    def __call__(self, clips: np.ndarray, skeleton: str, actions: list) -> np.ndarray:
        return np.asarray(self.load(skeleton).refine(clips, action=list(actions)))


def refine_by_length(refine: RefineFn, clips: Sequence[np.ndarray], skeleton: str, actions: Sequence) -> list:
    """``refine`` called once per clip length (a batch of the clips of that length); the clips back in order."""
    out: list = [None] * len(clips)
    for n in sorted({len(c) for c in clips}):
        idx = [i for i, c in enumerate(clips) if len(c) == n]
        refined = np.asarray(refine(np.stack([clips[i] for i in idx]).astype(np.float32), skeleton,
                                    [actions[i] for i in idx]))
        if refined.shape != (len(idx), *clips[idx[0]].shape):
            raise ValueError(f"`refine` returned shape {refined.shape} for clips {(len(idx), *clips[idx[0]].shape)}.")
        for i, r in zip(idx, refined):
            out[i] = r
    return out


def physical_figures(clips: Sequence[np.ndarray], skeleton: str, grounds=None) -> dict:
    """Means over ``clips`` of jerk, foot skating, penetration, floating and bone-length variation (see the module
    docstring); ``grounds``: per-clip ground heights (default each clip's own estimate)."""
    grounds = [None] * len(clips) if grounds is None else grounds
    rows = [(jerk(c, skeleton=skeleton), foot_skating_ratio(c, skeleton=skeleton, ground=g),
             100 * penetration(c, skeleton=skeleton, ground=g), 100 * floating(c, skeleton=skeleton, ground=g),
             100 * bone_length_variation(c, skeleton=skeleton)) for c, g in zip(clips, grounds)]
    keys = ("jerk", "foot_skating", "penetration_cm", "floating_cm", "bone_length_variation_pct")
    return {k: float(np.nanmean(v)) for k, v in zip(keys, zip(*rows))}


def _accuracy(recognizer, clips, labels, n_hidden: int, crop: str) -> dict:
    """Recogniser accuracy (%) over ``n_hidden`` random hidden states (seeds 0.., shared by every call)."""
    acc = [100 * float(np.mean(recognizer.predict(list(clips), crop=crop, random_state=s) == labels))
           for s in range(n_hidden)]
    return {"accuracy_pct": float(np.mean(acc)), "accuracy_std_pct": float(np.std(acc))}


def movement(before: Sequence[np.ndarray], after: Sequence[np.ndarray]) -> dict:
    """cm moved (all frames; changed frames), and the shares of frames and clips changed (:data:`CHANGED_M`)."""
    d = [np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=-1) for b, a in zip(before, after)]
    changed = [x.max(-1) > CHANGED_M for x in d]
    moved = np.concatenate([x[c].ravel() for x, c in zip(d, changed)])
    return {"cm_moved": float(100 * np.mean([x.mean() for x in d])),
            "cm_moved_changed_frames": float(100 * moved.mean()) if moved.size else 0.0,
            "frames_changed": float(np.mean([c.mean() for c in changed])),
            "clips_changed": float(np.mean([c.any() for c in changed]))}


def verdict(before: dict, after: dict) -> dict:
    """Per figure of :data:`TOLERANCES` present in both rows, whether after is worse; ``violated``: those that are."""
    out = {}
    for key, kind, tol in TOLERANCES:
        if before.get(key) is None or after.get(key) is None:
            continue
        b, a = before[key], after[key]
        out[key] = bool({"relative": a > b * (1 + tol), "up": a > b + tol, "level": a > b + 1e-4 and a >= tol,  # 1e-4 points: float error of rebuilt frames
                        
                         "down": a < b - tol}[kind])
    out["violated"] = [k for k, worse in out.items() if worse]
    return out


def _a2m_set(folder: Path, name: str, quick: bool) -> ClipSet | str:
    """One Action2Motion sample set (see the module docstring), or why it is missing."""
    from refiner.plugins.manager import convert

    stem, representation, skeleton, recognizer = A2M_SETS[name]
    path, labels_path = folder / f"{stem}_samples.npy", folder / f"{stem}_labels.npy"
    if not (path.is_file() and labels_path.is_file()):
        return missing_message("samples", path if not path.is_file() else labels_path)
    raw, labels = np.load(path), np.load(labels_path).astype(np.int64).ravel()
    if skeleton == "cmu_mocap":  # not an adapter format: (N, T, 60) at the recogniser's scale, root not at 0
        x = raw.reshape(len(raw), raw.shape[1], 20, 3).astype(np.float64)
        clips = list(((x - x[:, :1, :1]) * (20.0 * _CMU_UNIT_METRES)).astype(np.float32))
    else:
        clips = [m.joints for m in convert("action2motion", raw, representation=representation, recenter=True,
                                           skeleton=skeleton)]
    n = 5 if quick else len(clips)
    lie, ntu = representation == "lie", skeleton == "uestc"
    note = ("label file rewritten by a resumed run: labels may not match the clips, accuracy is reported anyway; "
            "the refiner is told no action" if lie else
            "NTU13 classes: the refiner (HumanAct12 weights through the uestc conversion) is told no action" if ntu
            else "")
    actions = [None] * n if lie or ntu else [int(a) for a in labels[:n]]
    return ClipSet(skeleton, clips[:n], labels[:n], actions, recognizer, note)


def _generator_sets(quick: bool) -> dict:
    """``gen_<kind>``: every shipped reference generator's samples, ``per_action`` per HumanAct12 action."""
    from refiner.reference import GENERATOR_KINDS, load_reference_generator

    sets = {}
    for kind in GENERATOR_KINDS:
        gen = load_reference_generator(kind)
        if quick and "sampling_steps" in gen.get_params():
            gen.set_params(sampling_steps=10)
        motions = [m for a in range(12) for m in gen.sample_motions(a, 1 if quick else 5, random_state=1000 * a + 7)]
        note = "10 sampling steps (quick)" if quick and "sampling_steps" in gen.get_params() else ""
        sets[f"gen_{kind}"] = ClipSet("humanact12", [m.joints for m in motions], np.array([m.action for m in motions]),
                                      [int(m.action) for m in motions], "humanact12", note)
    return sets


def _recognizer(name: str, data: Path | None):
    from refiner.evaluation.evaluators import load_recognizer  # imports torch

    # without ``data``: HumanAct12's packaged copy, the others from evaluators_dir()
    return load_recognizer(name, hidden="random", directory=None if data is None else Path(data).parent / "evaluators")


def _real_rows(data: Path | None, skeletons: set, quick: bool, recognizers: dict, n_hidden: int) -> dict:
    """The real data's own figures per skeleton of the sets (or why none)."""
    from refiner.io.datasets import load_cmu_mocap, load_humanact12

    root = default_data_dir() if data is None else Path(data)
    sources = {"humanact12": ("HumanAct12 subjects 11-12 (test split)",
                              lambda: load_humanact12(root / "humanact12" / "humanact12_joints.npz")),
               "cmu_mocap": ("CMU-Mocap held-out subjects (test split)",
                             lambda: load_cmu_mocap(root / "cmu_mocap" / "cmu_mocap_labeled_joints.npz"))}
    rows = {}
    for skel in sorted(skeletons):
        if skel not in sources:
            rows[skel] = {"none": f"no real {skel} clips available (NTU13 / UESTC data are not in ../shared)"}
            continue
        source, load = sources[skel]
        try:
            motions = load().split("test").motions[:: 8 if quick else 1]
        except ValueError as e:
            rows[skel] = {"none": str(e)}
            continue
        short = sum(m.n_frames < 4 for m in motions)  # jerk needs 4 frames (CMU has 3-frame clips)
        motions = [m for m in motions if m.n_frames >= 4]
        clips = [m.joints for m in motions]
        row = {"source": source, "clips": len(clips), "excluded_under_4_frames": short, **physical_figures(clips, skel)}
        if skel in recognizers:
            row.update(_accuracy(recognizers[skel], clips, np.array([m.action for m in motions]), n_hidden, "random"))
        rows[skel] = row
    return rows


@one_thread()
def bench_noharm(data: Path | None, out: Path | None, quick: bool, *, progress: Progress | None = None,
                 weights: Path | None = None, refine: RefineFn | None = None,
                 sets: Sequence[str] | None = None) -> dict:
    """Every set before and after ``refine`` (see the module docstring); writes ``noharm.json``.

    ``quick``: 5 clips per Action2Motion set, 1 sample per action per generator, 5 hidden states, every 8th real
    clip. ``refine``: the refiner measured (default :class:`DefaultRefine` with ``weights``, a folder of weight sets
    looked in before the shipped ones). ``sets``: only these set names (default all). Progress event ``"set"``:
    ``name``, ``before``, ``after``, ``verdict`` of each set as it is done.
    """
    t_start = time.perf_counter()
    progress = progress or ignore_progress
    default = refine is None
    refine = DefaultRefine(weights) if default else refine
    folder = (default_data_dir() if data is None else Path(data)).parent / "samples" / "action2motion"
    wanted = None if sets is None else set(sets)
    clip_sets, skipped = {}, {}
    for name in A2M_SETS:
        if wanted is None or name in wanted:
            s = _a2m_set(folder, name, quick)
            (skipped if isinstance(s, str) else clip_sets)[name] = s
    if wanted is None or any(n.startswith("gen_") for n in wanted):
        clip_sets.update({k: v for k, v in _generator_sets(quick).items() if wanted is None or k in wanted})
    n_hidden = 5 if quick else 20
    recognizers = {}
    for s in clip_sets.values():
        rec_skel = {"humanact12": "humanact12", "ntu13": "uestc", "cmu_mocap": "cmu_mocap"}[s.recognizer]
        if rec_skel not in recognizers:
            try:
                recognizers[rec_skel] = _recognizer(s.recognizer, data)
            except ValueError as e:
                skipped[f"recognizer {s.recognizer}"] = str(e)
                recognizers[rec_skel] = None
    recognizers = {k: v for k, v in recognizers.items() if v is not None}
    rec = {"quick": quick, "n_hidden": n_hidden, "thresholds": THRESHOLDS, "units": UNITS,
           "tolerances": {k: {"kind": kind, "tolerance": tol} for k, kind, tol in TOLERANCES},
           "refiner": (f"default: MotionRefiner.pretrained(skeleton{f', weights={weights}' * bool(weights)})"
                       if default else f"custom: {getattr(refine, '__name__', type(refine).__name__)}"),
           "sets": {}, "skipped": skipped}
    for name, s in clip_sets.items():
        if hasattr(refine, "load"):
            try:
                refine.load(s.skeleton)  # weights loaded outside the timing
            except ValueError as e:  # no model for this skeleton (cmu_mocap until its motion model ships)
                skipped[name] = str(e)
                continue
        t0 = time.perf_counter()
        after = refine_by_length(refine, s.clips, s.skeleton, s.actions)
        seconds = time.perf_counter() - t0
        grounds = [ground_height(c, skeleton=s.skeleton) for c in s.clips]
        before_row = physical_figures(s.clips, s.skeleton)
        after_row = physical_figures(after, s.skeleton, grounds)
        recognizer = recognizers.get(s.skeleton)
        if recognizer is not None and s.labels is not None:
            before_row.update(_accuracy(recognizer, s.clips, s.labels, n_hidden, "start"))
            after_row.update(_accuracy(recognizer, after, s.labels, n_hidden, "start"))
        after_row.update(movement(s.clips, after), seconds=seconds)
        row = rec["sets"][name] = {"skeleton": s.skeleton, "clips": len(s.clips), "frames": int(sum(map(len, s.clips))),
                                   "recognizer": s.recognizer if recognizer is not None else None,
                                   "refine_actions": "labels" if any(a is not None for a in s.actions) else "unknown",
                                   "note": s.note, "before": before_row, "after": after_row,
                                   "verdict": verdict(before_row, after_row)}
        progress("set", {"name": name, **{k: row[k] for k in ("before", "after", "verdict")}})
    rec["real"] = _real_rows(data, {s.skeleton for s in clip_sets.values()}, quick, recognizers, n_hidden)
    rec["seconds"] = time.perf_counter() - t_start
    return write_record(out, "noharm", rec)
