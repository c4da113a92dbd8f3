"""Pictures of motions: single poses, key-frame strips and per-frame score plots (PNG or arrays).

Views, colours and limits are those of :mod:`refiner.io.skeleton_drawing`; animations are
:mod:`refiner.io.animations`.
"""
from __future__ import annotations

import os
from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

from refiner.core.skeletons import Skeleton, get_skeleton
from refiner.core.validation import to_numpy
from refiner.io.change_marks import NOT_KEPT_HATCH, ChangeMarks
from refiner.io.skeleton_drawing import (
    CENTRE,
    FLAG,
    LEFT,
    PoseArtist,
    as_rows,
    axis_limits,
    check_axes,
    check_frames,
    check_labels,
    check_out_path,
    check_pose,
    check_view,
    colour_legend,
    new_figure,
    style_panel,
)

__all__ = ["draw_pose", "render_pose_image", "keyframe_strip", "plot_scores"]

_LEGEND_INCHES = 0.3  # height of the key-frame strip's colour legend


def draw_pose(
    ax,
    joints,
    skeleton: str | Skeleton = "humanact12",
    *,
    color=None,
    highlight: bool = False,
    view: str = "front",
    linewidth: float = 2.5,
):
    """Draw one pose as bones (lines from each joint to its parent).

    Parameters
    ----------
    ax : matplotlib Axes
        A 2-D axes for ``view="front"`` or ``"side"``, a 3-D axes (``projection="3d"``) for ``"3d"``.
        Limits are left to the caller (the axes autoscales as usual).
    joints : array-like of shape (J, 3)
        Joint positions in metres, in the skeleton's frame.
    skeleton : str or Skeleton, default="humanact12"
    color : matplotlib colour, optional
        One colour for every bone; by default bones are coloured by body side.
    highlight : bool, default=False
        Draw the bones red and thicker (a flagged frame).
    view : {"front", "side", "3d"}, default="front"
    linewidth : float, default=2.5
        In points.

    Returns
    -------
    LineCollection or Line3DCollection
        The bones, one segment per ``skeleton.bones`` row; update them with ``set_segments``.

    Raises
    ------
    ValueError
        Wrong shape for the skeleton, NaN or Inf, unknown view, or a 2-D axes with ``view="3d"``
        (or the reverse).
    """
    skel = get_skeleton(skeleton)
    pose = check_pose(joints, skel)
    check_view(view)
    check_axes(ax, view)
    return PoseArtist(ax, skel, view, color=color, linewidth=linewidth).draw(pose, highlight=highlight)


def render_pose_image(
    joints,
    skeleton: str | Skeleton = "humanact12",
    size: tuple[int, int] = (256, 256),
    *,
    view: str = "front",
    color=None,
    linewidth: float = 3.0,
) -> np.ndarray:
    """Render one pose to an RGB image on a white background.

    Parameters
    ----------
    joints : array-like of shape (J, 3)
        Joint positions in metres, in the skeleton's frame.
    skeleton : str or Skeleton, default="humanact12"
    size : (int, int), default=(256, 256)
        Image height and width in pixels, each 16..4096.
    view : {"front", "side", "3d"}, default="front"
    color : matplotlib colour, optional
        One colour for every bone; by default bones are coloured by body side.
    linewidth : float, default=3.0
        In pixels.

    Returns
    -------
    ndarray of shape (H, W, 3), uint8
        The pose centred in the image and scaled to fill it (equal scaling on both axes).

    Raises
    ------
    ValueError
        Wrong joint shape, NaN or Inf, bad size or unknown view.
    """
    skel = get_skeleton(skeleton)
    pose = check_pose(joints, skel)
    check_view(view)
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or not all(isinstance(s, (int, np.integer)) and 16 <= s <= 4096 for s in size)
    ):
        raise ValueError(f"`size` must be (height, width) in pixels, each 16..4096; got {size!r}.")
    height, width = int(size[0]), int(size[1])
    dpi = 100
    fig = new_figure(width / dpi, height / dpi, dpi=dpi)
    ax = fig.add_axes((0, 0, 1, 1), projection="3d" if view == "3d" else None)
    # Points are 1/72 inch: convert so `linewidth` means pixels at this dpi.
    artist = PoseArtist(ax, skel, view, color=color, linewidth=linewidth * 72 / dpi)
    style_panel(ax, view, axis_limits([pose], [skel], view, aspect=width / height))
    ax.set_axis_off()
    artist.draw(pose)
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    if image.shape[:2] != (height, width):  # rounding of the figure size; keep the promised shape
        image = _resize_nearest(image, height, width)
    return image


def keyframe_strip(
    motions_or_rows,
    frames: Sequence[int] | None = None,
    flagged=None,
    path: str | os.PathLike | None = None,
    *,
    skeleton: str | Skeleton = "humanact12",
    n_keyframes: int = 8,
    labels: Sequence[str] | None = None,
    view: str = "front",
    panel_size: float = 1.6,
    dpi: int = 100,
    title: str | None = None,
) -> Figure:
    """A grid of key frames: one row per motion (e.g. before / after refinement), one column per frame.

    Parameters
    ----------
    motions_or_rows : Motion, array-like of shape (T, J, 3) or (R, T, J, 3), or a sequence of them
        The rows. Arrays are read as ``skeleton`` motions; rows may differ in length and skeleton.
    frames : sequence of int, optional
        Frame indices to show, each valid in every row. By default ``n_keyframes`` evenly spaced
        frames of the shortest row plus every flagged frame.
    flagged : sequence of int or bool array of shape (T,), optional
        Flagged (e.g. bad-anchor) frames: their panels get a red frame in every row and red bones
        in the first row, the motion the flags were computed on.
    path : str or path-like, optional
        Write the figure there as PNG.
    skeleton : str or Skeleton, default="humanact12"
        Skeleton of array inputs.
    n_keyframes : int, default=8
    labels : sequence of str, optional
        Row labels; ``("before", "after")`` by default for two rows.
    view : {"front", "side", "3d"}, default="front"
    panel_size : float, default=1.6
        Panel edge in inches.
    dpi : int, default=100
    title : str, optional
        Figure title (e.g. the action). A colour legend (left / right / centre bones, flagged) is
        drawn below the title in any case.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        Bad motions, frame indices out of range, a flag mask of the wrong length, bad labels.
    """
    rows = as_rows(motions_or_rows, skeleton)
    check_view(view)
    out = None if path is None else check_out_path(path, (".png",))
    n_min = min(m.n_frames for m in rows)
    flags = check_frames(flagged, n_min, name="flagged", allow_mask=True)
    if frames is None:
        if not (isinstance(n_keyframes, (int, np.integer)) and n_keyframes >= 1):
            raise ValueError(f"`n_keyframes` must be a positive int; got {n_keyframes!r}.")
        even = np.round(np.linspace(0, n_min - 1, min(int(n_keyframes), n_min))).astype(int)
        cols = np.union1d(even, flags)
    else:
        cols = check_frames(frames, n_min, name="frames", allow_mask=False, unique=False)
        if cols.size == 0:
            raise ValueError("`frames` must name at least one frame; got an empty sequence.")
    labels = check_labels(labels, len(rows))
    if not (isinstance(panel_size, (int, float)) and panel_size > 0):
        raise ValueError(f"`panel_size` must be a positive number of inches; got {panel_size!r}.")

    skels = [m.skeleton_info for m in rows]
    head = 0.3 + _LEGEND_INCHES + (0.3 if title else 0.0)  # frame titles, the colour legend, the title
    fig = new_figure(panel_size * len(cols) + 0.4, panel_size * len(rows) + head, dpi=dpi)
    limits = axis_limits([m.joints for m in rows], skels, view)
    flag_set = set(flags.tolist())
    for r, (motion, skel) in enumerate(zip(rows, skels)):
        for c, t in enumerate(cols):
            ax = fig.add_subplot(len(rows), len(cols), r * len(cols) + c + 1, projection="3d" if view == "3d" else None)
            style_panel(ax, view, limits, flagged=int(t) in flag_set)
            PoseArtist(ax, skel, view).draw(motion.joints[t], highlight=r == 0 and int(t) in flag_set)
            if r == 0:
                ax.set_title(f"t={int(t)}" + (" (flagged)" if int(t) in flag_set else ""), fontsize=8,
                             color=FLAG if int(t) in flag_set else "black")
            if c == 0 and labels is not None:
                if view == "3d":
                    ax.text2D(-0.08, 0.5, labels[r], transform=ax.transAxes, rotation=90, ha="right", va="center")
                else:
                    ax.set_ylabel(labels[r], fontsize=9)
    fig.subplots_adjust(left=0.3 / fig.get_figwidth() + 0.01, right=0.99, bottom=0.01,
                        top=1 - head / fig.get_figheight(),
                        wspace=0.05, hspace=0.05)
    if title:
        fig.suptitle(title, y=1 - 0.05 / fig.get_figheight(), va="top", fontsize=10)
    colour_legend(fig, y=1 - (head - _LEGEND_INCHES / 2 - 0.3) / fig.get_figheight())
    if out is not None:
        fig.savefig(out, dpi=dpi, facecolor="white")
    return fig


def plot_scores(
    scores,
    threshold: float,
    anchors=None,
    flagged=None,
    path: str | os.PathLike | None = None,
    *,
    fps: float | None = None,
    label: str = "anchor score",
    title: str | None = None,
    changes: ChangeMarks | None = None,
) -> Figure:
    """Plot per-frame anchor scores with the flagging threshold.

    Parameters
    ----------
    scores : array-like of shape (T,)
        One finite score per frame.
    threshold : float
        Drawn as a dashed horizontal line.
    anchors : sequence of int, optional
        Anchor frames, marked with dots on the score curve.
    flagged : sequence of int or bool array of shape (T,), optional
        Flagged frames, marked with red crosses and a red band.
    path : str or path-like, optional
        Write the figure there as PNG.
    fps : float, optional
        When given, the x axis is in seconds instead of frames.
    label : str, default="anchor score"
        The quantity plotted: the y-axis label, the curve's legend entry and the threshold line's
        (``"<label> threshold = ..."``), so thresholds of different quantities are not confused.
    title : str, optional
        Axes title (e.g. the action).
    changes : ChangeMarks, optional
        A report's changes (:func:`~refiner.io.change_marks.read_marks`), shaded in their step's colour (hatched:
        not kept); its ``flagged`` frames are not drawn, pass them as ``flagged``.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        ``scores`` not 1-D, empty or not finite; non-finite threshold; frame indices out of range; ``changes`` of
        another length.
    """
    s = to_numpy(scores, name="scores").astype(np.float64)
    if s.ndim != 1 or s.size == 0:
        raise ValueError(f"`scores` must have shape (T,) with T >= 1; got {tuple(s.shape)}.")
    if not np.isfinite(s).all():
        bad = np.flatnonzero(~np.isfinite(s))
        raise ValueError(f"`scores` contains {bad.size} NaN or Inf values (first at frame {bad[0]}).")
    is_number = isinstance(threshold, (int, float, np.number)) and not isinstance(threshold, (bool, np.bool_))
    if not (is_number and np.isfinite(threshold)):
        raise ValueError(f"`threshold` must be a finite number; got {threshold!r}.")
    anchor_idx = check_frames(anchors, s.size, name="anchors", allow_mask=False)
    flag_idx = check_frames(flagged, s.size, name="flagged", allow_mask=True)
    if fps is not None and not (isinstance(fps, (int, float, np.number)) and np.isfinite(fps) and fps > 0):
        raise ValueError(f"`fps` must be a positive number; got {fps!r}.")
    if changes is not None and changes.n_frames != s.size:
        raise ValueError(f"`changes` must be of the T={s.size} scored frames; got {changes.n_frames}.")
    out = None if path is None else check_out_path(path, (".png",))
    x = np.arange(s.size) / (fps or 1.0)

    fig = new_figure(7.0, 2.8, dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(x, s, color=CENTRE, lw=1.2, label=label)
    ax.axhline(float(threshold), color=FLAG, ls="--", lw=1.2, label=f"{label} threshold = {float(threshold):.3g}")
    if anchor_idx.size:
        ax.plot(x[anchor_idx], s[anchor_idx], "o", color=LEFT, ms=5, label="anchors")
    half = 0.5 / (fps or 1.0)
    for c in [] if changes is None else changes.changes:
        colour, kept = changes.colour(c.step), c.kept
        ax.axvspan(x[c.start] - half, x[c.stop - 1] + half, facecolor=colour if kept else "none",
                   alpha=0.2 if kept else 0.8, edgecolor=colour, hatch=None if kept else NOT_KEPT_HATCH, lw=0, zorder=0,
                   label=f"{c.step}: {'changed' if kept else 'not kept'}")
    if flag_idx.size:
        for f in flag_idx:
            ax.axvspan(x[f] - half, x[f] + half, color=FLAG, alpha=0.15, lw=0)
        ax.plot(x[flag_idx], s[flag_idx], "x", color=FLAG, ms=8, mew=2, label="flagged")
    ax.set_xlabel("time (s)" if fps else "frame")
    ax.set_ylabel(label)
    if title:
        ax.set_title(title, fontsize=10)
    ax.set_xlim(x[0] - 0.5 / (fps or 1.0), x[-1] + 0.5 / (fps or 1.0))
    ax.grid(alpha=0.3)
    handles, names = ax.get_legend_handles_labels()
    unique = dict(zip(names, handles))  # one entry per step and kind, however many runs
    ax.legend(unique.values(), unique.keys(), loc="best", fontsize=8, framealpha=0.8)
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=100, facecolor="white")
    return fig


def _resize_nearest(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """``image`` resampled to ``height`` x ``width`` pixels by nearest neighbour."""
    rows = np.minimum((np.arange(height) * image.shape[0] / height).astype(int), image.shape[0] - 1)
    cols = np.minimum((np.arange(width) * image.shape[1] / width).astype(int), image.shape[1] - 1)
    return image[rows][:, cols]
