"""``refine()`` (paper §3.2) and :class:`Refiner`, the concepts method's fitted parts for one skeleton.

:func:`refine` runs one of two methods: ``"motion"`` (the default: one learned model of motion recognises flawed frames
and in-fills them, :class:`~refiner.refinement.motion_refiner.MotionRefiner`) or ``"concepts"`` (the paper's: anchor
scores and transition residuals, its variants as options, :mod:`refiner.refinement.concepts_pipeline`), whose parts
:class:`Refiner` holds. Do no harm: only flagged frames change, spliced in without jumps and put back on the input's
bone lengths (:mod:`refiner.core.splicing`); the concepts method's concept-snap option (off by default) is the
one step that moves a whole clip.
"""
from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.transitions import TransitionGenerator
from refiner.core.manifest import file_sha256, read_refiner_manifest, refiner_weight_sets, weight_set_folders, write_manifest
from refiner.core.motion import Motion
from refiner.core.output_kind import like_input
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_joints
from refiner.nn.training import resolve_device
from refiner.refinement import concepts_pipeline
from refiner.refinement.anchor_quality import AnchorQuality
from refiner.refinement.anchor_recognition import AnchorRecognizer
from refiner.refinement.anchor_refinement import AnchorRefiner
from refiner.refinement.concept_snap import check_snap, check_strength
from refiner.refinement.inputs import (METHODS, MODES, auto_threads, check_choice, check_choices, check_metres,
                                       check_metres_each, check_threads, thread_limits)
from refiner.refinement.motion_refiner import MotionRefiner
from refiner.refinement.report import RefinementReport
from refiner.core.splicing import project_bone_lengths, splice
from refiner.refinement.transition_refinement import TransitionRefiner, TransitionRetimer

__all__ = ["Refiner", "RefinementReport", "refine", "MODES", "METHODS", "splice", "project_bone_lengths"]

_PARTS = {"recognizer": AnchorRecognizer, "anchor_refiner": AnchorRefiner, "transition_generator": TransitionGenerator,
          "transition_refiner": TransitionRefiner, "anchor_concepts": AnchorConcepts, "anchor_quality": AnchorQuality}
_NO_DEVICE = ("anchor_concepts", "anchor_quality")
_WEIGHTS = Path(__file__).resolve().parents[1] / "weights"
#: Thresholds a manifest's ``calibration`` entry may hold; they belong to the steps, which save them.
_CALIBRATED = ("anchor_threshold", "transition_threshold", "transition_thresholds")
#: Skeletons the concepts method has weights for (shipped: HumanAct12's; ``motion-refiner train`` fits CMU's). Others
#: (``uestc``, ``humanml3d``) are refined through HumanAct12's by the default method only.
CONCEPTS_SKELETONS = ("humanact12", "cmu_mocap")
_PRETRAINED: dict = {}


class Refiner:
    """The concepts method's fitted refiner for one skeleton (``refine(..., method="concepts")``).

    Parameters
    ----------
    recognizer, anchor_refiner, transition_generator, transition_refiner, anchor_concepts : fitted parts
        :class:`AnchorRecognizer`, :class:`AnchorRefiner`, :class:`TransitionGenerator`, :class:`TransitionRefiner`, :class:`AnchorConcepts`.
    anchor_quality : AnchorQuality, optional
        Needed for ``quality="pose"`` and ``anchor_method="posterior"``.
    skeleton, action_names : str (default "humanact12"), sequence of str
    mode : {"full", "anchor", "transition"}, default="full"
    method : {"concepts"}, default="concepts"
        The one method a Refiner runs; the default method, ``"motion"``, is
        :class:`~refiner.refinement.motion_refiner.MotionRefiner`.
    concept_snap : float in [0, 1], default=0
        The concept-snap option (:mod:`refiner.refinement.concept_snap`): a clip of a given action has its anchors moved
        this share of the way onto the action's nearest anchor concepts, after the concept steps; fidelity traded for
        realism (off).
    quality, anchor_method, transition_method, anchor_noise
        See :mod:`refiner.refinement.concepts_pipeline`: ``quality`` in {"pose", "encoder"}, ``anchor_method`` in
        {"posterior", "concept"}, ``transition_method`` in {"network", "retime"}; ``anchor_noise=0.02`` m, the
        observation noise of the posterior anchor repair.
    blend : int, default=4
        Frames over which a change is tapered in at each kept side.
    threads : int, "auto" or None, default="auto"
        torch intra-op (and BLAS) threads while refining, restored afterwards (``"auto"``: one thread under
        :data:`~refiner.refinement.inputs.AUTO_THREADS_BATCH` clips, else the cores up to 4; None: torch's).
    manifest : dict, optional
        Provenance of the weights (dataset, split, licence, hashes) and ``calibration``, the record of
        :meth:`calibrate`. Thresholds found there (``anchor_threshold``; ``transition_thresholds`` or
        ``transition_threshold``, metres) are handed to the steps that own them.

    Attributes
    ----------
    transition_retimer : TransitionRetimer
        The re-timing transition step (``transition_method="retime"``); its thresholds go in the manifest's ``calibration``.
    """

    def __init__(self, recognizer, anchor_refiner, transition_generator, transition_refiner, anchor_concepts,
                 anchor_quality=None, *, skeleton: str = "humanact12", action_names=(), mode: str = "full",
                 method: str = "concepts", concept_snap: float = 0.0, quality: str = "pose",
                 anchor_method: str = "posterior", transition_method: str = "network", anchor_noise: float = 0.02,
                 blend: int = 4, threads: int | str | None = "auto", manifest: dict | None = None):
        if method != "concepts":
            raise ValueError(f"a Refiner runs method='concepts' only; got method={method!r} (the default method, "
                             "'motion', is refiner.refinement.motion_refiner.MotionRefiner).")
        self.method = method
        self.recognizer, self.anchor_refiner, self.anchor_concepts = recognizer, anchor_refiner, anchor_concepts
        self.transition_generator, self.transition_refiner = transition_generator, transition_refiner
        paper = {"recognizer": recognizer, "anchor_refiner": anchor_refiner, "transition_generator": transition_generator,
                 "transition_refiner": transition_refiner, "anchor_concepts": anchor_concepts}
        missing = [name for name, part in paper.items() if part is None]
        if missing:
            raise ValueError(f"method='concepts' (the paper's) needs the parts {', '.join(missing)}, which these "
                             "weights lack.")
        self.concept_snap = check_snap(concept_snap, anchor_concepts)
        self.quality = check_choice("quality", quality, concepts_pipeline.QUALITY)
        self.anchor_method = check_choice("anchor_method", anchor_method, concepts_pipeline.ANCHOR_METHODS)
        self.transition_method = check_choice("transition_method", transition_method, concepts_pipeline.TRANSITION_METHODS)
        if anchor_quality is None and (quality == "pose" or anchor_method == "posterior"):
            raise ValueError("quality='pose' and anchor_method='posterior' need an `anchor_quality` model.")
        self.anchor_noise, self.blend, self.threads = anchor_noise, blend, check_threads(threads)
        self.skeleton, self.action_names = get_skeleton(skeleton).name, tuple(action_names)
        self.mode = check_choice("mode", mode, MODES)
        self.manifest = manifest or {}
        calibration = self.manifest.get("calibration", {})
        if anchor_quality is not None and "anchor_threshold" in calibration:  # a copy: the given part stays as it is
            anchor_quality = copy.copy(anchor_quality)
            anchor_quality.threshold_ = float(calibration["anchor_threshold"])
        self.anchor_quality = anchor_quality
        self.transition_retimer = TransitionRetimer.from_calibration(calibration)

    # ------------------------------------------------------------------ persistence

    def save(self, folder: str | os.PathLike, *, half: bool = False, int8: tuple = ()) -> None:
        """Write every part as safetensors plus ``manifest.json`` (``half`` stores float16 weights; the
        network parts named in ``int8`` store their weight matrices as int8 codes, see ``NetworkComponent.save``).

        Each step's thresholds go with it: a part's in its file, the re-timing step's in ``calibration``.
        """
        int8 = check_choices("int8", int8, [n for n in _PARTS if n not in _NO_DEVICE])
        (folder := Path(folder)).mkdir(parents=True, exist_ok=True)
        files = {}
        for name in _PARTS:
            path = folder / f"{name}.safetensors"
            part = getattr(self, name)
            if part is None:
                continue
            part.save(path) if name in _NO_DEVICE else part.save(path, half=half, int8=name in int8)
            files[name] = {"file": path.name, "sha256": file_sha256(path)}
        calibration = {k: v for k, v in self.manifest.get("calibration", {}).items() if k not in _CALIBRATED}
        write_manifest(folder / "manifest.json", {
            **self.manifest, "calibration": {**calibration, **self.transition_retimer.to_calibration()},
            "skeleton": self.skeleton, "action_names": list(self.action_names), "files": files})

    @classmethod
    def load(cls, folder: str | os.PathLike, *, device: str = "cpu", verify: bool = True, **kwargs) -> "Refiner":
        """Load a saved refiner, checking its manifest's schema and sha256 and every file's sha256.

        ``verify=False`` skips the hashes (not the schema); a part named in ``kwargs`` replaces the loaded one.
        Raises ``ValueError`` naming the file and the problem (see :func:`refiner.core.manifest.read_refiner_manifest`).
        """
        resolve_device(device)  # an unavailable device is refused before anything is read
        manifest, paths = read_refiner_manifest(folder, _PARTS, verify=verify)
        parts = {name: None for name in _PARTS}
        for name, path in paths.items():
            parts[name] = _PARTS[name].load(path) if name in _NO_DEVICE else _PARTS[name].load(path, device=device)
        return cls(**{**parts, **kwargs}, skeleton=manifest["skeleton"], action_names=manifest["action_names"],
                   manifest=manifest)

    @classmethod
    def pretrained(cls, skeleton: str = "humanact12", *, split: str = "all", device: str = "cpu", weights=None,
                   **kwargs) -> "Refiner":
        """The shipped concepts weights: ``split="all"`` (default, all subjects) or ``"train"`` (subjects 1-10, for
        benchmarks).

        Weights are loaded and verified against their manifest on first use; every call returns an independent copy, so
        changing one (:meth:`calibrate`, a threshold) changes no other. Each weight set's licence is in its manifest
        (:meth:`shipped` lists them): HumanAct12's are for academic, non-commercial use only. A skeleton that ships a
        train split only falls back to it for ``split="all"``. ``weights``: a folder of weight sets named as the shipped
        ones (``humanact12-train/``, ``cmu_mocap/``: your own training, ``motion-refiner train``), looked in first. The
        concepts method supports ``humanact12`` and ``cmu_mocap``; ``uestc`` and ``humanml3d`` are refined through
        HumanAct12's by the default method (:class:`~refiner.refinement.motion_refiner.MotionRefiner`) only."""
        if "concept_snap" in kwargs:  # one cached refiner per strength, however written
            kwargs.update({"concept_snap": snap} if (snap := check_strength(kwargs.pop("concept_snap"))) else {})
        with thread_limits(1):  # copying the tensors on one thread: 0.07 s; on two, under load, 0.4-0.6 s
            return copy.deepcopy(_shared_pretrained(cls, skeleton, split, device, kwargs, weights))

    @staticmethod
    def shipped() -> list[dict]:
        """The shipped concepts weight sets with their skeleton, split, dataset, licence and parts."""
        return refiner_weight_sets(_WEIGHTS)

    def n_parameters(self) -> dict:
        """Network parameters per part, and their ``total``."""
        counts = {name: getattr(self, name).n_parameters() for name in _PARTS
                  if name not in _NO_DEVICE and getattr(self, name) is not None}
        return {**counts, "total": sum(counts.values())}

    # ------------------------------------------------------------------ refinement

    def threads_for(self, seq) -> int | None:
        """The torch / BLAS threads :meth:`refine` uses for ``seq`` (None: torch's setting, untouched)."""
        return auto_threads(seq) if self.threads == "auto" else self.threads

    def refine(self, seq, *, action=None, mode: str | None = None, return_report: bool = False):
        """Refine one clip or a batch; returns the same kind as given (see :func:`refine`)."""
        with thread_limits(self.threads_for(seq)):
            return self._refine(seq, action, mode, return_report)

    def _refine(self, seq, action, mode, return_report):
        mode = check_choice("mode", self.mode if mode is None else mode, MODES)
        steps = concepts_pipeline
        if isinstance(seq, Motion):
            if seq.skeleton != self.skeleton:
                raise ValueError(f"this refiner is for skeleton {self.skeleton!r}; got a {seq.skeleton!r} motion.")
            check_metres(seq.joints, get_skeleton(seq.skeleton))
            outs, reports = steps.refine_clips(self, seq.joints[None], [seq.action if action is None else action],
                                               mode, False)
            result, report = seq.with_joints(outs[0]), reports[0]
            if result.action is None and report.action is not None:
                result = Motion(outs[0], skeleton=seq.skeleton, fps=seq.fps, action=report.action)
            return (result, report) if return_report else result
        batched = len(getattr(seq, "shape", np.shape(seq))) == 4
        x = check_joints(seq, skeleton=get_skeleton(self.skeleton), batched=batched)
        clips = x if batched else x[None]
        check_metres_each(clips, get_skeleton(self.skeleton), batched)
        actions = action if (batched and isinstance(action, (list, tuple, np.ndarray))) else [action] * len(clips)
        if len(actions) != len(clips):
            raise ValueError(f"`action` must have one entry per clip ({len(clips)}); got {len(actions)}.")
        outs, reports = steps.refine_clips(self, clips, list(actions), mode, batched)
        out = like_input(np.stack(outs) if batched else outs[0], seq, x)
        return (out, reports if batched else reports[0]) if return_report else out

    def calibrate(self, clips, actions, *, percentile: float = 1.0, transition_clips=None) -> dict:
        """Set the concept steps' thresholds from real clips (see :func:`refiner.refinement.concepts_pipeline.calibrate`);
        returns what was set, which is also kept in ``manifest["calibration"]``."""
        self.manifest["calibration"] = concepts_pipeline.calibrate(self, clips, actions, percentile=percentile,
                                                                   transition_clips=transition_clips)
        return self.manifest["calibration"]


def refine(seq, skeleton: str = "humanact12", *, action=None, mode: str = "full", return_report: bool = False,
           refiner=None, method: str = "motion"):
    """Refine a motion with the shipped weights.

    Parameters
    ----------
    seq : Motion, or array-like of shape (T, J, 3) or (B, T, J, 3) (numpy or torch)
        Joint positions in metres in the skeleton's canonical frame (HumanAct12: y down, facing -z).
    skeleton : str, default="humanact12"
        ``method="motion"``: ``"humanact12"`` has a shipped motion model; ``"uestc"`` and ``"humanml3d"`` are refined
        through it (converted in, only the change converted back). ``method="concepts"``: ``"humanact12"``
        (:meth:`Refiner.shipped`), or ``"cmu_mocap"`` with weights of your own.
    action : int, str or None
        Action index or name (per clip for a batch); inferred by the refiner when None.
    mode : {"full", "anchor", "transition"}, default="full"
        Which steps of the concepts method run after recognition; the motion method has one mode, ``"full"``.
    return_report : bool, default=False
        Also return a :class:`RefinementReport` (a list of them for a batch).
    refiner : MotionRefiner or Refiner, optional
        Use this refiner instead of the shipped one of ``method``.
    method : {"motion", "concepts"}, default="motion"
        ``"motion"``: :meth:`MotionRefiner.pretrained(skeleton) <refiner.refinement.motion_refiner.MotionRefiner.pretrained>`;
        ``"concepts"``: the paper's method, :meth:`Refiner.pretrained(skeleton) <Refiner.pretrained>`.

    Returns
    -------
    The same kind as ``seq`` (Motion, numpy array or torch tensor), refined; frames that no step changed
    (each change is in the report) are returned exactly as given. The input is never modified.

    dtypes and tensors: refinement runs in float32; a floating input (float64, float16, bfloat16) comes
    back in its own dtype, unchanged frames bit-identical, others as float32. A tensor comes back on its
    device; one that requires grad comes back detached with a ``UserWarning`` (not differentiable).
    Sparse and ``meta`` tensors raise ``ValueError``.

    Examples
    --------
    >>> import numpy as np, refiner
    >>> from refiner.io.datasets import load_humanact12
    >>> clip = load_humanact12()[0]                            # doctest: +SKIP
    >>> out, report = refiner.refine(clip, return_report=True)  # doctest: +SKIP
    """
    check_choice("method", method, METHODS)
    method = getattr(refiner, "method", method) if refiner is not None else method  # a given refiner's own method
    if method == "motion" and mode not in (None, "full"):
        raise ValueError(f"mode={mode!r} belongs to method='concepts'; the default method, 'motion', has one mode, "
                         "'full'.")
    if refiner is None:  # the shipped refiner itself, not a copy (refining changes nothing in it)
        refiner = (_shared_motion(skeleton) if method == "motion"
                   else _shared_pretrained(Refiner, skeleton, "all", "cpu", {}))
    return refiner.refine(seq, action=action, mode=mode, return_report=return_report)


def _shared_motion(skeleton: str) -> MotionRefiner:
    """``MotionRefiner.pretrained(skeleton)``, built once per skeleton."""
    key = ("motion", get_skeleton(skeleton).name)
    if key not in _PRETRAINED:
        _PRETRAINED[key] = MotionRefiner.pretrained(skeleton)
    return _PRETRAINED[key]


def _shared_pretrained(cls, skeleton: str, split: str, device: str, kwargs: dict, weights=None) -> Refiner:
    """The concepts weights for these arguments (in ``weights``, else shipped), loaded once and cached (see
    :meth:`Refiner.pretrained`)."""
    name = f"{get_skeleton(skeleton).name}" + ("" if split == "all" else f"-{split}")
    found = weight_set_folders(name, [weights, _WEIGHTS] if weights else [_WEIGHTS])
    if found and found[0].name != name and split == "all":  # weights of a train split only
        return _shared_pretrained(cls, skeleton, "train", device, kwargs, weights)
    if not found or found[0].name != name:
        known = [f"{w['folder']} ({w['skeleton']}, {w['split']})" for w in refiner_weight_sets(_WEIGHTS)]
        raise ValueError(f"no concepts weights for skeleton {skeleton!r}, split {split!r}; shipped: {', '.join(known) or 'none'} "
                         f"(licences: Refiner.shipped()){f'; none in {weights} either' if weights else ''}. The concepts "
                         f"method supports {' and '.join(CONCEPTS_SKELETONS)} only (train with `motion-refiner train`); "
                         "uestc and humanml3d are refined through HumanAct12's by the default method='motion'.")
    key = (str(found[0].resolve()), device, tuple(sorted(kwargs.items())))
    if key not in _PRETRAINED:
        _PRETRAINED[key] = cls.load(found[0], device=device, **kwargs)
    return _PRETRAINED[key]
