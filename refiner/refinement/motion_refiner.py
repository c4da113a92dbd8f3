"""The default refiner: a declared list of steps around one learned model of motion.

:class:`MotionRefiner` checks the input, runs its declared steps (:class:`~refiner.refinement.steps.ground.GroundStep`: a body
floating above its floor without flying lowered onto it; :class:`~refiner.refinement.steps.ground.GlideStep`: a
body gliding over it with its planted feet slid back; :class:`~refiner.refinement.steps.retime.RetimeStep`: the motion
model's recognition, flagged runs re-timed; each kept where verified; the model's in-fill and a rigid-bones step
did not earn their place, ``docs/decisions.md`` D10, D20) and reports each change. Frames no step changed come back
exactly as given; changed frames keep the clip's own bone lengths. Skeletons without a model of their own (``uestc``,
``humanml3d``) are refined through HumanAct12's: converted in, refined, and only the change converted back.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from refiner.core.manifest import file_sha256
from refiner.core.motion import Motion
from refiner.core.output_kind import like_input
from refiner.core.skeleton_conversion import convert
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_joints
from refiner.refinement.inputs import MIN_FRAMES, check_metres, check_metres_each, thread_limits
from refiner.refinement.motion_model import MotionModel
from refiner.refinement.report import start_reports
from refiner.refinement.steps.ground import GlideConfig, GlideStep, GroundConfig, GroundStep
from refiner.refinement.steps.infill import InfillConfig, clip_scores
from refiner.refinement.steps.retime import RetimeConfig, RetimeStep

__all__ = ["MotionRefiner", "CalibrationConfig", "calibrated_threshold", "write_motion_weights"]

_WEIGHTS = Path(__file__).resolve().parents[1] / "weights"
_CONVERTED = ("uestc", "humanml3d")
#: Longest clip refined in one piece (30 minutes at 20 fps); longer input is refused rather than silently split.
MAX_FRAMES = 36_000
_CACHE: dict = {}


@dataclass(frozen=True)
class CalibrationConfig:
    """How a motion model's threshold is calibrated on clean clips it never saw: the share of ``window``-frame pieces
    (a generator's usual clip, 3 s at 20 fps) the detector may flag; ``min_run`` as in :class:`InfillConfig`;
    ``still_share``: the share of clean frames stiller than the re-timing's ``still_m``."""

    share: float = 0.03
    window: int = 60
    min_run: int = 2
    still_share: float = 0.01


def calibrated_threshold(model: MotionModel, clips, actions, config: CalibrationConfig = CalibrationConfig()) -> float:
    """The flaw-probability threshold that flags ``config.share`` of ``config.window``-frame pieces of the clean
    ``clips`` (real, unseen by the model): pieces, not clips, so long and short calibration clips weigh by their length."""
    scores = []
    for c, a in zip(clips, actions):
        if len(c) < MIN_FRAMES:
            continue
        p = model.scan(np.asarray(c)[None], [a])[1]
        starts = range(0, max(1, len(c) - config.window // 2), config.window)
        scores += [clip_scores(p[:, s:s + config.window], config.min_run)[0] for s in starts]
    return float(np.quantile(scores, 1.0 - config.share))


def write_motion_weights(folder, models: dict, thresholds: dict, *, skeleton: str, dataset: str, licence: str,
                         split: str = "train", calibration: CalibrationConfig = CalibrationConfig(),
                         support: dict | None = None, notes: dict | None = None) -> None:
    """Save motion ``models`` (name -> MotionModel; ``"all"`` is the default, ``"fold0"`` / ``"fold1"`` the benchmark's)
    with their calibrated ``thresholds``, the calibrated ``support`` values (``{"ground": fields of GroundConfig,
    "glide": fields of GlideConfig, "retime": {"still_m": ...}}``, any left out) and a ``manifest.json``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    entries = {}
    for name, model in models.items():
        path = folder / f"motion_model_{name}.safetensors"
        model.save(path, half=True)
        entries[name] = {"file": path.name, "sha256": file_sha256(path), "threshold": float(thresholds[name]),
                         "mechanisms": model.training_.get("mechanisms", [])}
    manifest = {"kind": "motion_model", "skeleton": skeleton, "dataset": dataset, "split": split, "licence": licence,
                "models": entries, "calibration_config": asdict(calibration), **(support or {}),
                **(notes or {})}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1))


class MotionRefiner:
    """Refine clips of one skeleton with a motion model.

    Parameters
    ----------
    model : MotionModel
    config : RetimeConfig or InfillConfig
        Its ``threshold`` and ``still_m`` come from the weights' manifest (:func:`calibrated_threshold`,
        :func:`~refiner.refinement.steps.retime.calibrated_stillness`); an :class:`InfillConfig` leaves freezes alone.
    ground, glide : GroundConfig, GlideConfig, optional
        The support steps' options (their heights from the manifest); None leaves a step out.
    skeleton : str, optional
        The clips' skeleton when it differs from the model's (converted through it; ``uestc``, ``humanml3d``).
    threads : int or None, default=1
        torch and BLAS threads while refining (None: leave them as they are).
    """

    method = "motion"

    def __init__(self, model: MotionModel, config: InfillConfig, *, ground: GroundConfig | None = None,
                 glide: GlideConfig | None = None, skeleton: str | None = None, threads: int | None = 1):
        self.model, self.config, self.threads = model, config, threads
        self.skeleton = get_skeleton(skeleton or model.skeleton).name
        self.action_names = model.action_names
        support = ((GroundStep(model.skeleton, ground),) if ground is not None else ()) + \
            ((GlideStep(model.skeleton, glide, judge=model),) if glide is not None else ())
        self.steps = support + (RetimeStep(model, config),)

    @classmethod
    def pretrained(cls, skeleton: str = "humanact12", *, model: str = "all", weights=None, **options) -> "MotionRefiner":
        """The shipped motion model of ``skeleton`` (``model``: ``"all"``, or ``"fold0"`` / ``"fold1"``, the benchmark's,
        each trained without one fold of flaw mechanisms); ``weights``: a folder holding ``<skeleton>-motion/``, looked
        in first. ``options`` replace fields of :class:`~refiner.refinement.steps.retime.RetimeConfig` (its
        ``threshold`` and ``still_m`` come from the manifest)."""
        name = get_skeleton(skeleton).name
        base = "humanact12" if name in _CONVERTED else name
        folders = [Path(w) / f"{base}-motion" for w in ([weights] if weights else [])] + [_WEIGHTS / f"{base}-motion"]
        folder = next((f for f in folders if (f / "manifest.json").is_file()), None)
        if folder is None:
            raise ValueError(f"no motion model for skeleton {skeleton!r} (looked in {', '.join(map(str, folders))}).")
        manifest = json.loads((folder / "manifest.json").read_text())
        if model not in manifest["models"]:
            raise ValueError(f"unknown motion model {model!r}; {folder} holds {', '.join(manifest['models'])}.")
        entry = manifest["models"][model]
        key = (str(folder.resolve()), model)
        if key not in _CACHE:
            path = folder / entry["file"]
            if file_sha256(path) != entry["sha256"]:
                raise ValueError(f"{path} does not match the sha256 in its manifest; reinstall or retrain it.")
            _CACHE[key] = MotionModel.load(path)
        config = RetimeConfig(**{"threshold": entry["threshold"], **manifest.get("retime", {}), **options})
        ground = GroundConfig(**manifest["ground"]) if "ground" in manifest else None
        glide = GlideConfig(**manifest["glide"]) if "glide" in manifest else None
        return cls(_CACHE[key], config, ground=ground, glide=glide, skeleton=name)

    def refine(self, seq, *, action=None, mode: str | None = None, return_report: bool = False):
        """Refine a Motion, ``(T, J, 3)`` or ``(B, T, J, 3)`` array or tensor; returns the same kind (see
        :func:`refiner.refine`). ``mode`` is accepted for the concepts method's callers and must be ``"full"``."""
        if mode not in (None, "full"):
            raise ValueError(f"mode={mode!r} belongs to method='concepts'; the motion refiner has one mode, 'full'.")
        with thread_limits(self.threads):
            return self._refine(seq, action, return_report)

    def _refine(self, seq, action, return_report):
        skel = get_skeleton(self.skeleton)
        if isinstance(seq, Motion):
            if seq.skeleton != self.skeleton:
                raise ValueError(f"this refiner is for skeleton {self.skeleton!r}; got a {seq.skeleton!r} motion.")
            check_joints(seq.joints, skeleton=skel, max_frames=MAX_FRAMES)
            check_metres(seq.joints, skel)
            out, reports = self._refine_batch(seq.joints[None], [seq.action if action is None else action], False)
            result = seq.with_joints(out[0].astype(np.float32))
            return (result, reports[0]) if return_report else result
        batched = len(getattr(seq, "shape", np.shape(seq))) == 4
        x = check_joints(seq, skeleton=skel, batched=batched, max_frames=MAX_FRAMES)
        clips = x if batched else x[None]
        check_metres_each(clips, skel, batched)
        actions = list(action) if (batched and isinstance(action, (list, tuple, np.ndarray))) else [action] * len(clips)
        if len(actions) != len(clips):
            raise ValueError(f"`action` must have one entry per clip ({len(clips)}); got {len(actions)}.")
        out, reports = self._refine_batch(clips, actions, batched)
        out = like_input((out if batched else out[0]).astype(np.float32), seq, x)
        return (out, reports if batched else reports[0]) if return_report else out

    def _refine_batch(self, clips, actions, batched):
        reports = start_reports(clips.shape[1], actions, "full", self.action_names, batched=batched)
        known = [r.action for r in reports]
        out = np.array(clips, dtype=np.float32)
        if clips.shape[1] < MIN_FRAMES:
            return out, reports
        inner = clips if self.skeleton == self.model.skeleton else convert(clips, self.skeleton, self.model.skeleton)
        refined = np.array(inner, dtype=np.float64)
        for step in self.steps:
            refined, changes, prob = step.refine(refined, known)
            for r, p in zip(reports, [] if prob is None else prob):
                r.flaw_probability, r.threshold = p.max(1).round(4).tolist(), self.config.threshold
            for r, entries in zip(reports, changes):
                r.flagged_frames = sorted(set(r.flagged_frames).union(*(range(e["start"], e["stop"]) for e in entries)))
                r.changes += [_change(e, self.model) for e in entries if e["kept"]]
                r.not_kept += [_change(e, self.model) for e in entries if not e["kept"]]
                r.notes += [f"{e['step']}: frames {e['start']}-{e['stop']} not changed ({_why_not(e)})"
                            for e in entries if not e["kept"]]
        for i, r in enumerate(reports):
            frames = r.changed_frames
            if not frames.any():
                continue
            if self.skeleton == self.model.skeleton:
                out[i, frames] = refined[i, frames]
            else:  # only the change goes back, so joints the conversion estimates stay as given
                delta = convert(refined[i, frames], self.model.skeleton, self.skeleton) - convert(inner[i, frames], self.model.skeleton, self.skeleton)
                out[i, frames] = clips[i, frames] + delta
        return out, reports


_HOW = {"infill": "in-filled from context by the motion model", "retime": "re-timed along its own path at an even pace",
        "ground": "lowered along the vertical onto the clip's floor",
        "glide": "slid back along the floor so the planted feet stay"}


def _why_not(entry: dict) -> str:
    if entry.get("passed_over"):
        return "the body never stands still there, so no time was lost to re-time"
    return f"worse on {', '.join(entry['worse'])}" if entry["worse"] else "not more real"


def _change(entry: dict, model: MotionModel) -> dict:
    """A step's run as a report entry: frames, parts in words, whether it was kept, and why."""
    skel = get_skeleton(model.skeleton)
    names = [skel.joint_names[skel.bones[p, 1]] if p < len(skel.bones) else "root" for p in entry["parts"]]
    how = _HOW.get(entry["step"], entry["step"])
    if entry.get("passed_over"):
        return {"step": entry["step"], "start": entry["start"], "stop": entry["stop"], "parts": names, "kept": False,
                "reason": f"flaw probability {entry['flaw_probability'][0]:.2f}, not kept: {_why_not(entry)}"}
    if "flaw_probability" in entry:
        before, after = entry["flaw_probability"]
        frozen = f"; {entry['still_frames']} frames frozen" if entry.get("still_frames", 0) >= 2 else ""
        reason = f"flaw probability {before:.2f} -> {after:.2f}{frozen}; {how}"
    elif entry["step"] == "glide":
        reason = f"body and planted feet slide {entry['gap_cm']:.1f} cm over the floor; {how}"
    else:
        reason = f"body floats {entry['gap_cm']:.1f} cm above its floor, not in flight; {how}"
    return {"step": entry["step"], "start": entry["start"], "stop": entry["stop"], "parts": names, "kept": entry["kept"],
            "reason": reason if entry["kept"] else f"{reason}, not kept: {_why_not(entry)}"}
