"""The refiner behind ``refine()`` (paper §3.2): the fitted parts for one skeleton and the steps they run.

:class:`Refiner` holds the parts, checks the input, and runs one of two methods on it: ``"learned"`` (flaw recognition
and repair networks, :mod:`refiner.refinement.learned_pipeline`, the default) or ``"concepts"`` (anchor scores and
transition residuals, the paper's variants as options, :mod:`refiner.refinement.concepts_pipeline`). Do no harm: only
flagged frames change, spliced in without jumps and put back on the input's bone lengths (:mod:`refiner.refinement.splicing`),
but for the steps that judge a clip as a whole (stretching bones, damped amplitude, noise throughout), the pose prior's
frames (further off real motion than held-out real clips go), the texture filter's (clips known or found to be a
generator's) and the concept-snap option (off by default).
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
from refiner.core.skeletons import BoneProportions, get_skeleton
from refiner.core.validation import check_joints
from refiner.nn.training import resolve_device
from refiner.refinement import concepts_pipeline, learned_pipeline
from refiner.refinement.amplitude import AmplitudeRestorer
from refiner.refinement.concept_snap import check_snaps, check_strength
from refiner.refinement.anchor_quality import AnchorQuality
from refiner.refinement.anchor_recognition import AnchorRecognizer
from refiner.refinement.anchor_refinement import AnchorRefiner
from refiner.refinement.converted_refinement import ConvertedRefiner, converts_with_humanact12
from refiner.refinement.flaw_classifier import FlawClassifier
from refiner.refinement.flaw_denoiser import FlawDenoiser
from refiner.refinement.infilling import MotionInfiller
from refiner.refinement.inputs import (AMPLITUDE, DENOISING, METHODS, MODES, POSING, RETIMING, RIGID_LENGTHS, TEXTURE,
                                       auto_threads, check_choice, check_choices, check_flag, check_metres, check_metres_each, check_threads, thread_limits)
from refiner.refinement.learned_refinement import FlawRecognizer, FlawRepairer
from refiner.refinement.noise_filter import NoiseFilter
from refiner.refinement.noise_residual import NoiseResidual, check_residual
from refiner.refinement.pose_prior import PosePrior
from refiner.refinement.report import RefinementReport
from refiner.refinement.texture_filter import TextureFilter
from refiner.refinement.rigid_step import NATURAL_BONES_KEY
from refiner.refinement.skating import skating_threshold
from refiner.refinement.splicing import project_bone_lengths, splice
from refiner.refinement.timing_estimation import TIMING_AGREEMENT, TimingEstimator
from refiner.refinement.transition_refinement import TransitionRefiner
from refiner.refinement.transition_retiming import TransitionRetimer

__all__ = ["Refiner", "RefinementReport", "refine", "MODES", "splice", "project_bone_lengths"]

_PARTS = {"recognizer": AnchorRecognizer, "anchor_refiner": AnchorRefiner, "transition_generator": TransitionGenerator,
          "transition_refiner": TransitionRefiner, "anchor_concepts": AnchorConcepts, "anchor_quality": AnchorQuality,
          "flaw_recognizer": FlawRecognizer, "flaw_repairer": FlawRepairer, "flaw_classifier": FlawClassifier,
          "flaw_denoiser": FlawDenoiser, "motion_infiller": MotionInfiller, "timing_estimator": TimingEstimator,
          "noise_filter": NoiseFilter, "amplitude_restorer": AmplitudeRestorer, "pose_prior": PosePrior,
          "texture_filter": TextureFilter, "noise_residual": NoiseResidual}
_NO_DEVICE = ("anchor_concepts", "anchor_quality", "amplitude_restorer")
_WEIGHTS = Path(__file__).resolve().parents[1] / "weights"
#: Thresholds a manifest's ``calibration`` entry may hold; they belong to the steps, which save them.
_CALIBRATED = ("anchor_threshold", "transition_threshold", "transition_thresholds")
_PRETRAINED: dict = {}


class Refiner:
    """The fitted refiner for one skeleton.

    Parameters
    ----------
    recognizer, anchor_refiner, transition_generator, transition_refiner, anchor_concepts : fitted parts
        :class:`AnchorRecognizer`, :class:`AnchorRefiner`, :class:`TransitionGenerator`, :class:`TransitionRefiner`, :class:`AnchorConcepts`.
    anchor_quality : AnchorQuality, optional
        Needed for ``quality="pose"`` and ``anchor_method="posterior"``.
    flaw_recognizer, flaw_repairer, flaw_classifier, flaw_denoiser, motion_infiller : optional
        The learned steps (:class:`FlawRecognizer`, :class:`FlawRepairer`, :class:`FlawClassifier`,
        :class:`FlawDenoiser`, :class:`MotionInfiller`; without the in-filler, the network's in-fill stands in).
    skeleton, action_names : str (default "humanact12"), sequence of str
    mode : {"full", "anchor", "transition"}, default="full"
    method : {"learned", "concepts"}, optional
        Default "learned" when ``flaw_recognizer`` and ``flaw_repairer`` are given, else "concepts".
    repair, detect, min_run, margin, hysteresis, change_penalty, rigid_tolerance
        Options of the learned method, see :mod:`refiner.refinement.learned_pipeline`: ``repair`` in
        {"typed", "select", "given", "infill"} (default "typed"), ``detect`` the detectors joined by "+"
        (default "classifier"); a flagged run needs ``min_run=2`` frames above the threshold and is widened
        by ``margin=2``, extended while the score stays above ``hysteresis=0.5`` of it; ``change_penalty=0.01``
        is the flaw probability a ``"select"`` candidate must gain per centimetre; a clip whose bone lengths
        vary more than ``rigid_tolerance=0.005`` (std / mean; mocap: under 0.001 %) is put back on rigid bones.
    timing_estimator, noise_filter, noise_residual, amplitude_restorer, pose_prior, texture_filter : optional
        The learned re-timing step (:mod:`refiner.refinement.timing_estimation`), noise filter
        (:mod:`refiner.refinement.noise_filter`; without it, flagged noise runs are smoothed instead) and the network
        that corrects what it leaves of a noise run (:mod:`refiner.refinement.noise_residual`),
        amplitude step (:mod:`refiner.refinement.amplitude`; "restore" for a generator's clips, the default "keep"), pose prior
        (:mod:`refiner.refinement.pose_prior`; ``posing="keep"`` skips it) and texture filter
        (:mod:`refiner.refinement.texture_filter`, last, on the clips ``texture`` names: "off", the default (a mocap
        clip may be given); "all", every clip, for a generator's clips, as :class:`RefinedGenerator` uses; "auto", those
        the noise step found noisy throughout).
    retiming : {"estimated", "flagged", "stalls"}, optional
        ``"estimated"`` (default with a ``timing_estimator``): its runs re-timed before detection, then as "flagged":
        flagged retraces cut (:mod:`refiner.refinement.retrace`) and flagged stalls re-timed; ``"stalls"``: stalls only.
    timing_agreement : float or None, default=0.8
        An estimated run is re-timed where the flaw classifier's timing group reaches it (None, a generator's: every run).
    denoising : {"runs", "filter", "throughout", "flagged"}, optional
        ``"runs"`` (default with a ``noise_filter``): the runs the flaw classifier's noise group finds are denoised last; ``"filter"``
        (a generator's, ``GENERATOR_OPTIONS``): those, then clips noisy throughout; ``"throughout"``: the latter; ``"flagged"``: neither.
    concept_snap : float in [0, 1], default=0
        The concept-snap option (:mod:`refiner.refinement.concept_snap`): a clip of a given action has its anchors moved
        this share of the way onto the action's nearest anchor concepts; fidelity traded for realism (off).
    misread_snap : float in [0, 1], default=0
        The same snap for the clips of a given action that the recognition network reads as another: for a generator's
        clips (``GENERATOR_OPTIONS``: 1); off, as real clips of unseen people are misread too (15 % of subjects 11-12).
    rigid_lengths : {"proportions", "median"}, optional
        The lengths of that rigid skeleton: the clip's medians drawn toward the human bone proportions the weights
        learned (``manifest["learned"]["bone_proportions"]``), or the medians alone (default: the former, if there).
    rigid_core : bool, default=True
        The flaw steps see a clip's rigid core and its frames whose bones only shorten as given; the last step puts the
        latter on the core's lengths (:func:`~refiner.core.rigid.rigid_skeleton`); False: all projected first (the previous release).
    natural_bones, skating : float, optional
        A clip whose bones vary no more than ``natural_bones`` (std / mean) gets its given frames back where no step after
        the rigid one changed them (:func:`~refiner.refinement.rigid_step.natural_bones_back`); a body gliding ``skating``
        metres over its planted feet in half a second is moved back (:mod:`refiner.refinement.skating`). Default: the
        weights' ``manifest["learned"]`` ``natural_bone_variation`` (CMU: 5.5 %) and ``skating_threshold_m``, else 0 (off).
    quality, anchor_method, transition_method, anchor_noise
        Options of the concepts method, see :mod:`refiner.refinement.concepts_pipeline`: ``quality`` in
        {"pose", "encoder"}, ``anchor_method`` in {"posterior", "concept"}, ``transition_method`` in
        {"network", "retime"}; ``anchor_noise=0.02`` m, the observation noise of the posterior anchor repair.
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
                 anchor_quality=None, flaw_recognizer=None, flaw_repairer=None, flaw_classifier=None,
                 flaw_denoiser=None, motion_infiller=None, timing_estimator=None, noise_filter=None,
                 amplitude_restorer=None, pose_prior=None, texture_filter=None, noise_residual=None, *,
                 skeleton: str = "humanact12", action_names=(), mode: str = "full", method: str | None = None,
                 repair: str = "typed", detect: str = "classifier", min_run: int = 2, margin: int = 2,
                 rigid_tolerance: float = 0.005, rigid_lengths: str | None = None, rigid_core: bool = True,
                 natural_bones: float | None = None, skating: float | None = None, retiming: str | None = None,
                 timing_agreement: float | None = TIMING_AGREEMENT, denoising: str | None = None, amplitude: str = "keep",
                 posing: str = "prior", texture: str = "off", concept_snap: float = 0.0, misread_snap: float = 0.0,
                 change_penalty: float = 0.01, hysteresis: float = 0.5,
                 quality: str = "pose", anchor_method: str = "posterior", transition_method: str = "network",
                 anchor_noise: float = 0.02, blend: int = 4, threads: int | str | None = "auto", manifest: dict | None = None):
        self.recognizer, self.anchor_refiner, self.anchor_concepts = recognizer, anchor_refiner, anchor_concepts
        self.transition_generator, self.transition_refiner = transition_generator, transition_refiner
        self.flaw_recognizer, self.flaw_repairer, self.flaw_classifier = flaw_recognizer, flaw_repairer, flaw_classifier
        self.flaw_denoiser, self.motion_infiller, self.timing_estimator = flaw_denoiser, motion_infiller, timing_estimator
        self.noise_filter, self.amplitude_restorer = noise_filter, amplitude_restorer
        self.noise_residual = check_residual(noise_filter, noise_residual)
        self.pose_prior, self.texture_filter, self.texture = pose_prior, texture_filter, check_choice("texture", texture, TEXTURE)
        self.amplitude, self.posing = check_choice("amplitude", amplitude, AMPLITUDE), check_choice("posing", posing, POSING)
        learned = flaw_recognizer is not None and flaw_repairer is not None
        self.method = check_choice("method", method or ("learned" if learned else "concepts"), METHODS)
        self.concept_snap, self.misread_snap = check_snaps(self.method, anchor_concepts, concept_snap=concept_snap,
                                                           misread_snap=misread_snap)
        if self.method == "learned" and not learned:
            raise ValueError("method='learned' needs a `flaw_recognizer` and a `flaw_repairer`.")
        paper = {"recognizer": recognizer, "anchor_refiner": anchor_refiner, "transition_generator": transition_generator,
                 "transition_refiner": transition_refiner, "anchor_concepts": anchor_concepts, "anchor_quality": anchor_quality}
        missing = [name for name, part in paper.items() if part is None]
        if self.method == "concepts" and missing:
            raise ValueError(f"method='concepts' (the paper's) needs the parts {', '.join(missing)}, which these "
                             "weights lack (they hold the learned steps only); use method='learned'.")
        self.repair = check_choice("repair", repair, learned_pipeline.REPAIRS)
        self.detect = learned_pipeline.check_detect(detect)
        for option, needs in (("detect", "classifier" in self.detect.split("+")), ("repair", repair in ("select", "typed"))):
            if needs and learned and flaw_classifier is None:
                raise ValueError(f"{option}={getattr(self, option)!r} needs a `flaw_classifier`.")
        if learned and "denoiser" in self.detect.split("+") and flaw_denoiser is None:
            raise ValueError(f"detect={self.detect!r} needs a `flaw_denoiser`, which these weights lack.")
        self.min_run, self.margin, self.rigid_tolerance, self.change_penalty, self.hysteresis = (
            int(min_run), int(margin), float(rigid_tolerance), float(change_penalty), float(hysteresis))
        self.quality = check_choice("quality", quality, concepts_pipeline.QUALITY)
        self.anchor_method = check_choice("anchor_method", anchor_method, concepts_pipeline.ANCHOR_METHODS)
        self.transition_method = check_choice("transition_method", transition_method, concepts_pipeline.TRANSITION_METHODS)
        if self.method == "concepts" and anchor_quality is None and (quality == "pose" or anchor_method == "posterior"):
            raise ValueError("quality='pose' and anchor_method='posterior' need an `anchor_quality` model.")
        self.anchor_noise, self.blend, self.threads = anchor_noise, blend, check_threads(threads)
        self.skeleton, self.action_names = get_skeleton(skeleton).name, tuple(action_names)
        self.mode = check_choice("mode", mode, MODES)
        self.manifest = manifest or {}
        self.natural_bones = check_strength(self.manifest.get("learned", {}).get(NATURAL_BONES_KEY, 0.0) if natural_bones
                                            is None else natural_bones, "natural_bones", "a bone-length std / mean")
        self.skating = skating_threshold(self.manifest, skating)
        calibration = self.manifest.get("calibration", {})
        if anchor_quality is not None and "anchor_threshold" in calibration:  # a copy: the given part stays as it is
            anchor_quality = copy.copy(anchor_quality)
            anchor_quality.threshold_ = float(calibration["anchor_threshold"])
        self.anchor_quality = anchor_quality
        self.transition_retimer = TransitionRetimer.from_calibration(calibration)
        record = self.manifest.get("learned", {}).get("bone_proportions")
        self.bone_proportions = BoneProportions.from_dict(record) if record else None
        n_bones = len(get_skeleton(skeleton).bones)
        if self.bone_proportions is not None and self.bone_proportions.mean.shape != (n_bones,):
            raise ValueError(f"the manifest's bone proportions have {self.bone_proportions.mean.size} bones; "
                             f"skeleton {skeleton!r} has {n_bones}.")
        self.rigid_core = check_flag("rigid_core", rigid_core)
        self.rigid_lengths = check_choice("rigid_lengths", rigid_lengths or (
            "median" if self.bone_proportions is None else "proportions"), RIGID_LENGTHS)
        self.retiming = check_choice("retiming", retiming or ("flagged" if timing_estimator is None else "estimated"), RETIMING)
        if timing_agreement is not None and (isinstance(timing_agreement, bool) or not 0 <= timing_agreement <= 1):
            raise ValueError(f"`timing_agreement` must be None or a probability in [0, 1]; got {timing_agreement!r}.")
        self.timing_agreement = timing_agreement
        self.denoising = check_choice("denoising", denoising or ("flagged" if noise_filter is None else "runs"), DENOISING)
        for option, value, part, name in (("retiming", self.retiming, timing_estimator, "timing_estimator"),
                                          ("denoising", self.denoising, noise_filter, "noise_filter")):
            if value in ("estimated", "runs", "filter", "throughout") and part is None:
                raise ValueError(f"{option}={value!r} needs a `{name}`, which these weights lack; use 'flagged'.")
        if self.rigid_lengths == "proportions" and self.bone_proportions is None:
            raise ValueError("rigid_lengths='proportions' needs the bone proportions of the weights' manifest "
                             "(`learned.bone_proportions`), which these weights lack; use 'median'.")

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

        ``verify=False`` skips the hashes (not the schema); a part named in ``kwargs`` (``noise_residual=None``) replaces the
        loaded one. Raises ``ValueError`` naming the file and the problem (see :func:`refiner.core.manifest.read_refiner_manifest`).
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
                   **kwargs) -> "Refiner | ConvertedRefiner":
        """The shipped weights: ``split="all"`` (default, all subjects) or ``"train"`` (subjects 1-10, for benchmarks).

        Weights are loaded and verified against their manifest on first use; every call returns an independent copy, so
        changing one (:meth:`calibrate`, a threshold) changes no other. Each weight set's licence is in its manifest
        (:meth:`shipped` lists them): HumanAct12's are for academic, non-commercial use only; ``cmu_mocap``'s (the learned
        steps, trained on the CMU subset alone; train split only, which ``split="all"`` falls back to) for all uses. A
        skeleton without weights of its own that :func:`refiner.core.skeletons.convert` connects with HumanAct12's
        (``uestc``, ``humanml3d``) gets a :class:`~refiner.refinement.converted_refinement.ConvertedRefiner` running the
        HumanAct12 weights. ``weights``: a folder of weight sets named as the shipped ones (``humanact12-train/``: your
        own training), looked in first."""
        for option in ("concept_snap", "misread_snap"):  # one cached refiner per strength, however written
            kwargs.update({option: snap} if (snap := check_strength(kwargs.pop(option, 0.0), option)) else {})
        with thread_limits(1):  # copying the tensors on one thread: 0.07 s; on two, under load, 0.4-0.6 s
            return copy.deepcopy(_shared_pretrained(cls, skeleton, split, device, kwargs, weights))

    @staticmethod
    def shipped() -> list[dict]:
        """The shipped weight sets with their skeleton, split, dataset, licence and parts."""
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
        steps = learned_pipeline if self.method == "learned" else concepts_pipeline
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
           refiner: Refiner | None = None):
    """Refine a motion with the shipped concepts and networks.

    Parameters
    ----------
    seq : Motion, or array-like of shape (T, J, 3) or (B, T, J, 3) (numpy or torch)
        Joint positions in metres in the skeleton's canonical frame (HumanAct12: y down, facing -z).
    skeleton : str, default="humanact12"
        ``"humanact12"`` and ``"cmu_mocap"`` have shipped weights (:meth:`Refiner.shipped`; CMU's, trained on
        the CMU subset alone, may be used commercially); ``"uestc"`` and ``"humanml3d"`` are refined through
        HumanAct12's (:class:`~refiner.refinement.converted_refinement.ConvertedRefiner`).
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
    The same kind as ``seq`` (Motion, numpy array or torch tensor), refined; frames that no step changed
    (each change is in the report) are returned exactly as given. The input is never modified.

    dtypes and tensors: refinement runs in float32; a floating input (float64, float16, bfloat16) comes
    back in its own dtype, unchanged frames bit-identical, others as float32. A tensor comes back on its
    device; one that requires grad comes back detached with a ``UserWarning`` (not differentiable).
    Sparse and ``meta`` tensors raise ``ValueError``, as does a refiner loaded for an unavailable device.

    Examples
    --------
    >>> import numpy as np, refiner
    >>> from refiner.io.datasets import load_humanact12
    >>> clip = load_humanact12()[0]                            # doctest: +SKIP
    >>> out, report = refiner.refine(clip, return_report=True)  # doctest: +SKIP
    """
    # the shipped refiner itself, not a copy (refining changes nothing in it)
    model = refiner if refiner is not None else _shared_pretrained(Refiner, skeleton, "all", "cpu", {})
    return model.refine(seq, action=action, mode=mode, return_report=return_report)


def _shared_pretrained(cls, skeleton: str, split: str, device: str, kwargs: dict, weights=None) -> "Refiner | ConvertedRefiner":
    """The weights for these arguments (in ``weights``, else shipped), loaded once and cached (see :meth:`Refiner.pretrained`)."""
    name = f"{get_skeleton(skeleton).name}" + ("" if split == "all" else f"-{split}")
    found = weight_set_folders(name, [weights, _WEIGHTS] if weights else [_WEIGHTS])
    if found and found[0].name != name and split == "all":  # weights of a train split only
        return _shared_pretrained(cls, skeleton, "train", device, kwargs, weights)
    if not found and converts_with_humanact12(skeleton):
        kwargs = dict(kwargs)
        tolerance = kwargs.pop("rigid_tolerance", 0.005)  # on the clip's own bones, not the estimated ones
        base = _shared_pretrained(cls, "humanact12", split, device, {**kwargs, "rigid_tolerance": float("inf")}, weights)
        record = base.manifest.get("learned", {}).get("converted_bone_proportions", {}).get(get_skeleton(skeleton).name)
        use = record is not None and base.rigid_lengths == "proportions"
        return ConvertedRefiner(base, skeleton, rigid_tolerance=tolerance,
                                proportions=BoneProportions.from_dict(record) if use else None)
    if not found or found[0].name != name:
        known = [f"{w['folder']} ({w['skeleton']}, {w['split']})" for w in refiner_weight_sets(_WEIGHTS)]
        raise ValueError(f"no shipped weights for skeleton {skeleton!r}, split {split!r}; shipped: {', '.join(known) or 'none'} "
                         f"(licences: Refiner.shipped()){f'; none in {weights} either' if weights else ''}.")
    key = (str(found[0].resolve()), device, tuple(sorted(kwargs.items())))
    if key not in _PRETRAINED:
        _PRETRAINED[key] = cls.load(found[0], device=device, **kwargs)
    return _PRETRAINED[key]
