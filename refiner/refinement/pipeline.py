"""The three-step refiner (paper §3.2) behind ``refine()``: recognise, refine anchors, refine transitions.

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
  concept (the CVAE's transition between the same anchors): given the flawed transition it cuts
  frozen / reversed / time-warped errors from 7.8 / 6.7 / 5.8 cm to 2.4 / 4.0 / 4.8 cm, but its
  detector (spline residual between recognised anchors) flags too few flawed and too many real
  transitions, so in the full pipeline it cost 0.2 cm on clean clips for no gain.

Do no harm: only flagged anchors and flagged transitions change. Every change is spliced in as a
displacement that is zero at the kept frames on both sides and tapered with a smoothstep, so
position *and* velocity are continuous where refined frames meet kept ones; changed frames are then
put back on the input's bone lengths.
"""
from __future__ import annotations

import numbers
import os
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.splines import eval_spline, fit_spline
from refiner.concepts.transitions import TransitionGenerator, arc_length_profile, retime
from refiner.core.manifest import file_sha256, read_refiner_manifest, write_manifest
from refiner.core.motion import Motion
from refiner.core.output_kind import like_input
from refiner.core.signal import smoothstep
from refiner.core.skeletons import get_skeleton, joint_bone_lengths, with_bone_lengths
from refiner.core.validation import check_action, check_joints
from refiner.nn.training import resolve_device
from refiner.refinement.anchor_refinement import AnchorRefiner, masked_window
from refiner.refinement.flaw_classifier import FlawClassifier
from refiner.refinement.learned_pipeline import REPAIRS, check_detect, refine_batch
from refiner.refinement.learned_refinement import FlawRecognizer, FlawRepairer
from refiner.refinement.anchor_quality import AnchorQuality
from refiner.refinement.anchor_recognition import AnchorRecognizer
from refiner.refinement.transition_refinement import TransitionRefiner

__all__ = ["Refiner", "RefinementReport", "refine", "MODES", "splice", "project_bone_lengths"]

MODES = ("full", "anchor", "transition")
_PARTS = {
    "recognizer": AnchorRecognizer,
    "anchor_refiner": AnchorRefiner,
    "transition_generator": TransitionGenerator,
    "transition_refiner": TransitionRefiner,
    "anchor_concepts": AnchorConcepts,
    "anchor_quality": AnchorQuality,
    "flaw_recognizer": FlawRecognizer,
    "flaw_repairer": FlawRepairer,
    "flaw_classifier": FlawClassifier,
}
_NO_DEVICE = ("anchor_concepts", "anchor_quality")
QUALITY = ("pose", "encoder")
ANCHOR_METHODS = ("posterior", "concept")
TRANSITION_METHODS = ("network", "retime")
#: ``"learned"``: flaw recognition + repair networks (:mod:`refiner.refinement.learned_pipeline`); ``"concepts"``:
#: the anchor-score / transition-residual pipeline below, with the paper's variants as options.
METHODS = ("learned", "concepts")
_WEIGHTS = Path(__file__).resolve().parents[1] / "weights"
#: Upper ends (frames) of the duration bins of the transition thresholds.
_DURATION_BINS = (8, 16, 32, 64)
#: Shortest clip refined; shorter ones pass through unchanged (reported).
MIN_FRAMES = 8


@dataclass
class RefinementReport:
    """What ``refine`` found and changed in one clip (JSON-serialisable via :meth:`to_dict`)."""

    mode: str
    n_frames: int
    action: int | None = None
    action_name: str | None = None
    action_inferred: bool = False
    anchors: list[int] = field(default_factory=list)
    anchor_probability: list[float] = field(default_factory=list)
    flaw_probability: list[float] = field(default_factory=list)
    correction_cm: list[float] = field(default_factory=list)
    anchor_scores: list[float] = field(default_factory=list)
    threshold: float | None = None
    flagged_anchors: list[int] = field(default_factory=list)
    refined_anchors: list[dict] = field(default_factory=list)
    transition_residuals_cm: list[float] = field(default_factory=list)
    transition_thresholds_cm: list[float] = field(default_factory=list)
    flagged_transitions: list[list[int]] = field(default_factory=list)
    changes: list[dict] = field(default_factory=list)
    note: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def changed_frames(self) -> np.ndarray:
        """Boolean ``(T,)`` mask of frames that changed."""
        mask = np.zeros(self.n_frames, dtype=bool)
        for c in self.changes:
            mask[c["start"] : c["stop"]] = True
        return mask

    @property
    def threshold_quantity(self) -> str | None:
        """The field ``threshold`` applies to: ``"flaw_probability"`` (learned method) or ``"anchor_scores"``
        (concepts method: the anchors' pose scores, a log-likelihood, not ``anchor_probability``)."""
        if self.threshold is None:
            return None
        return "flaw_probability" if self.flaw_probability else "anchor_scores"

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict, with ``threshold_quantity`` after ``threshold``."""
        out = {}
        for key, value in asdict(self).items():
            out[key] = value
            if key == "threshold":
                out["threshold_quantity"] = self.threshold_quantity
        return out


def splice(original: np.ndarray, proposal: np.ndarray, lo: int, hi: int, *, blend: int = 4,
           keep_start: bool = True, keep_end: bool = True) -> np.ndarray:
    """Replace frames ``lo..hi-1`` of ``original`` by ``proposal`` without jumps.

    The displacement ``proposal - original`` is corrected linearly so it is zero at the kept
    frames ``lo - 1`` and ``hi`` (when ``keep_start`` / ``keep_end``), then tapered over ``blend``
    frames at each kept side, so position and velocity are continuous there.

    Parameters
    ----------
    original, proposal : ndarray (T, J, 3)
    lo, hi : int
        Changed frames ``lo <= t < hi``.
    """
    out = original.copy()
    a, b = (lo - 1 if keep_start else lo), (hi if keep_end else hi - 1)
    a, b = max(a, 0), min(b, len(original) - 1)
    disp = (proposal[a : b + 1] - original[a : b + 1]).astype(np.float64)
    n = len(disp)
    tau = np.linspace(0.0, 1.0, n)[:, None, None]
    start_fix = disp[0] if keep_start and lo > 0 else 0.0
    end_fix = disp[-1] if keep_end and hi < len(original) else 0.0
    disp = disp - (1 - tau) * start_fix - tau * end_fix
    w = np.ones(n)
    m = min(blend, (n - 1) // 2)
    if keep_start and lo > 0 and m > 0:
        w[1 : m + 1] = np.minimum(w[1 : m + 1], smoothstep(np.arange(1, m + 1) / (m + 1)))
        w[0] = 0.0
    if keep_end and hi < len(original) and m > 0:
        w[n - 1 - m : n - 1] = np.minimum(w[n - 1 - m : n - 1], smoothstep(np.arange(1, m + 1) / (m + 1))[::-1])
        w[-1] = 0.0
    out[a : b + 1] = original[a : b + 1] + (w[:, None, None] * disp).astype(original.dtype)
    return out


def project_bone_lengths(joints: np.ndarray, lengths: np.ndarray, frames: np.ndarray, skeleton="humanact12") -> np.ndarray:
    """Put ``frames`` of ``joints`` ``(T, J, 3)`` on the given bone lengths, keeping the root and bone directions.

    ``lengths`` is ``(T, J)``: the length of the bone ending at each joint (the root's is unused).
    """
    out = joints.copy()
    out[frames] = with_bone_lengths(joints[frames], lengths[frames], skeleton)
    return out


#: ``threads="auto"`` uses more than one thread from this many clips in a batch on.
AUTO_THREADS_BATCH = 32


@contextmanager
def thread_limits(threads: int | None):
    """torch intra-op and BLAS threads set to ``threads`` inside the block, restored after (None: untouched)."""
    if threads is None:
        yield
        return
    import torch
    from threadpoolctl import threadpool_limits

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with threadpool_limits(threads):  # under load, free BLAS threads made a call 3-12x slower
            yield
    finally:
        torch.set_num_threads(before)


def _auto_threads(seq) -> int:
    """One thread for a clip or a small batch, the available cores (at most 4) for a large one."""
    shape = getattr(seq, "shape", None)
    if shape is None and isinstance(seq, (list, tuple)):
        shape = np.shape(seq)
    if shape is None or len(shape) != 4 or shape[0] < AUTO_THREADS_BATCH:
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(4, cores))


class Refiner:
    """The fitted three-step refiner for one skeleton.

    Parameters
    ----------
    recognizer : AnchorRecognizer
    anchor_refiner : AnchorRefiner
    transition_generator : TransitionGenerator
    transition_refiner : TransitionRefiner
    anchor_concepts : AnchorConcepts
    anchor_quality : AnchorQuality, optional
        Needed for ``quality="pose"`` and ``anchor_method="posterior"``.
    skeleton : str, default="humanact12"
    action_names : sequence of str
    mode : {"full", "anchor", "transition"}, default="full"
    quality : {"pose", "encoder"}, default="pose"
    anchor_method : {"posterior", "concept"}, default="posterior"
    transition_method : {"network", "retime"}, default="network"
    anchor_noise : float, default=0.02
        Observation noise (metres) of the posterior anchor repair: larger trusts the prior more.
    blend : int, default=4
        Frames over which a change is tapered in at each kept side.
    threads : int, "auto" or None, default="auto"
        torch intra-op (and BLAS) threads while refining, restored afterwards. The networks are
        small: on a 2-core CPU one thread refined a 60-frame clip in 12 ms, torch's default two in
        113 ms; but a batch of 256 clips went at 515 clips/s on one thread and 742 on two.
        ``"auto"``: one thread for batches under :data:`AUTO_THREADS_BATCH` clips, else the
        available cores up to 4. None leaves torch's setting alone.
    flaw_recognizer : FlawRecognizer, optional
    flaw_repairer : FlawRepairer, optional
        The learned steps; needed for ``method="learned"``.
    method : {"learned", "concepts"}, optional
        Default "learned" when both learned parts are given, else "concepts".
    repair : {"typed", "select", "given", "infill"}, default="typed"
        Learned repair: the repair for the flaw group the classifier recognises ("typed"), the
        candidate the flaw classifier finds most real ("select"), the repair
        network seeing the flagged frames ("given"), or in-filling them from the context ("infill").
    change_penalty : float, default=0.01
        With ``repair="select"``: flaw probability a candidate must gain per centimetre it moves.
    flaw_classifier : FlawClassifier, optional
        The kinematic flaw detector (default detector of the learned method).
    detect : str, default="classifier"
        Learned flaw detectors whose flags are used, joined by "+" (any of "classifier",
        "recognizer", "correction"; see :mod:`refiner.refinement.learned_pipeline`).
    min_run, margin : int, default=2, 2
        A flagged run needs ``min_run`` frames above the flaw threshold; it is widened by ``margin``.
    hysteresis : float, default=0.5
        A flagged run extends over neighbouring frames whose score stays above this share of the threshold.
    rigid_tolerance : float, default=0.005
        Bone-length variation (std / mean of any bone) above which every frame is put back on the
        clip's median bone lengths (learned method; real mocap varies by under 0.001 %).
    manifest : dict, optional
        Provenance of the weights (dataset, split, licence, hashes) and ``calibration``
        (``anchor_threshold``, ``transition_threshold`` in metres) from :meth:`calibrate`.
    """

    def __init__(self, recognizer, anchor_refiner, transition_generator, transition_refiner, anchor_concepts,
                 anchor_quality=None, flaw_recognizer=None, flaw_repairer=None, flaw_classifier=None, *,
                 skeleton: str = "humanact12",
                 action_names=(), mode: str = "full", method: str | None = None, repair: str = "typed",
                 detect: str = "classifier",
                 min_run: int = 2, margin: int = 2, rigid_tolerance: float = 0.005, change_penalty: float = 0.01,
                 hysteresis: float = 0.5,
                 quality: str = "pose", anchor_method: str = "posterior", transition_method: str = "network",
                 anchor_noise: float = 0.02, blend: int = 4, threads: int | str | None = "auto", manifest: dict | None = None):
        self.recognizer = recognizer
        self.anchor_refiner = anchor_refiner
        self.transition_generator = transition_generator
        self.transition_refiner = transition_refiner
        self.anchor_concepts = anchor_concepts
        self.anchor_quality = anchor_quality
        self.flaw_recognizer = flaw_recognizer
        self.flaw_repairer = flaw_repairer
        self.flaw_classifier = flaw_classifier
        learned = flaw_recognizer is not None and flaw_repairer is not None
        self.method = _check_choice("method", method or ("learned" if learned else "concepts"), METHODS)
        if self.method == "learned" and not learned:
            raise ValueError("method='learned' needs a `flaw_recognizer` and a `flaw_repairer`.")
        self.repair = _check_choice("repair", repair, REPAIRS)
        self.detect = check_detect(detect)
        if "classifier" in self.detect.split("+") and flaw_classifier is None and learned:
            raise ValueError(f"detect={detect!r} needs a `flaw_classifier`.")
        self.min_run, self.margin, self.rigid_tolerance = int(min_run), int(margin), float(rigid_tolerance)
        self.change_penalty, self.hysteresis = float(change_penalty), float(hysteresis)
        if self.repair in ("select", "typed") and learned and flaw_classifier is None:
            raise ValueError(f"repair={repair!r} needs a `flaw_classifier`.")
        self.quality = _check_choice("quality", quality, QUALITY)
        self.anchor_method = _check_choice("anchor_method", anchor_method, ANCHOR_METHODS)
        self.transition_method = _check_choice("transition_method", transition_method, TRANSITION_METHODS)
        if anchor_quality is None and (quality == "pose" or anchor_method == "posterior"):
            raise ValueError("quality='pose' and anchor_method='posterior' need an `anchor_quality` model.")
        self.anchor_noise = anchor_noise
        if not (threads is None or (isinstance(threads, str) and threads == "auto")
                or (isinstance(threads, numbers.Integral) and not isinstance(threads, (bool, np.bool_)) and threads >= 1)):
            raise ValueError(f"`threads` must be a positive int, 'auto' or None; got {threads!r}.")
        self.threads = threads if threads is None or isinstance(threads, str) else int(threads)
        self.skeleton = get_skeleton(skeleton).name
        self.action_names = tuple(action_names)
        self.mode = _check_mode(mode)
        self.blend = blend
        self.manifest = manifest or {}

    # ------------------------------------------------------------------ persistence

    def save(self, folder: str | os.PathLike, *, half: bool = False) -> None:
        """Write every part as safetensors plus ``manifest.json`` (``half`` stores float16 weights)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        files = {}
        for name in _PARTS:
            path = folder / f"{name}.safetensors"
            part = getattr(self, name)
            if part is None:
                continue
            part.save(path) if name in _NO_DEVICE else part.save(path, half=half)
            files[name] = {"file": path.name, "sha256": file_sha256(path)}
        write_manifest(folder / "manifest.json", {**self.manifest, "skeleton": self.skeleton,
                                                  "action_names": list(self.action_names), "files": files})

    @classmethod
    def load(cls, folder: str | os.PathLike, *, device: str = "cpu", verify: bool = True, **kwargs) -> "Refiner":
        """Load a saved refiner, checking its manifest's schema and sha256 and every file's sha256.

        ``verify=False`` skips the hashes (not the schema). Raises ``ValueError`` naming the file and
        the problem (see :func:`refiner.core.manifest.read_refiner_manifest`).
        """
        resolve_device(device)  # an unavailable device is refused before anything is read
        manifest, paths = read_refiner_manifest(folder, _PARTS, verify=verify)
        parts = {name: None for name in _PARTS}
        for name, path in paths.items():
            part_cls = _PARTS[name]
            parts[name] = part_cls.load(path) if name in _NO_DEVICE else part_cls.load(path, device=device)
        return cls(**parts, skeleton=manifest["skeleton"], action_names=manifest["action_names"],
                   manifest=manifest, **kwargs)

    @classmethod
    def pretrained(cls, skeleton: str = "humanact12", *, split: str = "all", device: str = "cpu",
                   **kwargs) -> "Refiner | ConvertedRefiner":
        """The shipped weights: ``split="all"`` (default, all subjects) or ``"train"`` (subjects 1-10, for benchmarks).

        Weights are loaded on first use and verified against their manifest. They were trained on
        HumanAct12, which is for academic, non-commercial use only; so are they. A skeleton without
        weights of its own that :func:`refiner.core.skeletons.convert` connects with HumanAct12's
        (``uestc``, ``humanml3d``, ``cmu_mocap``) gets a
        :class:`~refiner.refinement.converted_refinement.ConvertedRefiner` running the HumanAct12 weights.
        """
        name = f"{get_skeleton(skeleton).name}" + ("" if split == "all" else f"-{split}")
        folder = _WEIGHTS / name
        if not (folder / "manifest.json").is_file() and _converts(skeleton):
            from refiner.refinement.converted_refinement import ConvertedRefiner

            tolerance = kwargs.pop("rigid_tolerance", 0.005)  # on the clip's own bones, not the estimated ones
            base = cls.pretrained("humanact12", split=split, device=device, rigid_tolerance=float("inf"), **kwargs)
            return ConvertedRefiner(base, skeleton, rigid_tolerance=tolerance)
        if not (folder / "manifest.json").is_file():
            known = sorted(p.name for p in _WEIGHTS.iterdir() if (p / "manifest.json").is_file()) if _WEIGHTS.is_dir() else []
            raise ValueError(f"no shipped weights for skeleton {skeleton!r}, split {split!r}; shipped: {known or 'none'}.")
        key = (name, device, tuple(sorted(kwargs.items())))
        if key not in _PRETRAINED:
            _PRETRAINED[key] = cls.load(folder, device=device, **kwargs)
        return _PRETRAINED[key]

    def n_parameters(self) -> dict:
        counts = {name: getattr(self, name).n_parameters() for name in _PARTS
                  if name not in _NO_DEVICE and getattr(self, name) is not None}
        counts["total"] = sum(counts.values())
        return counts

    # ------------------------------------------------------------------ refinement

    def threads_for(self, seq) -> int | None:
        """The torch / BLAS threads :meth:`refine` uses for ``seq`` (None: torch's setting, untouched)."""
        return _auto_threads(seq) if self.threads == "auto" else self.threads

    def refine(self, seq, *, action=None, mode: str | None = None, return_report: bool = False):
        """Refine one clip or a batch; returns the same kind as given (see :func:`refine`)."""
        with thread_limits(self.threads_for(seq)):
            return self._refine(seq, action, mode, return_report)

    def _refine(self, seq, action, mode, return_report):
        mode = _check_mode(self.mode if mode is None else mode)
        skel = get_skeleton(self.skeleton)
        if isinstance(seq, Motion):
            if seq.skeleton != self.skeleton:
                raise ValueError(f"this refiner is for skeleton {self.skeleton!r}; got a {seq.skeleton!r} motion.")
            act = seq.action if action is None else action
            _check_metres(seq.joints, get_skeleton(seq.skeleton))
            outs, reports = (self._refine_learned(seq.joints[None], [act], mode, False) if self.method == "learned"
                             else self._refine_each(seq.joints[None], [act], mode, False))
            out, report = outs[0], reports[0]
            result = seq.with_joints(out)
            if result.action is None and report.action is not None:
                result = Motion(out, skeleton=seq.skeleton, fps=seq.fps, action=report.action)
            return (result, report) if return_report else result
        ndim = len(getattr(seq, "shape", np.shape(seq)))
        batched = ndim == 4
        x = check_joints(seq, skeleton=skel, batched=batched)
        clips = x if batched else x[None]
        check_metres_each(clips, skel, batched)
        actions = action if (batched and isinstance(action, (list, tuple, np.ndarray))) else [action] * len(clips)
        if len(actions) != len(clips):
            raise ValueError(f"`action` must have one entry per clip ({len(clips)}); got {len(actions)}.")
        if self.method == "learned":
            out, reports = self._refine_learned(clips, actions, mode, batched)
            outs = list(out)
        else:
            outs, reports = self._refine_each(clips, actions, mode, batched)
        out = like_input(np.stack(outs) if batched else outs[0], seq, x)
        if return_report:
            return out, (reports if batched else reports[0])
        return out

    def _refine_learned(self, clips, actions, mode, batched):
        """The whole batch through the learned steps at once (see :mod:`refiner.refinement.learned_pipeline`)."""
        x = np.array(clips, dtype=np.float32, copy=True)
        reports = [RefinementReport(mode=mode, n_frames=x.shape[1]) for _ in range(len(x))]
        for i, (report, act) in enumerate(zip(reports, actions)):
            if act is not None:
                try:
                    report.action = check_action(act, self.action_names)
                except ValueError as e:
                    raise ValueError(f"clip {i} of {len(x)}: {e}") from e if batched else e
        if x.shape[1] < MIN_FRAMES:
            for report in reports:
                report.note = (f"clip has {x.shape[1]} frames; at least {MIN_FRAMES} are needed to refine, "
                               "returned unchanged")
            return x, reports
        return refine_batch(self, x, [r.action for r in reports], mode, reports), reports

    def _refine_each(self, clips, actions, mode, batched):
        outs, reports = [], []
        for i, (clip, act) in enumerate(zip(clips, actions)):
            try:
                o, r = self._refine_clip(clip, act, mode)
            except ValueError as e:
                raise ValueError(f"clip {i} of {len(clips)}: {e}") from e if batched else e
            outs.append(o)
            reports.append(r)
        return outs, reports

    def _refine_clip(self, joints: np.ndarray, action, mode: str) -> tuple[np.ndarray, RefinementReport]:
        x = np.array(joints, dtype=np.float32, copy=True)
        report = RefinementReport(mode=mode, n_frames=len(x))
        if action is not None:
            report.action = check_action(action, self.action_names)
        if len(x) < MIN_FRAMES:
            report.note = f"clip has {len(x)} frames; at least {MIN_FRAMES} are needed to refine, returned unchanged"
            return x, report
        rec = self.recognizer.recognize(x)
        if report.action is None:
            report.action, report.action_inferred = int(np.argmax(rec.action_probability)), True
        report.action_name = self.action_names[report.action] if self.action_names else None
        anchors = rec.anchors
        report.anchors = anchors.tolist()
        report.anchor_probability = [round(float(p), 4) for p in rec.probability]
        scores, threshold = self._anchor_scores(x, anchors, report.action, rec)
        flagged = scores < threshold
        report.anchor_scores = [round(float(v), 3) for v in scores]
        report.threshold = round(float(threshold), 3)
        report.flagged_anchors = anchors[flagged].tolist()
        y = x.copy()
        changed = np.zeros(len(x), dtype=bool)
        touched: set[int] = set()
        if mode in ("full", "anchor"):
            for k in np.flatnonzero(flagged):
                if self.anchor_method == "posterior":
                    y = self._posterior_anchor(y, anchors, int(k), report, changed)
                else:
                    y = self._refine_anchor(y, anchors, int(k), report, changed)
                    touched.update({int(k) - 1, int(k)} & set(range(len(anchors) - 1)))
        if mode in ("full", "transition"):
            y = self._refine_transitions(y, anchors, report, changed, touched if mode == "full" else set())
        if changed.any():
            y = project_bone_lengths(y, _reference_lengths(x, self.skeleton), changed, self.skeleton)
        return y, report

    def _anchor_scores(self, x, anchors, action, rec) -> tuple[np.ndarray, float]:
        if self.quality == "encoder":
            return rec.scores, rec.threshold
        threshold = self.manifest.get("calibration", {}).get("anchor_threshold", self.anchor_quality.threshold_)
        return self.anchor_quality.score(x[anchors], action), float(threshold)

    def _posterior_anchor(self, y, anchors, k, report, changed) -> np.ndarray:
        frame = int(anchors[k])
        pose = self.anchor_quality.denoise(y[frame][None], report.action, self.anchor_noise)[0]
        target = pose - pose[:1] + y[frame, :1]  # the root stays where it is
        delta = target - y[frame]
        lo = int(anchors[k - 1]) if k > 0 else frame
        hi = int(anchors[k + 1]) if k + 1 < len(anchors) else frame
        weight = np.zeros(len(y))
        weight[frame] = 1.0
        if frame > lo:
            u = (np.arange(lo, frame + 1) - lo) / (frame - lo)
            weight[lo : frame + 1] = u * u * (3 - 2 * u)
        if hi > frame:
            u = (hi - np.arange(frame, hi + 1)) / (hi - frame)
            weight[frame : hi + 1] = u * u * (3 - 2 * u)
        out = y + (weight[:, None, None] * delta).astype(y.dtype)
        window = weight > 0
        changed |= window
        start, stop = int(np.argmax(window)), int(len(window) - np.argmax(window[::-1]))
        moved = 100 * float(np.linalg.norm(delta, axis=-1).mean())
        report.refined_anchors.append({"frame": frame, "method": "posterior", "moved_cm": round(moved, 3)})
        report.changes.append({"start": start, "stop": stop, "step": "anchor",
                               "reason": f"anchor {frame} pose scored below the threshold; moved {moved:.1f} cm "
                                         "toward the action's pose distribution"})
        return out

    def _refine_transitions(self, y, anchors, report, changed, touched: set) -> np.ndarray:
        n = len(anchors) - 1
        if self.transition_method == "network":
            refined, residuals = self.transition_refiner.refine_transitions(y, anchors)
            threshold = float(self.transition_refiner.threshold_)
        else:
            residuals = np.array([_spline_residual(y[anchors[m] : anchors[m + 1] + 1]) for m in range(n)])
            thresholds = np.array([self._transition_threshold(int(d)) for d in np.diff(anchors)])
            refined = None
        if self.transition_method == "network":
            thresholds = np.full(n, threshold)
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
                concept = self.transition_generator.generate(y[a][None], y[b][None], [b - a])[0]
                proposal = y.copy()
                proposal[a : b + 1] = retime(y[a : b + 1], arc_length_profile(concept))
                why += "; re-timed along its path with its transition concept's speed profile"
            else:
                proposal = refined
            y = splice(y, proposal, a + 1, b, blend=self.blend)
            changed[a + 1 : b] = True
            report.flagged_transitions.append([a, b])
            report.changes.append({"start": a + 1, "stop": b, "step": "transition", "reason": why})
        return y

    def calibrate(self, clips, actions, *, percentile: float = 1.0, transition_clips=None) -> dict:
        """Set the flaw thresholds from real clips, using this refiner's own recognised anchors.

        Anchors: the ``percentile``-th percentile of real anchors' pose scores (use clips the pose
        model was not fitted on). Transitions: per duration bin, the ``100 - percentile``-th
        percentile of real transitions' spline residuals (metres), since longer transitions fit a
        cubic less tightly; ``transition_clips`` (default ``clips``) supplies them. Stored in
        ``manifest["calibration"]`` (saved with the refiner).
        """
        anchor_scores = []
        for clip, action in zip(clips, actions):
            x = np.asarray(clip, dtype=np.float32)
            if self.anchor_quality is not None:
                anchor_scores.extend(self.anchor_quality.score(x[self.recognizer.recognize(x).anchors], int(action)))
        durations, residuals = [], []
        for clip in (clips if transition_clips is None else transition_clips):
            x = np.asarray(clip, dtype=np.float32)
            a = self.recognizer.recognize(x).anchors
            durations.extend(np.diff(a))
            residuals.extend(_spline_residual(x[a[m] : a[m + 1] + 1]) for m in range(len(a) - 1))
        durations, residuals = np.asarray(durations), np.asarray(residuals)
        bins = []
        lower = 0
        for upper in (*_DURATION_BINS, np.inf):
            sel = (durations > lower) & (durations <= upper)
            if sel.sum() >= 20 or (upper == np.inf and sel.any()):
                bins.append([float(upper), float(np.percentile(residuals[sel], 100 - percentile))])
                lower = upper
        if bins:
            bins[-1][0] = float("inf")
        calibration = {"percentile": percentile, "clips": len(clips), "transition_thresholds": bins}
        if anchor_scores:
            calibration["anchor_threshold"] = float(np.percentile(anchor_scores, percentile))
        self.manifest["calibration"] = calibration
        return calibration

    def _transition_threshold(self, duration: int) -> float:
        calibration = self.manifest.get("calibration", {})
        if "transition_threshold" in calibration:  # a single value set by hand
            return float(calibration["transition_threshold"])
        for upper, threshold in calibration.get("transition_thresholds", []):
            if duration <= upper:
                return float(threshold)
        return float("inf")

    def _refine_anchor(self, y, anchors, k, report, changed) -> np.ndarray:
        frame = int(anchors[k])
        pose, concept = self.anchor_refiner.refine_anchor(y, anchors, k, report.action)
        proposal = y.copy()
        proposal[frame] = pose
        starts, ends, durations = [], [], []
        if k > 0:
            starts.append(y[anchors[k - 1]]), ends.append(pose), durations.append(frame - int(anchors[k - 1]))
        if k + 1 < len(anchors):
            starts.append(pose), ends.append(y[anchors[k + 1]]), durations.append(int(anchors[k + 1]) - frame)
        pieces = self.transition_generator.generate(np.stack(starts), np.stack(ends), np.array(durations))
        p = 0
        if k > 0:
            proposal[anchors[k - 1] : frame + 1] = pieces[p]
            p += 1
        if k + 1 < len(anchors):
            proposal[frame : anchors[k + 1] + 1] = pieces[p]
        lo, hi = masked_window(len(y), anchors, k)
        moved_cm = 100 * float(np.linalg.norm(pose - y[frame], axis=-1).mean())
        y = splice(y, proposal, lo, hi, blend=self.blend, keep_start=k > 0, keep_end=k + 1 < len(anchors))
        changed[lo:hi] = True
        report.refined_anchors.append({"frame": frame, "concept": int(concept), "moved_cm": round(moved_cm, 3)})
        report.changes.append({"start": lo, "stop": hi, "step": "anchor",
                               "reason": f"anchor {frame} scored below the threshold; replaced by concept {concept}"})
        return y


_PRETRAINED: dict = {}


def refine(seq, skeleton: str = "humanact12", *, action=None, mode: str = "full", return_report: bool = False,
           refiner: Refiner | None = None):
    """Refine a motion with the shipped concepts and networks.

    Parameters
    ----------
    seq : Motion, or array-like of shape (T, J, 3) or (B, T, J, 3) (numpy or torch)
        Joint positions in metres in the skeleton's canonical frame (HumanAct12: y down, facing -z).
    skeleton : str, default="humanact12"
        ``"humanact12"`` has shipped weights; ``"uestc"``, ``"cmu_mocap"`` and ``"humanml3d"`` are
        refined through them (:class:`~refiner.refinement.converted_refinement.ConvertedRefiner`).
    action : int, str or None
        Action index or name (per clip for a batch); inferred by anchor recognition when None.
    mode : {"full", "anchor", "transition"}, default="full"
        Which refinement steps run after recognition.
    return_report : bool, default=False
        Also return a :class:`RefinementReport` (a list of them for a batch).
    refiner : Refiner, optional
        Use this refiner instead of the shipped one.

    Returns
    -------
    The same kind as ``seq`` (Motion, numpy array or torch tensor), refined; frames that were not
    flagged are returned exactly as given. The input is never modified.

    dtypes and tensors: refinement runs in float32; a floating input (float64, float16, torch
    bfloat16) comes back in its own dtype with its unchanged frames bit-identical, other inputs as
    float32. A tensor comes back on its own device; one that requires grad comes back detached with a
    ``UserWarning`` (refinement is not differentiable). Sparse tensors and tensors on the ``meta``
    device raise ``ValueError``, as does a refiner loaded for an unavailable ``device``.

    Examples
    --------
    >>> import numpy as np, refiner
    >>> from refiner.io.datasets import load_humanact12
    >>> clip = load_humanact12()[0]                            # doctest: +SKIP
    >>> out, report = refiner.refine(clip, return_report=True)  # doctest: +SKIP
    """
    model = refiner if refiner is not None else Refiner.pretrained(skeleton)
    return model.refine(seq, action=action, mode=mode, return_report=return_report)


def _converts(skeleton: str) -> bool:
    """Whether :func:`refiner.core.skeletons.convert` connects ``skeleton`` with HumanAct12 both ways."""
    from refiner.core.skeleton_conversion import estimated_joints

    try:
        estimated_joints(skeleton, "humanact12"), estimated_joints("humanact12", skeleton)
    except ValueError:
        return False
    return get_skeleton(skeleton).name != "humanact12"


def _spline_residual(frames: np.ndarray) -> float:
    """MPJPE (metres) between a transition's frames and their least-squares cubic."""
    return float(np.linalg.norm(eval_spline(fit_spline(frames), len(frames)) - frames, axis=-1).mean())


def _reference_lengths(x: np.ndarray, skeleton: str) -> np.ndarray:
    """Bone lengths ``(T, J)`` to restore: where a bone's length is constant over the clip (spread
    under 2 %, as in mocap) its median, so a distorted frame goes back to the true length; elsewhere
    (generators whose bones stretch) each frame's own length."""
    lengths = joint_bone_lengths(x, skeleton)  # (T, J)
    median = np.median(lengths, axis=0)
    rigid = lengths.std(0) < 0.02 * np.maximum(median, 1e-9)
    return np.where(rigid, median, lengths)


def check_metres_each(clips: np.ndarray, skel, batched: bool) -> None:
    """:func:`_check_metres` per clip of ``clips (B, T, J, 3)`` (one clip in centimetres must not hide in a
    batch's median), naming the clip when the input was a batch."""
    for i, clip in enumerate(clips):
        try:
            _check_metres(clip, skel)
        except ValueError as e:
            if not batched:
                raise
            raise ValueError(f"clip {i} of {len(clips)}: {e}") from e


def _check_metres(x: np.ndarray, skel) -> None:
    """Refuse joints that cannot be metres: huge values, or bones metres long (centimetres given)."""
    extent = float(np.abs(x).max())
    if extent > 1e3:
        raise ValueError(f"`seq` has coordinates up to {extent:.3g}; joints must be in metres (|x| < 1000).")
    median = float(np.median(skel.bone_lengths(x)))
    if median > 1.5:
        raise ValueError(f"`seq` has bones of {median:.3g} units median length; joints must be in metres "
                         "(centimetres: divide by 100).")


def _check_choice(name: str, value: str, choices) -> str:
    if value not in choices:
        raise ValueError(f"unknown {name} {value!r}; known: {', '.join(choices)}.")
    return value


def _check_mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; known: {', '.join(MODES)}.")
    return mode
