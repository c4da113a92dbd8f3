"""One clip's refinement in figures: jerk, foot skating, bone-length variation and cm moved, before and after.

The numbers are the project's metrics as ``motion-refiner bench noharm`` takes them: :func:`~refiner.evaluation.
physics.jerk`, :func:`~refiner.evaluation.ground_metrics.foot_skating_ratio` (both clips on the *before* clip's
ground), :func:`~refiner.evaluation.physics.bone_length_variation` and :func:`~refiner.evaluation.metrics.mpjpe`
of after against before (all frames, and the frames where a joint moved more than the bench's ``CHANGED_M``).
"""
from __future__ import annotations

import os
from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

from refiner.core.skeletons import Skeleton
from refiner.evaluation.bench_noharm import CHANGED_M
from refiner.evaluation.ground_metrics import foot_skating_ratio, ground_height
from refiner.evaluation.metrics import mpjpe
from refiner.evaluation.physics import bone_length_variation, jerk
from refiner.io.change_marks import read_marks
from refiner.io.change_scene import GHOST_ALPHA, make_scene
from refiner.io.skeleton_drawing import CENTRE, check_labels, check_out_path, new_figure

__all__ = ["clip_figures", "summary_figure", "SUMMARY_PANELS"]

#: The summary's panels: (key, title). A "before"/"after" pair each, but "cm_moved": (all frames, changed frames).
SUMMARY_PANELS = (("jerk", "jerk (m/s³)"), ("foot_skating", "foot skating\n(share of frame pairs)"),
                  ("bone_variation_pct", "bone-length variation (%)"), ("cm_moved", "moved (cm per joint)"))

_FLOORS = {"foot_skating": 0.1, "bone_variation_pct": 1.0, "cm_moved": 0.5, "confidence": 1.0}  # least y range: a
# near-zero value stays a near-zero bar, not one blown up to the panel's height


def clip_figures(before, after, *, skeleton: str | Skeleton = "humanact12") -> dict:
    """The summary's numbers for ``before`` and ``after`` (Motions or ``(T, J, 3)`` arrays, metres, one skeleton
    and length).

    Returns
    -------
    dict
        ``jerk``, ``foot_skating``, ``bone_variation_pct``: ``(before, after)`` pairs in m/s³, a share in [0, 1]
        and percent; ``cm_moved``: ``(all frames, changed frames)`` in cm (0 when no frame moved);
        ``frames_moved``: how many frames moved.
    """
    return _numbers(make_scene(before, after, skeleton))


def _numbers(scene) -> dict:
    """:func:`clip_figures` of a :class:`~refiner.io.change_scene.Scene`."""
    b, a = scene.before, scene.after
    ground = ground_height(b)
    moved = np.linalg.norm(a.joints.astype(np.float64) - b.joints, axis=-1).max(-1) > CHANGED_M  # (T,)
    return {
        "jerk": (float(jerk(b)), float(jerk(a))),
        "foot_skating": (float(foot_skating_ratio(b, ground=ground)), float(foot_skating_ratio(a, ground=ground))),
        "bone_variation_pct": (100 * float(bone_length_variation(b)), 100 * float(bone_length_variation(a))),
        "cm_moved": (100 * mpjpe(a, b), 100 * mpjpe(a, b, mask=moved) if moved.any() else 0.0),
        "frames_moved": int(moved.sum()),
    }


def summary_figure(
    before,
    after,
    report=None,
    path: str | os.PathLike | None = None,
    *,
    skeleton: str | Skeleton = "humanact12",
    labels: Sequence[str] = ("generated", "refined"),
    confidence: tuple[float, float] | None = None,
    title: str | None = None,
    dpi: int = 100,
) -> Figure:
    """Bars of :func:`clip_figures`, before (faint) and after (solid), one panel each, with a line of what the
    report flagged and changed.

    Parameters
    ----------
    before, after : Motion or array-like of shape (T, J, 3)
    report : RefinementReport or dict, optional
        Counted in the subtitle: frames flagged, changed per step, and changes not kept.
    path : str or path-like, optional
        Write the figure there as PNG.
    skeleton : str or Skeleton, default="humanact12"
    labels : (str, str), default=("generated", "refined")
    confidence : (float, float), optional
        A recogniser's probability of the clip's action before and after, drawn as a fifth panel.
    title : str, optional
    dpi : int, default=100

    Returns
    -------
    matplotlib.figure.Figure
        One axes per panel of :data:`SUMMARY_PANELS` (and the confidence's), bars in the order drawn.
    """
    scene = make_scene(before, after, skeleton)
    numbers = _numbers(scene)
    labels = tuple(check_labels(labels, 2))
    out = None if path is None else check_out_path(path, (".png",))
    panels = list(SUMMARY_PANELS)
    if confidence is not None:
        numbers["confidence"] = tuple(float(c) for c in confidence)
        panels.append(("confidence", "recogniser confidence\n(the action's probability)"))
    fig = new_figure(1.75 * len(panels) + 0.3, 2.9, dpi=dpi)
    for i, (key, name) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1)
        values = numbers[key]
        if key == "cm_moved":
            ticks, alphas = ("all frames", f"{numbers['frames_moved']} moved\nframes"), (1.0, 1.0)
        else:
            ticks, alphas = labels, (GHOST_ALPHA, 1.0)
        bars = ax.bar([0, 1], values, color=CENTRE, width=0.6)
        for bar, alpha, value in zip(bars, alphas, values):
            bar.set_alpha(alpha)
            ax.annotate(f"{value:.3g}", (bar.get_x() + bar.get_width() / 2, value), ha="center", va="bottom",
                        fontsize=7, xytext=(0, 2), textcoords="offset points")
        ax.set_xticks([0, 1], ticks, fontsize=7)
        ax.set_title(name, fontsize=8)
        ax.set_ylim(0, max(max(values) * 1.25, _FLOORS.get(key, 1e-9)))
        ax.tick_params(axis="y", labelsize=7)
        ax.spines[["top", "right"]].set_visible(False)
    fig.suptitle("\n".join(filter(None, [title, _marks_line(report, scene.n_frames)])), fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.9 if title else 0.93))
    if out is not None:
        fig.savefig(out, dpi=dpi, facecolor="white")
    return fig


def _marks_line(report, n_frames: int) -> str:
    """``"flagged 4 of 60 frames; changed 10 (infill 10); not kept: infill 8"`` from the report."""
    if report is None:
        return ""
    marks = read_marks(report, n_frames)
    line = f"flagged {int(marks.flagged.sum())} of {marks.n_frames} frames; changed {int(marks.changed(True).sum())}"
    by_step = {}
    for kept in (True, False):
        for c in marks.changes:
            if c.kept == kept:
                key = (c.step, kept)
                by_step[key] = by_step.get(key, 0) + c.stop - c.start
    kept = [f"{s} {n}" for (s, k), n in by_step.items() if k]
    dropped = [f"{s} {n}" for (s, k), n in by_step.items() if not k]
    return line + (f" ({', '.join(kept)})" if kept else "") + (f"; not kept: {', '.join(dropped)}" if dropped else "")
