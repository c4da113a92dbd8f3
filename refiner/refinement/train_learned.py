"""Train the learned refinement steps (flaw recognition and repair) on a dataset, resumable, with a progress log.

The clips of the split's two highest-numbered subjects are held out: they select the best weights
and set the flaw threshold, so the threshold holds for people the networks never saw.
"""
from __future__ import annotations

import json
import logging
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.segmentation import segment
from refiner.core.contact import SKATING_WINDOW
from refiner.core.manifest import file_sha256, read_refiner_manifest, write_manifest
from refiner.core.rigid import bone_variation
from refiner.core.skeletons import BoneProportions, convert
from refiner.io.datasets import MotionDataset
from refiner.refinement.flaw_classifier import FlawClassifier
from refiner.refinement.flaw_denoiser import FlawDenoiser
from refiner.refinement.infilling import MotionInfiller
from refiner.refinement.amplitude import AmplitudeRestorer
from refiner.refinement.learned_refinement import FlawRecognizer, FlawRepairer
from refiner.refinement.noise_filter import NoiseFilter
from refiner.refinement.noise_residual import NoiseResidual
from refiner.refinement.pipeline import _PARTS, _WEIGHTS, Refiner
from refiner.refinement.pose_prior import PosePrior
from refiner.refinement.rigid_step import NATURAL_BONES_KEY
from refiner.refinement.skating import SKATING_KEY, calibrate_skating
from refiner.refinement.texture_filter import TextureFilter
from refiner.refinement.timing_estimation import AGREED_KEY, TimingEstimator

__all__ = ["LEARNED_CONFIGS", "LEARNED_PARTS", "OPTIONAL_PARTS", "train_learned", "train_learned_refiner", "install_learned",
           "calibrate_learned", "calibration_split", "install_part", "add_optional_part", "STORED_INT8", "CLIP_RATE", "POSE_QUANTILE", "POSE_TEXTURE_QUANTILE", "bone_proportion_records", "CONVERTED_SKELETONS",
           "fit_anchor_concepts"]

#: Share of held-out real clips the timing estimator may re-time: it changes frames unverified, before
#: detection. Calibration subjects 9-10 (mean of the 7 families removed): thresholds 1.8 / 2.5 / 3.5 /
#: 3.8 frames (1.8: 3 % of clean clips; 3.8: 1 %) gave 19.0 / 19.5 / 19.5 / 19.8 %, 18.6 without it (the first
#: version, in an older pipeline); the shipped 80-channel one (unturned) at 0.5 / 1 %: 33.9 / 34.1 %, 30.7 without it.
TIMING_CLIP_RATE = 0.01
#: Parts whose weight matrices the shipped sets store as int8 codes (``NetworkComponent.save(int8=True)``): the
#: paper's (see their manifests' notes), the timing estimator (0.70 MB instead of 1.36; its offsets move by
#: 0.04 frames at most on held-out clips, against a threshold of about 3.7), the flaw recogniser (0.45 MB instead of
#: 0.85) and the noise residual (0.24 MB instead of 0.47): `bench flaws` as with float16 (38.36 %, every family and
#: the clean clips within 0.01).
STORED_INT8 = ("recognizer", "anchor_refiner", "transition_generator", "timing_estimator", "flaw_recognizer",
               "noise_residual")
#: The manifest key (under ``learned``) of each optional part's threshold.
_THRESHOLD_KEYS = {"flaw_denoiser": "denoiser_threshold_m", "motion_infiller": None,
                   "timing_estimator": "timing_threshold_frames", "noise_residual": None}
#: Layouts refined through HumanAct12 weights (``Refiner.pretrained`` gives them a ConvertedRefiner).
CONVERTED_SKELETONS = ("uestc", "humanml3d")
#: Share of held-out real clips each detector may flag (both together: at most twice this).
CLIP_RATE = 0.03

log = logging.getLogger(__name__)

#: Epochs of the "fast" configuration (the defaults: 40, 60 / 80, 100, 24, 200). The small parts (flaw classifier, noise
#: filter and residual, amplitude) keep their schedules: a few minutes in all (the paper's: ``train_refiner.CONFIGS``).
FAST_EPOCHS = {"flaw_networks": 16, "corrections": 30, "pose_prior": 40, "texture_filter": 10, "timing_estimator": 80}

#: "default" fits in about 30 minutes per network on one CPU core; "fast" is every part's schedule cut to about half
#: (the whole refiner in under an hour on 2 CPU cores: ``motion-refiner train --whole --jobs 2 --config fast``);
#: "tiny" trains in seconds for tests.
LEARNED_CONFIGS = {
    "default": dict(d_model=128, n_layers=3, n_heads=4, ffn_dim=256,
                    schedule=dict(n_epochs=40, steps_per_epoch=200, batch_size=64)),
    "fast": dict(d_model=128, n_layers=3, n_heads=4, ffn_dim=256,
                 schedule=dict(n_epochs=FAST_EPOCHS["flaw_networks"], steps_per_epoch=200, batch_size=64)),
    "tiny": dict(d_model=16, n_layers=1, n_heads=2, ffn_dim=16, schedule=dict(n_epochs=2, steps_per_epoch=2, batch_size=8)),
}
#: The flaw classifier's settings (about 2 minutes on one CPU core) and its tiny test version; ``schedule``
#: holds the fields that differ from the estimator's default schedule.
CLASSIFIER_CONFIGS = {"default": dict(schedule=dict()), "fast": dict(schedule=dict()),
                      "tiny": dict(hidden=8, n_layers=1, copies=1, schedule=dict(n_epochs=2, steps_per_epoch=2, batch_size=8))}
#: The settings of the two convolution networks that correct frames, the flaw denoiser (about 38 minutes on
#: one CPU core) and the motion in-filler (about 40), and their tiny test version.
CORRECTION_CONFIGS = {"default": dict(schedule=dict()), "fast": dict(schedule=dict(n_epochs=FAST_EPOCHS["corrections"])),
                      "tiny": dict(hidden=8, n_layers=1, schedule=dict(n_epochs=2, steps_per_epoch=2, batch_size=8))}
LEARNED_PARTS = ("flaw_classifier", "flaw_recognizer", "flaw_repairer", "noise_filter", "amplitude_restorer", "pose_prior",
                 "texture_filter")
#: The pose prior's settings (100 epochs of 200 steps, about 22 minutes on one CPU core) and its tiny test version.
POSE_PRIOR_CONFIGS = {"default": dict(schedule=dict()), "fast": dict(schedule=dict(n_epochs=FAST_EPOCHS["pose_prior"])),
                      "tiny": dict(hidden=8, n_layers=1, crop=16, schedule=dict(n_epochs=2, steps_per_epoch=2, batch_size=8))}
#: The texture filter's settings (about 25 minutes on one CPU core) and its tiny test version.
TEXTURE_FILTER_CONFIGS = {"default": dict(schedule=dict()),
                          "fast": dict(schedule=dict(n_epochs=FAST_EPOCHS["texture_filter"])),
                          "tiny": dict(channels=8, dilations=(1,), crop=16, schedule=dict(n_epochs=2, steps_per_epoch=2,
                                                                                         batch_size=8))}
#: The pose prior corrects frames of drifting skeletons where it would move them further than this quantile of its
#: corrections of held-out clean frames (people it never saw), frames of clips noisy throughout beyond the second.
POSE_QUANTILE, POSE_TEXTURE_QUANTILE = 0.5, 0.95
#: Share of held-out clean clips the amplitude step may scale: it changes whole clips.
AMPLITUDE_CLIP_RATE = 0.005
#: The noise filter's settings (fitted in closed form: about a minute on one CPU core) and its tiny test version
#: (noisy copies not put back on rigid bones: that projection was most of a tiny training's time).
NOISE_FILTER_CONFIGS = {"default": {}, "tiny": dict(half_width=1, copies=1, rigid_tolerance=None)}
#: Parts trained only when asked (``only=``): the denoiser and the motion in-filler serve options of the
#: refiner (see :data:`refiner.refinement.learned_pipeline.TYPED_REPAIRS`); once trained into ``out/parts``
#: they are calibrated and installed with the others.
OPTIONAL_PARTS = ("flaw_denoiser", "motion_infiller", "timing_estimator", "noise_residual")
#: The timing estimator's settings (about 20 minutes on one CPU core) and its tiny test version.
TIMING_CONFIGS = {"default": dict(schedule=dict()), "fast": dict(schedule=dict(n_epochs=FAST_EPOCHS["timing_estimator"])),
                  "tiny": dict(hidden=8, schedule=dict(n_epochs=2, steps_per_epoch=2, batch_size=8))}
#: The noise residual's settings (behind the noise filter of the same run, else of ``base``: about 2 minutes on one CPU
#: core) and its tiny test version.
NOISE_RESIDUAL_CONFIGS = {"default": dict(schedule=dict()), "fast": dict(schedule=dict()),
                          "tiny": dict(hidden=8, copies=1, schedule=dict(n_epochs=2, steps_per_epoch=2, batch_size=8))}
_CLASSES = {"flaw_classifier": FlawClassifier, "flaw_recognizer": FlawRecognizer, "flaw_repairer": FlawRepairer,
            "flaw_denoiser": FlawDenoiser, "motion_infiller": MotionInfiller, "timing_estimator": TimingEstimator,
            "noise_filter": NoiseFilter, "amplitude_restorer": AmplitudeRestorer, "pose_prior": PosePrior,
            "texture_filter": TextureFilter, "noise_residual": NoiseResidual}
_CONFIGS = {"flaw_classifier": CLASSIFIER_CONFIGS, "flaw_denoiser": CORRECTION_CONFIGS, "motion_infiller": CORRECTION_CONFIGS,
            "timing_estimator": TIMING_CONFIGS, "pose_prior": POSE_PRIOR_CONFIGS, "noise_residual": NOISE_RESIDUAL_CONFIGS,
            "texture_filter": TEXTURE_FILTER_CONFIGS}


def calibration_split(subjects) -> np.ndarray:
    """Boolean mask of held-out clips: the two highest-numbered subjects (10 % of clips if there are no subjects)."""
    subjects = np.asarray(subjects)
    if len(np.unique(subjects)) > 2:
        return np.isin(subjects, np.unique(subjects)[-2:])
    held = np.zeros(len(subjects), bool)
    held[:: 10] = True
    return held


def train_learned(dataset: MotionDataset, out: str | Path, *, split: str = "all", config: str = "default",
                  only: str | None = None, device: str = "auto", random_state: int = 0, max_seconds: float | None = None,
                  anchor_concepts: AnchorConcepts | None = None, progress: bool = False, base: str | Path | None = None) -> dict:
    """Train the learned parts (:data:`LEARNED_PARTS`), or the one named ``only`` (which may be one of
    :data:`OPTIONAL_PARTS`), into ``out/parts/`` (checkpoints there make a rerun resume). The noise residual is
    trained behind this run's noise filter, else the one in ``base`` (default: the shipped weights of ``split``).

    Returns ``{name: fitted part}`` for the parts trained or found finished (with ``only=None``, the
    optional parts found there too).
    """
    if only is not None and only not in LEARNED_PARTS + OPTIONAL_PARTS:
        raise ValueError(f"unknown learned part {only!r}; known: {', '.join(LEARNED_PARTS + OPTIONAL_PARTS)}.")
    if config not in LEARNED_CONFIGS:
        raise ValueError(f"unknown config {config!r}; known: {', '.join(LEARNED_CONFIGS)}.")
    parts_dir = Path(out) / "parts"
    parts_dir.mkdir(parents=True, exist_ok=True)
    names = list(LEARNED_PARTS) if only is None else [only]
    done = {n: _CLASSES[n].load(parts_dir / f"{n}.safetensors") for n in (*names, *OPTIONAL_PARTS)
            if (n in names or only is None) and (parts_dir / f"{n}.safetensors").is_file()}
    if all(n in done for n in names):
        return done
    data = dataset.split(split)
    skeleton = data.motions[0].skeleton
    clips = [m.joints for m in data]
    actions = data.actions
    anchors = [segment(c).anchors for c in clips]
    held = calibration_split(data.subjects)
    fit_idx, cal_idx = np.flatnonzero(~held), np.flatnonzero(held)

    def pick(idx):
        return [clips[i] for i in idx], actions[idx], [anchors[i] for i in idx]

    n_actions = len(dataset.action_names)
    run = dict(device=device, max_seconds=max_seconds, progress=progress)  # every part's schedule gets these
    for name in names:
        if name in done:
            continue
        t0 = time.perf_counter()
        cls = _CLASSES[name]
        if name in ("noise_filter", "amplitude_restorer"):  # closed form: no schedule, no checkpoint
            if name == "noise_filter":
                cfg = NOISE_FILTER_CONFIGS["tiny" if config == "tiny" else "default"]
                est = cls(**cfg, random_state=random_state).fit(pick(fit_idx)[0], skeleton=skeleton)
            else:
                est = cls(random_state=random_state).fit(*pick(fit_idx)[:2], skeleton=skeleton, n_actions=n_actions)
            est.save(parts_dir / f"{name}.safetensors")
            (parts_dir / f"{name}.json").write_text(json.dumps({"seconds": round(time.perf_counter() - t0, 1), "split": split,
                                                                "fit_clips": int(len(fit_idx))}, indent=1))
            done[name] = est
            continue
        cfg = dict(_CONFIGS.get(name, LEARNED_CONFIGS)[config])
        schedule = replace(cls().schedule, **cfg.pop("schedule"), **run)
        est = cls(**cfg, schedule=schedule, random_state=random_state)
        if name == "noise_residual":
            est.fit(pick(fit_idx)[0], _noise_filter_behind(done, parts_dir, dataset, split, base),
                    skeleton=skeleton, validation=pick(cal_idx)[0], checkpoint=parts_dir / f"{name}.checkpoint.safetensors")
        elif name in ("flaw_classifier", "flaw_denoiser", "motion_infiller", "timing_estimator", "pose_prior",
                      "texture_filter"):  # action-agnostic
            est.fit(pick(fit_idx)[0], skeleton=skeleton, validation=pick(cal_idx)[0],
                    checkpoint=parts_dir / f"{name}.checkpoint.safetensors")
        elif name == "flaw_recognizer":
            est.fit(*pick(fit_idx), skeleton=skeleton, n_actions=n_actions, validation=pick(cal_idx),
                    checkpoint=parts_dir / f"{name}.checkpoint.safetensors")
        else:
            if anchor_concepts is None:
                anchor_concepts = fit_anchor_concepts(*pick(fit_idx), n_actions=n_actions, config=config,
                                                      random_state=random_state)
                anchor_concepts.save(parts_dir / "anchor_concepts.safetensors")  # weights without a base keep them
            est.fit(*pick(fit_idx), anchor_concepts, skeleton=skeleton, validation=pick(cal_idx),
                    checkpoint=parts_dir / f"{name}.checkpoint.safetensors")
        est.save(parts_dir / f"{name}.safetensors")
        (parts_dir / f"{name}.json").write_text(json.dumps({
            "seconds": round(time.perf_counter() - t0, 1), "split": split, "fit_clips": int(len(fit_idx)),
            "calibration_clips": int(len(cal_idx)), "epochs": len(est.history_),
            "steps": len(est.history_) * est.schedule.steps_per_epoch if est.schedule.steps_per_epoch else None,
            "history": est.history_[-3:]}, indent=1))
        done[name] = est
    return done


def install_learned(folder: str | Path, parts: dict, *, out: str | Path | None = None, info: dict | None = None):
    """Add the learned parts to the refiner saved in ``folder`` and save it to ``out`` (default: in place).

    The manifest records, under ``learned``, how they were trained (``info``) and the flaw threshold.
    """
    refiner = Refiner.load(folder, method="concepts")
    refiner.flaw_classifier = parts["flaw_classifier"]
    refiner.flaw_recognizer = parts["flaw_recognizer"]
    refiner.flaw_repairer = parts["flaw_repairer"]
    refiner.flaw_denoiser = parts.get("flaw_denoiser")
    refiner.motion_infiller = parts.get("motion_infiller")
    refiner.timing_estimator = parts.get("timing_estimator")
    refiner.noise_filter = parts.get("noise_filter")
    refiner.amplitude_restorer = parts.get("amplitude_restorer")
    refiner.pose_prior = parts.get("pose_prior")
    refiner.texture_filter = parts.get("texture_filter")
    refiner.noise_residual = parts.get("noise_residual")
    refiner.denoising = "runs" if refiner.noise_filter is not None else "flagged"
    refiner.retiming = "estimated" if refiner.timing_estimator is not None else "flagged"
    refiner.manifest["learned"] = {**(info or {}), "flaw_threshold": float(parts["flaw_recognizer"].threshold_),
                                   "classifier_threshold": float(parts["flaw_classifier"].threshold_),
                                   "correction_threshold_m": float(parts["flaw_repairer"].correction_threshold_),
                                   **({"denoiser_threshold_m": float(parts["flaw_denoiser"].threshold_)}
                                      if parts.get("flaw_denoiser") is not None else {}),
                                   **({"timing_threshold_frames": float(parts["timing_estimator"].threshold_)}
                                      if parts.get("timing_estimator") is not None else {}),
                                   **({"noise_threshold_m": float(parts["noise_filter"].threshold_)}
                                      if parts.get("noise_filter") is not None else {}),
                                   **({"pose_prior_threshold_m": float(parts["pose_prior"].threshold_),
                                       "pose_prior_texture_threshold_m": float(parts["pose_prior"].texture_threshold_)}
                                      if parts.get("pose_prior") is not None else {}),
                                   **({"amplitude_gate": parts["amplitude_restorer"].gate_,
                                       "amplitude_target": parts["amplitude_restorer"].target_}
                                      if parts.get("amplitude_restorer") is not None else {})}
    refiner.save(out or folder, half=True, int8=STORED_INT8)
    return Refiner.load(out or folder)


def install_part(folder: str | Path, name: str, part, *, info: dict | None = None) -> None:
    """Add one fitted and calibrated optional part (:data:`OPTIONAL_PARTS`) to the refiner saved in ``folder``, in
    place: its file (float16, int8 codes if in :data:`STORED_INT8`), its sha256 under ``files``, its threshold and
    ``info`` under ``learned``. Every other file stays byte for byte, so its figures stay those measured."""
    if name not in OPTIONAL_PARTS:
        raise ValueError(f"install_part adds one of {', '.join(OPTIONAL_PARTS)}; got {name!r}.")
    folder = Path(folder)
    manifest, _ = read_refiner_manifest(folder, _PARTS)  # a folder that fails its hashes is refused here
    path = folder / f"{name}.safetensors"
    part.save(path, half=True, int8=name in STORED_INT8)
    learned = dict(manifest.get("learned", {}))
    if _THRESHOLD_KEYS[name] is not None:
        learned[_THRESHOLD_KEYS[name]] = float(part.threshold_)
    if getattr(part, "agreed_threshold_", None) is not None:  # the timing estimator's, with the classifier's agreement
        learned[AGREED_KEY] = float(part.agreed_threshold_)
    learned[name] = info or {}
    write_manifest(folder / "manifest.json", {**manifest, "learned": learned,
                                              "files": {**manifest["files"], name: {"file": path.name,
                                                                                    "sha256": file_sha256(path)}}})


def fit_anchor_concepts(clips, actions, anchors, *, n_actions: int, config: str = "default",
                        random_state: int = 0) -> AnchorConcepts:
    """The anchor concepts the repair network attends to: K-means (8 per action, 2 with ``config="tiny"``)
    over the anchor poses ``clips[i][anchors[i]]`` of clips ``(T_i, J, 3)`` metres with ``actions (N,)``."""
    poses = np.concatenate([c[a] for c, a in zip(clips, anchors)])
    acts = np.concatenate([np.full(len(a), act) for a, act in zip(anchors, actions)])
    return AnchorConcepts(2 if config == "tiny" else 8, random_state=random_state).fit(poses, acts, n_actions=n_actions)


def train_learned_refiner(dataset: MotionDataset, out: str | Path, *, split: str = "all", base: str | Path | None = None,
                          only: str | None = None, **kwargs):
    """Train the learned steps (:func:`train_learned`) and save them with the parts of the refiner in
    ``base`` (default: the shipped weights of ``split``) to ``out``; None when ``only`` trains one part."""
    parts = train_learned(dataset, out, split=split, only=only, base=base, **kwargs)
    if only in OPTIONAL_PARTS and base is not None:  # one option added to a finished refiner
        return add_optional_part(parts[only], only, dataset, out, split=split, base=base)
    if only is not None:
        return None
    parts = {name: as_stored(name, part) for name, part in parts.items()}
    thresholds = calibrate_learned(parts, dataset, split=split)  # the parts keep their own thresholds
    kept = {k: thresholds[k] for k in (NATURAL_BONES_KEY, SKATING_KEY, AGREED_KEY) if k in thresholds}
    base = _default_base(dataset, split) if base is None else base
    info = {}
    for name in LEARNED_PARTS + OPTIONAL_PARTS:
        log_path = Path(out) / "parts" / f"{name}.json"
        if log_path.is_file():
            info[name] = {k: v for k, v in json.loads(log_path.read_text()).items() if k != "history"}
    return install_learned(base, parts, out=out, info={"split": split, **bone_proportion_records(dataset.split(split)),
                                                        **kept, **info})


def _default_base(dataset: MotionDataset, split: str) -> Path:
    """The shipped weights of ``dataset`` and ``split``."""
    return _WEIGHTS / (f"{dataset.name}" + ("" if split == "all" else f"-{split}"))


def _noise_filter_behind(done: dict, parts_dir: Path, dataset: MotionDataset, split: str, base) -> NoiseFilter:
    """The noise filter a noise residual is trained behind: this run's (trained or in ``parts_dir``), else the one of
    the refiner in ``base`` (default: the shipped weights of ``split``)."""
    if "noise_filter" in done:
        return done["noise_filter"]
    if (parts_dir / "noise_filter.safetensors").is_file():
        return NoiseFilter.load(parts_dir / "noise_filter.safetensors")
    _, paths = read_refiner_manifest(_default_base(dataset, split) if base is None else base, _PARTS)
    if "noise_filter" not in paths:
        raise ValueError("the noise residual is trained behind a noise filter: train one in the same run "
                         "(`--only noise_filter`) or give a `base` whose weights hold one.")
    return NoiseFilter.load(paths["noise_filter"])


def add_optional_part(part, name: str, dataset: MotionDataset, out: str | Path, *, split: str = "all",
                      base: str | Path) -> Refiner:
    """The refiner in ``base`` copied to ``out`` with ``part`` (one of :data:`OPTIONAL_PARTS`, trained on ``split``)
    calibrated on the split's held-out subjects (:func:`calibration_split`) and installed (:func:`install_part`)."""
    data = dataset.split(split)
    clips = [data.motions[i].joints for i in np.flatnonzero(calibration_split(data.subjects))]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    part = as_stored(name, part)
    if name == "timing_estimator":
        part.calibrate(clips, clip_rate=TIMING_CLIP_RATE)
    elif name == "flaw_denoiser":
        part.calibrate(clips, clip_rate=CLIP_RATE)
    manifest, paths = read_refiner_manifest(base, _PARTS)
    for path in [*paths.values(), Path(base) / "manifest.json"]:
        if Path(path).resolve() != (out / Path(path).name).resolve():
            shutil.copyfile(path, out / Path(path).name)
    log_path = out / "parts" / f"{name}.json"
    info = {k: v for k, v in json.loads(log_path.read_text()).items() if k != "history"} if log_path.is_file() else {}
    install_part(out, name, part, info=info)
    return Refiner.load(out)


def as_stored(name: str, part):
    """``part`` as the saved refiner will hold it, to be calibrated so: through int8 codes if ``name`` is in
    :data:`STORED_INT8` (they move its outputs a little), else itself."""
    if name not in STORED_INT8:
        return part
    with tempfile.TemporaryDirectory() as tmp:
        part.save(Path(tmp) / f"{name}.safetensors", int8=True)
        return type(part).load(Path(tmp) / f"{name}.safetensors")


def bone_proportion_records(data: MotionDataset) -> dict:
    """``bone_proportions`` of the clips' own skeleton and, for HumanAct12 clips, ``converted_bone_proportions``
    of every layout :class:`~refiner.refinement.converted_refinement.ConvertedRefiner` serves through them
    (the clips converted there), as the manifest's ``learned`` entry keeps them."""
    clips, skeleton = [m.joints for m in data.motions], data.motions[0].skeleton
    record = {"bone_proportions": BoneProportions.from_clips(clips, skeleton).to_dict()}
    if skeleton == "humanact12":
        record["converted_bone_proportions"] = {
            name: BoneProportions.from_clips([convert(c, skeleton, name) for c in clips], name).to_dict()
            for name in CONVERTED_SKELETONS}
    return record


def calibrate_learned(parts: dict, dataset: MotionDataset, *, split: str = "all", clip_rate: float = CLIP_RATE) -> dict:
    """Set both flaw thresholds on the clean clips of the split's held-out subjects (:func:`calibration_split`):
    each detector flags at most ``clip_rate`` of them; and the bone variation their clean clips reach (the refiner gives
    a clip within it its own bones back, ``Refiner(natural_bones=)``); and, on every clip of the split, the skating step's
    threshold (:func:`~refiner.refinement.skating.calibrate_skating`). Returns the thresholds."""
    data = dataset.split(split)
    held = np.flatnonzero(calibration_split(data.subjects))
    clips, actions = [data.motions[i].joints for i in held], data.actions[held]
    long_clips = [m.joints for m in data.motions if len(m.joints) > 2 * SKATING_WINDOW]  # a rule: every clip serves
    return {"classifier_threshold": parts["flaw_classifier"].calibrate(clips, clip_rate=clip_rate),
            "flaw_threshold": parts["flaw_recognizer"].calibrate(clips, actions, clip_rate=clip_rate),
            "correction_threshold_m": parts["flaw_repairer"].calibrate(clips, actions, clip_rate=clip_rate),
            **({"denoiser_threshold_m": parts["flaw_denoiser"].calibrate(clips, clip_rate=clip_rate)}
               if "flaw_denoiser" in parts else {}),
            **({"timing_threshold_frames": parts["timing_estimator"].calibrate(clips, clip_rate=TIMING_CLIP_RATE),
                AGREED_KEY: parts["timing_estimator"].agreed_threshold_} if "timing_estimator" in parts else {}),
            **({"noise_threshold_m": parts["noise_filter"].calibrate(clips, clip_rate=clip_rate)}
               if "noise_filter" in parts else {}),
            **(dict(zip(("pose_prior_threshold_m", "pose_prior_texture_threshold_m"), parts["pose_prior"].calibrate(
                clips, quantile=POSE_QUANTILE, texture_quantile=POSE_TEXTURE_QUANTILE))) if "pose_prior" in parts else {}),
            **(dict(zip(("amplitude_gate", "amplitude_target"), parts["amplitude_restorer"].calibrate(
                clips, actions, clip_rate=AMPLITUDE_CLIP_RATE))) if "amplitude_restorer" in parts else {}),
            NATURAL_BONES_KEY: min(1.0, max(bone_variation(data.motions[i].joints, data.motions[i].skeleton)
                                            for i in held)),
            **({SKATING_KEY: calibrate_skating(long_clips, data.motions[0].skeleton)} if long_clips else {}),
            "clip_rate": clip_rate, "calibration_clips": int(len(held))}
