"""The demo: sample every action from a reference generator, refine it, and draw what changed.

:func:`run_demo` wraps a shipped reference generator (:mod:`refiner.reference`) in a
:class:`~refiner.refinement.refined_generator.RefinedGenerator`, samples one clip per HumanAct12 action, and writes
for each action, from its refinement report: an animation and a key-frame picture of the generated clip (faint)
under the refined one (solid), front and side, with the ground and the feet's paths, frames framed in the colour of
the step that changed them and "flagged" only where a detector flagged (:mod:`refiner.io.change_views`); a plot
of the per-frame flaw probability (the concepts method's: anchor probability) with its threshold and the changes;
a summary figure (jerk, foot skating, bone-length variation, cm moved, recogniser confidence, before and after);
the motions as ``.npy`` and the report as JSON. The HumanAct12 recogniser (hidden state ``"fixed"``, so before and
after see the same noise) scores each clip.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from tqdm.auto import tqdm

from refiner.cli.options import (GENERATOR_NAMES, GIF_DPI, GIF_PANEL_PX, gif_size_argument, int_or_str, set_threads,
                                  threads_argument)
from refiner.core.validation import check_action
from refiner.io.datasets import HUMANACT12_ACTIONS
from refiner.plugins.manager import get_plugin_manager
from refiner.refinement.refined_generator import RefinedGenerator

__all__ = ["GIF_DPI", "GIF_PANEL_PX", "DemoRow", "DemoResult", "run_demo", "format_table", "unchanged_note",
           "demo_arguments", "demo_run"]


def demo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="output folder (created)")
    p.add_argument("--generator", default="a2m", choices=GENERATOR_NAMES,
                   help="reference generator: a2m (Lie GRU VAE, default), actor (transformer CVAE), mdm (diffusion); "
                        "-large: the larger, longer-trained variants")
    p.add_argument("--actions", default=None,
                   help="comma-separated action names or indices (default: all 12; --quick: walk, boxing)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-mp4", action="store_true", help="GIF only, even when ffmpeg is on PATH")
    p.add_argument("--quick", action="store_true", help="two actions and a small animation (for tests)")
    p.add_argument("--force", action="store_true", help="replace the demo's files in an existing --out folder")
    gif_size_argument(p)
    threads_argument(p)


def demo_run(args: argparse.Namespace) -> int:
    set_threads(args.threads)

    actions = None if args.actions is None else [int_or_str(a) for a in args.actions.split(",") if a.strip()]
    print(f"sampling {'every action' if actions is None and not args.quick else 'the chosen actions'} from the "
          f"{args.generator!r} reference generator, refining and drawing into {args.out} ...", flush=True)
    result = run_demo(args.out, generator=args.generator, actions=actions, quick=args.quick, random_state=args.seed,
                      mp4=False if args.no_mp4 else None, progress=True, gif_size=args.gif_size, overwrite=args.force)
    print(format_table(result.rows))
    if note := unchanged_note(result.rows):
        print(note)
    print("confidence: the HumanAct12 recogniser's probability of the sampled action (hidden state fixed); "
          "frames flagged: frames the refiner's detector flagged (a flagged run is changed only where verified).")
    n_files = sum(len(r.files) for r in result.rows) + len(result.files)
    print(f"{n_files} files written to {result.out} in {result.seconds:.1f} s "
          f"(per action: .gif before/after, _keyframes.png, _scores.png, _summary.png, _before/_after.npy, "
          "_report.json)")
    return 0


@dataclass
class DemoRow:
    """One action of the demo.

    Attributes
    ----------
    action, action_name : int, str
    frames : int
    frames_changed, frames_flagged : int
        Frames the refiner changed, and frames its detector flagged.
    confidence_before, confidence_after : float
        Recogniser probability of the true action (softmax), before and after refinement.
    predicted_before, predicted_after : str
        Recogniser's top class names.
    files : list of str
        Files written for this action, relative to the output folder.
    """

    action: int
    action_name: str
    frames: int
    frames_changed: int
    frames_flagged: int
    confidence_before: float
    confidence_after: float
    predicted_before: str
    predicted_after: str
    files: list[str] = field(default_factory=list)


@dataclass
class DemoResult:
    """What :func:`run_demo` did: one row per action, the summary files and the wall time."""

    generator: str
    out: Path
    rows: list[DemoRow]
    files: list[str]
    seconds: float

    def to_dict(self) -> dict:
        return {"generator": self.generator, "out": str(self.out), "seconds": round(self.seconds, 2),
                "rows": [asdict(r) for r in self.rows], "files": self.files}


def run_demo(
    out: str | os.PathLike,
    *,
    generator: str = "a2m",
    actions: Sequence[int | str] | None = None,
    quick: bool = False,
    random_state: int = 0,
    refiner: Any = None,
    mp4: bool | None = None,
    progress: bool = False,
    generator_folder: str | os.PathLike | None = None,
    recognizer_dir: str | os.PathLike | None = None,
    gif_size: int = GIF_PANEL_PX,
    overwrite: bool = False,
) -> DemoResult:
    """Sample, refine and visualise one clip per action.

    Parameters
    ----------
    out : path
        Output folder (created).
    generator : {"a2m", "actor", "mdm", "a2m-large", "actor-large"}, default="a2m"
        Which shipped reference generator to sample.
    actions : sequence of int or str, optional
        HumanAct12 actions; default all 12 (two with ``quick``).
    quick : bool, default=False
        Two actions and a small, short animation (for tests).
    random_state : int, default=0
        Seed of the samples; action ``a`` uses ``random_state + a``.
    refiner : object, optional
        Anything :class:`~refiner.refinement.refined_generator.RefinedGenerator` accepts; default the default
        refiner, ``MotionRefiner.pretrained("humanact12")``.
    mp4 : bool, optional
        Also write MP4 animations: None (default) when ffmpeg is on PATH.
    progress : bool, default=False
        Show a progress bar (stderr).
    generator_folder : path, optional
        Folder of generator weights; default the shipped ones.
    recognizer_dir : path, optional
        Folder of the Action2Motion recognisers; default the HumanAct12 recogniser shipped in the
        package (:mod:`refiner.evaluation.evaluator_weights`), so the demo needs no data folder.
    gif_size : int, default=GIF_PANEL_PX
        Edge of each animation panel in pixels (``quick`` draws small ones regardless).
    overwrite : bool, default=False
        Replace files of a previous demo in ``out``; without it, any of the demo's files already there
        is a ``ValueError`` raised before anything is written (the CLI's ``--force``).

    Returns
    -------
    DemoResult

    Raises
    ------
    ValueError
        Unknown generator or action, missing weights or recogniser, a bad ``gif_size``, or files
        of the demo already in ``out`` without ``overwrite``.
    """
    # these import torch or matplotlib: here, so that --help stays cheap
    from refiner.evaluation.clip_summary import summary_figure
    from refiner.evaluation.evaluators import load_recognizer
    from refiner.io import viz
    from refiner.reference import load_reference_generator
    from refiner.refinement.motion_refiner import MotionRefiner

    started = time.perf_counter()
    if isinstance(random_state, (bool, np.bool_)) or not isinstance(random_state, (int, np.integer)):
        raise ValueError(f"`random_state` must be an int seed; got {random_state!r}.")
    if actions is None:
        actions = (1, 10) if quick else range(len(HUMANACT12_ACTIONS))
    labels = [check_action(a, HUMANACT12_ACTIONS) for a in actions]
    if not labels:
        raise ValueError("`actions` must name at least one action; got none.")
    if isinstance(gif_size, (bool, np.bool_)) or not isinstance(gif_size, (int, np.integer)) or gif_size < 1:
        raise ValueError(f"`gif_size` must be a positive int (pixels); got {gif_size!r}.")
    out = Path(out)
    existing = _existing_outputs(out, [f"{a:02d}_{HUMANACT12_ACTIONS[a]}" for a in labels])
    if existing and not overwrite:
        shown = ", ".join(existing[:4]) + (f" and {len(existing) - 4} more" if len(existing) > 4 else "")
        raise ValueError(f"refusing to overwrite {shown} in {str(out)!r}; pass --force (overwrite=True) "
                         "or choose another --out.")
    out.mkdir(parents=True, exist_ok=True)

    gen = load_reference_generator(generator, folder=generator_folder)
    pm = get_plugin_manager(autoload=False)
    if refiner is None:
        refiner = MotionRefiner.pretrained("humanact12")
    wrapped = RefinedGenerator(gen, adapter=gen.adapter, refiner=refiner, skeleton="humanact12",
                               adapter_options=gen.adapter_options(), plugin_manager=pm)
    # The anchor detector's probability threshold, drawn on the score plots (0.5 for other refiners).
    detect = float(getattr(getattr(refiner, "recognizer", None), "detect_threshold_", 0.5))
    recognizer = load_recognizer("humanact12", hidden="fixed", directory=recognizer_dir)
    n_frames = 24 if quick else None
    gif = {"panel_size": 1.6, "dpi": 40} if quick else {"panel_size": gif_size / GIF_DPI, "dpi": GIF_DPI}

    samples = []
    for label in tqdm(labels, desc=f"demo ({generator})", disable=not progress, unit="action"):
        after, raw, reports = wrapped.sample(label, n=1, return_raw=True, return_report=True,
                                             random_state=random_state + label)
        before = gen.to_motions(raw, label, plugin_manager=pm)[0]
        after, report = after[0], reports[0]
        stem = f"{label:02d}_{HUMANACT12_ACTIONS[label]}"
        files = _write_action(out, stem, before, after, report, viz, gif, n_frames, mp4, detect)
        samples.append((label, before, after, report, files))

    befores = [s[1] for s in samples]
    afters = [s[2] for s in samples]
    p_before = _softmax(recognizer.predict_logits(befores, crop="start"))
    p_after = _softmax(recognizer.predict_logits(afters, crop="start"))
    names = recognizer.config.class_names
    rows = []
    for i, (label, before, after, report, files) in enumerate(samples):
        stem = f"{label:02d}_{HUMANACT12_ACTIONS[label]}"
        summary_figure(before, after, report, path=out / f"{stem}_summary.png",
                       confidence=(p_before[i, label], p_after[i, label]),
                       title=f"{HUMANACT12_ACTIONS[label].replace('_', ' ')}: generated and refined")
        files.insert(files.index(f"{stem}_scores.png") + 1, f"{stem}_summary.png")
        rows.append(DemoRow(
            action=label, action_name=HUMANACT12_ACTIONS[label], frames=before.n_frames,
            frames_changed=int(report.changed_frames.sum()), frames_flagged=len(report.flagged_frames),
            confidence_before=round(float(p_before[i, label]), 4), confidence_after=round(float(p_after[i, label]), 4),
            predicted_before=str(names[int(p_before[i].argmax())]), predicted_after=str(names[int(p_after[i].argmax())]),
            files=files,
        ))
    result = DemoResult(generator=generator, out=out, rows=rows, files=["summary.json", "summary.md"],
                        seconds=time.perf_counter() - started)
    (out / "summary.md").write_text(f"# motion-refiner demo ({generator} reference generator)\n\n"
                                    + format_table(rows) + "\n")
    (out / "summary.json").write_text(json.dumps(result.to_dict(), indent=1) + "\n")
    return result


def unchanged_note(rows: Sequence[DemoRow]) -> str:
    """What to tell a user whose demo changed no frame (empty when some frame changed)."""
    if not rows or any(r.frames_changed for r in rows):
        return ""
    flagged = sum(r.frames_flagged for r in rows)
    why = "no frame was flagged" if not flagged else (
        f"{flagged} flagged frame{'s' * (flagged != 1)} left as given (refused by verification, or passed over where "
        "the body never stands still)")
    return (f"No frame was changed: {why}. The refiner leaves as given what it cannot show to be better; other "
            "clips (--seed, --generator) may hold flaws it repairs.")


def format_table(rows: Sequence[DemoRow]) -> str:
    """The demo's per-action table as Markdown."""
    header = ["action", "frames changed", "frames flagged", "confidence before", "confidence after",
              "predicted before", "predicted after"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        lines.append(f"| {r.action_name} | {r.frames_changed}/{r.frames} | {r.frames_flagged}/{r.frames} | "
                     f"{r.confidence_before:.3f} | {r.confidence_after:.3f} | {r.predicted_before} | "
                     f"{r.predicted_after} |")
    if rows:
        mean_b = np.mean([r.confidence_before for r in rows])
        mean_a = np.mean([r.confidence_after for r in rows])
        lines.append(f"| **total; mean confidence** | {sum(r.frames_changed for r in rows)}/{sum(r.frames for r in rows)} | "
                     f"{sum(r.frames_flagged for r in rows)}/{sum(r.frames for r in rows)} | {mean_b:.3f} | "
                     f"{mean_a:.3f} | | |")
    return "\n".join(lines)


def _write_action(out: Path, stem: str, before, after, report, viz, gif: dict, n_frames: int | None,
                  mp4: bool | None, detect: float) -> list[str]:
    """Every file of one action but its summary figure (drawn once the recogniser has scored it); returns their
    names."""
    marks = viz.read_marks(report, before.n_frames)
    np.save(out / f"{stem}_before.npy", before.joints)
    np.save(out / f"{stem}_after.npy", after.joints)
    (out / f"{stem}_report.json").write_text(json.dumps(report.to_dict(), indent=1) + "\n")
    anim_before, anim_after, anim_marks = before, after, marks
    if n_frames is not None and before.n_frames > n_frames:
        anim_before, anim_after, anim_marks = before.crop(0, n_frames), after.crop(0, n_frames), marks.crop(n_frames)
    animations = viz.animate_change(anim_before, anim_after, anim_marks, path=out / f"{stem}.gif",
                                    labels=("generated", "refined"), mp4=mp4, **gif)
    action = stem.split("_", 1)[1].replace("_", " ")
    marked = marks.flagged | marks.changed(True) | marks.changed(False)
    viz.change_figure(before, after, marks, path=out / f"{stem}_keyframes.png",
                      frames=strip_frames(before.n_frames, np.flatnonzero(marked), 6 if n_frames else 8),
                      labels=("generated", "refined"), title=f"{action}: key frames, generated (faint) under refined")
    # Name each plotted threshold by its quantity: the report's own `threshold` is, for the concepts
    # method, a pose-score threshold (report.threshold_quantity), not this anchor-probability one.
    if report.flaw_probability:  # the motion method: per-frame flaw probability and its threshold
        probability, threshold, label = report.flaw_probability, report.threshold, "flaw probability"
    else:
        probability, threshold, label = report.anchor_probability, detect, "anchor probability"
    probability = np.asarray(probability, dtype=np.float64)
    if probability.size != before.n_frames:  # clips too short to refine carry no per-frame scores
        probability = np.zeros(before.n_frames)
    viz.plot_scores(probability, threshold, anchors=report.anchors, flagged=marks.flagged, changes=marks,
                    path=out / f"{stem}_scores.png", fps=before.fps, label=label,
                    title=f"{action}: {label} per frame (generated clip); crosses: flagged by the detector")
    names = [f"{stem}.gif"] + [p.name for p in animations[1:]]
    names += [f"{stem}_keyframes.png", f"{stem}_scores.png", f"{stem}_before.npy", f"{stem}_after.npy",
              f"{stem}_report.json"]
    return names


def strip_frames(n_frames: int, flagged, n_keyframes: int) -> np.ndarray:
    """Frames a key-frame picture shows: :func:`refiner.io.change_views.key_frames` (``n_keyframes`` evenly spaced
    ones and the middle frame of each of the first ``n_keyframes`` runs of ``flagged`` frames)."""
    from refiner.io.change_views import key_frames  # imports matplotlib: here, so that --help stays cheap

    return key_frames(n_frames, flagged, n_keyframes)


def _existing_outputs(out: Path, stems: Sequence[str]) -> list[str]:
    """Names of files in ``out`` that the demo would write (its summary, or any file of an action's stem)."""
    if not out.is_dir():
        return []
    return sorted(p.name for p in out.iterdir()
                  if p.name in ("summary.md", "summary.json") or any(p.name.startswith(s + ".") or
                                                                     p.name.startswith(s + "_") for s in stems))


def _softmax(logits: np.ndarray) -> np.ndarray:
    z = logits - logits.max(1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(1, keepdims=True)
