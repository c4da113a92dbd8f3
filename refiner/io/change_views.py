"""The still picture of a refinement: key frames of both clips overlaid, seen from the front and the side, the feet
over the ground, and a timeline of what a detector flagged and which step changed which frames.

The scene (before faint, after solid, ground, feet) is :mod:`refiner.io.change_scene`, the report's marks
:mod:`refiner.io.change_marks`; :mod:`refiner.io.change_animation` animates the same views.
"""
from __future__ import annotations

import os
from typing import Sequence

import numpy as np
from matplotlib.cbook import contiguous_regions
from matplotlib.figure import Figure

from refiner.core.skeletons import Skeleton
from refiner.io.change_marks import ChangeMarks, draw_timeline, marks_legend, read_marks
from refiner.io.change_scene import (draw_feet, draw_ground, feet_limits, make_scene, mark_change, pose_artists,
                                     scene_legend, status_text)
from refiner.io.skeleton_drawing import (FLAG, axis_limits, check_frames, check_labels, check_out_path, new_figure,
                                        style_panel)

__all__ = ["change_figure", "key_frames"]

_FEET_WIDTH = 1.5  # the feet column, in key-frame panels


def key_frames(n_frames: int, marked, n_keyframes: int) -> np.ndarray:
    """Frames to show: ``n_keyframes`` evenly spaced ones and the middle frame of each of the first ``n_keyframes``
    runs of ``marked`` frames (indices or a ``(T,)`` bool mask); an even frame within a third of the spacing of a
    middle one is left out, as it would show the same pose. Not every marked frame: a clip may be changed over
    long runs, and a strip of 60 panels shows nothing."""
    marked = np.asarray(marked)
    mask = marked.astype(bool) if marked.dtype == bool else np.isin(np.arange(n_frames), marked.astype(int))
    middles = np.asarray([(a + b - 1) // 2 for a, b in contiguous_regions(mask)][:n_keyframes], int)
    even = np.round(np.linspace(0, n_frames - 1, min(n_keyframes, n_frames))).astype(int)
    if middles.size:
        near = np.abs(even[:, None] - middles[None]).min(1) < (n_frames - 1) / max(len(even) - 1, 1) / 3
        even = even[~near | np.isin(even, middles)]
    return np.union1d(even, middles)


def change_figure(
    before,
    after,
    report=None,
    path: str | os.PathLike | None = None,
    *,
    frames: Sequence[int] | None = None,
    n_keyframes: int = 8,
    skeleton: str | Skeleton = "humanact12",
    labels: Sequence[str] = ("generated", "refined"),
    panel_size: float = 1.6,
    dpi: int = 100,
    title: str | None = None,
) -> Figure:
    """Key frames of ``before`` (faint) under ``after`` (solid), front row and side row, with the ground, a column
    of both feet's paths (from above and from the side, ground contacts as dots) and the report's timeline.

    A key frame's title turns red and says "flagged" only where a detector flagged that frame; its panel frame
    takes the colour of the step that changed it (dashed: a change the step proposed and did not keep).

    Parameters
    ----------
    before, after : Motion or array-like of shape (T, J, 3)
        The clip and its refinement, metres, one skeleton and length.
    report : RefinementReport or dict, optional
        The refinement's report (``to_dict()`` works too); without it, no flags and no changes are drawn.
    path : str or path-like, optional
        Write the figure there as PNG.
    frames : sequence of int, optional
        Key frames; default :func:`key_frames` of the flagged and changed frames.
    n_keyframes : int, default=8
    skeleton : str or Skeleton, default="humanact12"
        Skeleton of array inputs.
    labels : (str, str), default=("generated", "refined")
        Names of ``before`` and ``after`` in the legend.
    panel_size : float, default=1.6
        Key-frame panel edge in inches.
    dpi : int, default=100
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        Axes in order: front key frames, side key frames, feet from above, feet from the side, timeline.

    Raises
    ------
    ValueError
        Clips of different skeletons or lengths, frames out of range, bad labels or path.
    """
    scene = make_scene(before, after, skeleton)
    marks = read_marks(report, scene.n_frames)
    labels = tuple(check_labels(labels, 2))
    out = None if path is None else check_out_path(path, (".png",))
    if not (isinstance(panel_size, (int, float)) and panel_size > 0):
        raise ValueError(f"`panel_size` must be a positive number of inches; got {panel_size!r}.")
    if frames is None:
        if not (isinstance(n_keyframes, (int, np.integer)) and n_keyframes >= 1):
            raise ValueError(f"`n_keyframes` must be a positive int; got {n_keyframes!r}.")
        marked = marks.flagged | marks.changed(True) | marks.changed(False)
        cols = key_frames(scene.n_frames, marked, int(n_keyframes))
    else:
        cols = check_frames(frames, scene.n_frames, name="frames", allow_mask=False)
        if cols.size == 0:
            raise ValueError("`frames` must name at least one frame; got an empty sequence.")

    k, lanes = len(cols), 1 + len(marks.steps)
    timeline = 0.2 * lanes + 0.35  # inches: the lanes and the frame axis
    top = 0.3 if title else 0.05
    head = top + 0.75  # the title, two legend rows and the frame titles
    width = panel_size * (k + _FEET_WIDTH + 0.15) + 1.0
    height = panel_size * 2 + 0.35 + timeline + head
    fig = new_figure(width, height, dpi=dpi)
    grid = fig.add_gridspec(3, k + 2, width_ratios=[1] * k + [0.15, _FEET_WIDTH],
                            height_ratios=[1, 1, (timeline + 0.35) / panel_size], left=0.9 / width,
                            right=1 - 0.1 / width, bottom=0.3 / height, top=1 - head / height, wspace=0.06, hspace=0.12)
    fronts = [fig.add_subplot(grid[0, c]) for c in range(k)]
    sides = [fig.add_subplot(grid[1, c]) for c in range(k)]
    for view, axes in (("front", fronts), ("side", sides)):
        _key_frame_row(axes, scene, marks, cols, view)
        axes[0].set_ylabel(view, fontsize=9)
    for c, t in enumerate(cols):
        is_flagged = bool(marks.flagged[t])
        fronts[c].set_title(f"t={int(t)}" + (" flagged" if is_flagged else ""), fontsize=8,
                            color=FLAG if is_flagged else "black", fontweight="bold" if is_flagged else "normal")
        text, colour = status_text(marks, int(t))
        sides[c].set_xlabel(text, fontsize=7, color=colour or "black", labelpad=2)
    for row, view, name in ((0, "top", "feet, from above"), (1, "side", "feet, from the side")):
        ax = fig.add_subplot(grid[row, k + 1])
        style_panel(ax, view, feet_limits(scene, view, aspect=_FEET_WIDTH))
        draw_ground(ax, scene, view)
        draw_feet(ax, scene, view)
        ax.text(0.03, 0.97, name, transform=ax.transAxes, ha="left", va="top", fontsize=7)
    ax = fig.add_subplot(grid[2, :k])
    draw_timeline(ax, marks, keyframes=cols)
    ax.set_xlabel("frame (dotted: the key frames above)", fontsize=7, labelpad=1)
    if title:
        fig.suptitle(title, y=1 - 0.05 / height, va="top", fontsize=10)
    handles = scene_legend(labels) + marks_legend(marks)
    fig.legend(handles=handles, loc="center", bbox_to_anchor=(0.5, 1 - (top + 0.22) / height),
               ncol=int(np.ceil(len(handles) / 2)), fontsize=7, frameon=False, handlelength=1.8, columnspacing=1.2)
    if out is not None:
        fig.savefig(out, dpi=dpi, facecolor="white")
    return fig


def _key_frame_row(axes, scene, marks: ChangeMarks, cols, view: str) -> None:
    """One row of key-frame panels: the ground, both poses overlaid, the panel frame by the change there."""
    limits = axis_limits([scene.before.joints, scene.after.joints], [scene.skel] * 2, view)
    for ax, t in zip(axes, cols):
        style_panel(ax, view, limits)
        draw_ground(ax, scene, view)
        ghost, solid = pose_artists(ax, scene, view)
        ghost.draw(scene.before.joints[t])
        solid.draw(scene.after.joints[t])
        mark_change(ax, marks, int(t))

