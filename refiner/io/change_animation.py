"""The animation of a refinement: both clips in one view (before faint, after solid), front and side, with the ground,
the feet's paths and a timeline of the report's flags and changes under a moving cursor.

The still picture of the same views is :mod:`refiner.io.change_views`; ``motion-refiner demo`` and
``motion-refiner refine --gif`` draw both from the report.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from refiner.core.skeletons import Skeleton
from refiner.io.animations import check_fps, output_targets, write_frames
from refiner.io.change_marks import draw_timeline, read_marks
from refiner.io.change_scene import draw_feet, draw_ground, make_scene, mark_change, pose_artists, status_text
from refiner.io.skeleton_drawing import FLAG, axis_limits, check_labels, new_figure, style_panel

__all__ = ["animate_change"]

_BAND = 0.2  # inches: the caption band above the panels and the timeline band below them


def animate_change(
    before,
    after,
    report=None,
    path: str | os.PathLike = "motion.gif",
    fps: float | None = None,
    *,
    skeleton: str | Skeleton = "humanact12",
    labels: Sequence[str] = ("input", "refined"),
    mp4: bool | None = None,
    panel_size: float = 3.0,
    dpi: int = 80,
    progress: bool = False,
) -> list[Path]:
    """Animate ``after`` over ``before`` (faint) from the front and the side, as GIF (and MP4 when ffmpeg exists).

    Each panel shows the ground, both feet's paths over the clip (ground contacts as dots) and both poses of the
    frame; its frame takes the colour of the step that changed that frame (dashed: a change not kept). The caption
    names the frame's changes and says "flagged" (red) only where a detector flagged it; the timeline below shows
    the whole clip's flags and changes (:func:`~refiner.io.change_marks.draw_timeline`) under a cursor.

    Parameters
    ----------
    before, after : Motion or array-like of shape (T, J, 3)
        The clip and its refinement, metres, one skeleton and length.
    report : RefinementReport or dict, optional
        The refinement's report; without it, no flags and no changes are drawn.
    path : str or path-like, default="motion.gif"
        ``*.gif`` (written with Pillow) or ``*.mp4`` (needs ffmpeg).
    fps : float, optional
        Playback rate; ``before``'s by default (the skeleton's for arrays).
    skeleton : str or Skeleton, default="humanact12"
        Skeleton of array inputs.
    labels : (str, str), default=("input", "refined")
        Names of ``before`` and ``after`` in the caption.
    panel_size : float, default=3.0
        Panel edge in inches; the image is ``2 * panel_size`` by ``panel_size + 0.4`` inches.
    mp4, dpi, progress
        As for :func:`~refiner.io.animations.animate`: by default an MP4 beside a GIF when ffmpeg is on PATH,
        80 dots per inch, no progress bar.

    Returns
    -------
    list of Path, the GIF first

    Raises
    ------
    ValueError
        Clips of different skeletons or lengths, bad labels, fps, suffix, or MP4 requested without ffmpeg.
    """
    scene = make_scene(before, after, skeleton)
    marks = read_marks(report, scene.n_frames)
    labels = tuple(check_labels(labels, 2))
    fps = check_fps(scene.before.fps if fps is None else fps)
    if not (isinstance(panel_size, (int, float)) and panel_size > 0):
        raise ValueError(f"`panel_size` must be a positive number of inches; got {panel_size!r}.")
    targets = output_targets(path, mp4)

    height = panel_size + 2 * _BAND
    fig = new_figure(2 * panel_size, height, dpi=dpi)
    scale = panel_size / 1.6  # lines and dots as on a 1.6-inch still panel
    panels, artists = [], []
    for i, view in enumerate(("front", "side")):
        ax = fig.add_axes((i / 2 + 0.005, _BAND / height, 0.49, panel_size / height))
        style_panel(ax, view, axis_limits([scene.before.joints, scene.after.joints], [scene.skel] * 2, view))
        draw_ground(ax, scene, view)
        draw_feet(ax, scene, view, size=min(scale, 1.5))
        ax.text(0.03, 0.97, view, transform=ax.transAxes, ha="left", va="top", fontsize=7, color="#606060")
        panels.append(ax)
        artists.append(pose_artists(ax, scene, view, linewidth=2.5 * min(scale, 1.5)))
    caption = 1 - _BAND / 2 / height
    fig.text(0.01, caption, f"{labels[0]} faint, {labels[1]} solid", ha="left", va="center", fontsize=7)
    counter = fig.text(0.99, caption, "", ha="right", va="center", fontsize=7)
    status = panels[0].text(0.97, 0.97, "", transform=panels[0].transAxes, ha="right", va="top", fontsize=7)
    timeline = fig.add_axes((0.01, 0.02 / height, 0.98, (_BAND - 0.05) / height))
    cursor = draw_timeline(timeline, marks, labels=False)
    timeline.set_xticks([])

    def draw(t: int) -> None:
        for ax, (ghost, solid) in zip(panels, artists):
            ghost.draw(scene.before.joints[t])
            solid.draw(scene.after.joints[t])
            mark_change(ax, marks, t, width=2.0 * min(scale, 1.5))
        flagged = bool(marks.flagged[t])
        counter.set_text(f"frame {t + 1}/{scene.n_frames}" + ("  flagged" if flagged else ""))
        counter.set_color(FLAG if flagged else "black")
        text, colour = status_text(marks, t)
        status.set_text(text)
        status.set_color(colour or "black")
        cursor.set_xdata([t, t])
        cursor.set_visible(True)

    write_frames(fig, targets, draw, scene.n_frames, fps=fps, dpi=dpi, progress=progress)
    return targets
