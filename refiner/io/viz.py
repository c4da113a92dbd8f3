"""Skeleton pictures of motions: single poses, key-frame strips, before/after animations and anchor-score plots.

Everything is drawn on explicit :class:`matplotlib.figure.Figure` objects with the Agg canvas, so
no pyplot state is touched and no display is needed.

Views (``view=``), all orthographic and computed from the skeleton's own ``up`` and ``forward``
(so y-down HumanAct12 / UESTC data and y-up HumanML3D / CMU data both stand upright):

- ``"front"``: the subject faces the viewer; screen right is ``up x forward`` (the subject's
  left, e.g. +x for HumanAct12), screen up is the skeleton's up.
- ``"side"``: the subject faces screen right.
- ``"3d"``: a perspective-free 3-D axes seen slightly from above and the front.

Bones are coloured by side (left blue, right green, centre grey); bones of flagged frames are red
and their panels get a red frame. Axis limits come from the whole motion (all rows together), with
equal scaling, so bodies never jump or stretch between frames.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton
from refiner.core.validation import check_joints, to_numpy

__all__ = [
    "VIEWS",
    "draw_pose",
    "render_pose_image",
    "keyframe_strip",
    "animate",
    "plot_scores",
]

#: Accepted values of ``view``.
VIEWS = ("front", "side", "3d")

_LEFT, _RIGHT, _CENTRE, _FLAG = "#1f77b4", "#2ca02c", "#404040", "#d62728"
_MARGIN = 0.08  # fraction of the body's extent left free around it
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
    pose = _check_pose(joints, skel)
    _check_view(view)
    _check_axes(ax, view)
    return _PoseArtist(ax, skel, view, color=color, linewidth=linewidth).draw(pose, highlight=highlight)


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
    pose = _check_pose(joints, skel)
    _check_view(view)
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or not all(isinstance(s, (int, np.integer)) and 16 <= s <= 4096 for s in size)
    ):
        raise ValueError(f"`size` must be (height, width) in pixels, each 16..4096; got {size!r}.")
    height, width = int(size[0]), int(size[1])
    dpi = 100
    fig = _figure(width / dpi, height / dpi, dpi=dpi)
    ax = fig.add_axes((0, 0, 1, 1), projection="3d" if view == "3d" else None)
    # Points are 1/72 inch: convert so `linewidth` means pixels at this dpi.
    artist = _PoseArtist(ax, skel, view, color=color, linewidth=linewidth * 72 / dpi)
    _style_panel(ax, view, _limits([pose], [skel], view, aspect=width / height))
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
    rows = _as_rows(motions_or_rows, skeleton)
    _check_view(view)
    out = None if path is None else _out_path(path, (".png",))
    n_min = min(m.n_frames for m in rows)
    flags = _check_frames(flagged, n_min, name="flagged", allow_mask=True)
    if frames is None:
        if not (isinstance(n_keyframes, (int, np.integer)) and n_keyframes >= 1):
            raise ValueError(f"`n_keyframes` must be a positive int; got {n_keyframes!r}.")
        even = np.round(np.linspace(0, n_min - 1, min(int(n_keyframes), n_min))).astype(int)
        cols = np.union1d(even, flags)
    else:
        cols = _check_frames(frames, n_min, name="frames", allow_mask=False, unique=False)
        if cols.size == 0:
            raise ValueError("`frames` must name at least one frame; got an empty sequence.")
    labels = _check_labels(labels, len(rows))
    if not (isinstance(panel_size, (int, float)) and panel_size > 0):
        raise ValueError(f"`panel_size` must be a positive number of inches; got {panel_size!r}.")

    skels = [m.skeleton_info for m in rows]
    head = 0.3 + _LEGEND_INCHES + (0.3 if title else 0.0)  # frame titles, the colour legend, the title
    fig = _figure(panel_size * len(cols) + 0.4, panel_size * len(rows) + head, dpi=dpi)
    limits = _limits([m.joints for m in rows], skels, view)
    flag_set = set(flags.tolist())
    for r, (motion, skel) in enumerate(zip(rows, skels)):
        for c, t in enumerate(cols):
            ax = fig.add_subplot(len(rows), len(cols), r * len(cols) + c + 1, projection="3d" if view == "3d" else None)
            _style_panel(ax, view, limits, flagged=int(t) in flag_set)
            _PoseArtist(ax, skel, view).draw(motion.joints[t], highlight=r == 0 and int(t) in flag_set)
            if r == 0:
                ax.set_title(f"t={int(t)}" + (" (flagged)" if int(t) in flag_set else ""), fontsize=8,
                             color=_FLAG if int(t) in flag_set else "black")
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
    _colour_legend(fig, y=1 - (head - _LEGEND_INCHES / 2 - 0.3) / fig.get_figheight())
    if out is not None:
        fig.savefig(out, dpi=dpi, facecolor="white")
    return fig


def animate(
    before,
    after=None,
    flagged=None,
    path: str | os.PathLike = "motion.gif",
    fps: float | None = None,
    *,
    skeleton: str | Skeleton = "humanact12",
    labels: Sequence[str] | None = None,
    view: str = "front",
    mp4: bool | None = None,
    panel_size: float = 3.0,
    dpi: int = 80,
    progress: bool = False,
) -> list[Path]:
    """Animate a motion, or a before / after pair side by side, as GIF (and MP4 when ffmpeg exists).

    Parameters
    ----------
    before : Motion or array-like of shape (T, J, 3)
    after : Motion or array-like of shape (T', J', 3), optional
        Shown to the right of ``before``. A shorter motion holds its last frame.
    flagged : sequence of int or bool array of shape (T,), optional
        Frames of ``before`` to highlight: red frame around both panels, red bones in ``before``
        and a "flagged" note in the frame counter.
    path : str or path-like, default="motion.gif"
        ``*.gif`` (written with Pillow) or ``*.mp4`` (needs ffmpeg).
    fps : float, optional
        Playback rate; ``before.fps`` by default.
    skeleton : str or Skeleton, default="humanact12"
        Skeleton of array inputs.
    labels : sequence of str, optional
        Panel titles; ``("before", "after")`` by default for a pair.
    view : {"front", "side", "3d"}, default="front"
    mp4 : bool, optional
        For a ``.gif`` path, also write an MP4 beside it: None (default) does so when ``ffmpeg``
        is on PATH, True requires it, False never.
    panel_size : float, default=3.0
        Panel edge in inches.
    dpi : int, default=80
    progress : bool, default=False
        Show a progress bar over the frames drawn (stderr).

    Returns
    -------
    list of Path
        The files written, the GIF first.

    Raises
    ------
    ValueError
        Bad motions, bad flags, a suffix other than .gif / .mp4, or MP4 requested without ffmpeg.
    """
    rows = _as_rows([before] if after is None else [before, after], skeleton)
    _check_view(view)
    n_frames = max(m.n_frames for m in rows)
    flags = set(_check_frames(flagged, rows[0].n_frames, name="flagged", allow_mask=True).tolist())
    labels = _check_labels(labels, len(rows))
    fps = rows[0].fps if fps is None else fps
    if not (isinstance(fps, (int, float, np.number)) and np.isfinite(fps) and 0 < fps <= 100):
        raise ValueError(f"`fps` must be a number in (0, 100]; got {fps!r}.")
    out = _out_path(path, (".gif", ".mp4"))
    ffmpeg = shutil.which("ffmpeg") is not None
    targets = [out]
    if out.suffix.lower() == ".gif" and (mp4 or (mp4 is None and ffmpeg)):
        targets.append(out.with_suffix(".mp4"))
    if any(t.suffix.lower() == ".mp4" for t in targets) and not ffmpeg:
        raise ValueError("MP4 output needs `ffmpeg` on PATH; install it or write a .gif with mp4=False.")

    from matplotlib.animation import FFMpegWriter, PillowWriter

    skels = [m.skeleton_info for m in rows]
    fig = _figure(panel_size * len(rows), panel_size + 0.4, dpi=dpi)
    limits = _limits([m.joints for m in rows], skels, view)
    axes, artists = [], []
    for i, skel in enumerate(skels):
        ax = fig.add_subplot(1, len(rows), i + 1, projection="3d" if view == "3d" else None)
        _style_panel(ax, view, limits)
        if labels is not None:
            ax.set_title(labels[i], fontsize=10)
        axes.append(ax)
        artists.append(_PoseArtist(ax, skel, view))
    counter = fig.text(0.5, 0.02, "", ha="center", va="bottom", fontsize=9)
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.1, top=0.9, wspace=0.05)

    writers = [PillowWriter(fps=fps) if t.suffix.lower() == ".gif" else FFMpegWriter(fps=fps) for t in targets]
    for writer, target in zip(writers, targets):
        writer.setup(fig, str(target), dpi=dpi)
    from tqdm.auto import tqdm

    try:
        for t in tqdm(range(n_frames), desc=f"drawing {out.name}", unit="frame", disable=not progress):
            is_flagged = t in flags
            for r, (motion, artist, ax) in enumerate(zip(rows, artists, axes)):
                artist.draw(motion.joints[min(t, motion.n_frames - 1)], highlight=is_flagged and r == 0)
                _set_frame(ax, view, is_flagged)
            counter.set_text(f"frame {t + 1}/{n_frames}" + ("   flagged" if is_flagged else ""))
            counter.set_color(_FLAG if is_flagged else "black")
            for writer in writers:
                writer.grab_frame(facecolor="white")
    finally:
        for writer in writers:
            writer.finish()
    return targets


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

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        ``scores`` not 1-D, empty or not finite; non-finite threshold; frame indices out of range.
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
    anchor_idx = _check_frames(anchors, s.size, name="anchors", allow_mask=False)
    flag_idx = _check_frames(flagged, s.size, name="flagged", allow_mask=True)
    if fps is not None and not (isinstance(fps, (int, float, np.number)) and np.isfinite(fps) and fps > 0):
        raise ValueError(f"`fps` must be a positive number; got {fps!r}.")
    out = None if path is None else _out_path(path, (".png",))
    x = np.arange(s.size) / (fps or 1.0)

    fig = _figure(7.0, 2.8, dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(x, s, color=_CENTRE, lw=1.2, label=label)
    ax.axhline(float(threshold), color=_FLAG, ls="--", lw=1.2, label=f"{label} threshold = {float(threshold):.3g}")
    if anchor_idx.size:
        ax.plot(x[anchor_idx], s[anchor_idx], "o", color=_LEFT, ms=5, label="anchors")
    if flag_idx.size:
        half = 0.5 / (fps or 1.0)
        for f in flag_idx:
            ax.axvspan(x[f] - half, x[f] + half, color=_FLAG, alpha=0.15, lw=0)
        ax.plot(x[flag_idx], s[flag_idx], "x", color=_FLAG, ms=8, mew=2, label="flagged")
    ax.set_xlabel("time (s)" if fps else "frame")
    ax.set_ylabel(label)
    if title:
        ax.set_title(title, fontsize=10)
    ax.set_xlim(x[0] - 0.5 / (fps or 1.0), x[-1] + 0.5 / (fps or 1.0))
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8, framealpha=0.8)
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=100, facecolor="white")
    return fig


# ----------------------------------------------------------------------------------------------
# helpers


class _PoseArtist:
    """The bones of one skeleton on one axes, redrawn in place frame after frame."""

    def __init__(self, ax, skel: Skeleton, view: str, *, color=None, linewidth: float = 2.5):
        self.ax, self.skel, self.view, self.linewidth = ax, skel, view, linewidth
        self.bones = skel.bones
        self.basis = _basis(skel, view)
        if color is None:
            names = [skel.joint_names[j] for j in self.bones[:, 1]]
            self.colors = [_LEFT if n.startswith("left") else _RIGHT if n.startswith("right") else _CENTRE for n in names]
        else:
            self.colors = [color] * len(self.bones)
        self.collection = None

    def draw(self, pose: np.ndarray, *, highlight: bool = False):
        proj = np.asarray(pose, dtype=np.float64) @ self.basis  # (J, 2) or (J, 3)
        segments = np.stack([proj[self.bones[:, 0]], proj[self.bones[:, 1]]], axis=1)
        colors = [_FLAG] * len(self.bones) if highlight else self.colors
        width = self.linewidth * (1.4 if highlight else 1.0)
        if self.collection is None:
            if self.view == "3d":
                from mpl_toolkits.mplot3d.art3d import Line3DCollection

                self.collection = Line3DCollection(segments, colors=colors, linewidths=width, capstyle="round")
                self.ax.add_collection3d(self.collection)
            else:
                self.collection = LineCollection(segments, colors=colors, linewidths=width, capstyle="round")
                self.ax.add_collection(self.collection)
                self.ax.autoscale_view()
        else:
            self.collection.set_segments(segments)
            self.collection.set_color(colors)
            self.collection.set_linewidth(width)
        return self.collection


def _colour_legend(fig: Figure, *, y: float) -> None:
    """One legend line naming the bone colours and the flag colour, centred at height ``y``."""
    from matplotlib.lines import Line2D

    entries = [("left side", _LEFT), ("right side", _RIGHT), ("centre", _CENTRE), ("flagged frame", _FLAG)]
    handles = [Line2D([], [], color=c, lw=2.5, label=n) for n, c in entries]
    fig.legend(handles=handles, loc="center", bbox_to_anchor=(0.5, y), ncol=len(handles), fontsize=7,
               frameon=False, handlelength=1.5, columnspacing=1.0)


def _basis(skel: Skeleton, view: str) -> np.ndarray:
    """``(3, 2)`` or ``(3, 3)`` projection: columns are the skeleton-frame directions of the screen axes."""
    up, fwd = skel.up_vector, skel.forward_vector
    right = np.cross(up, fwd)  # the subject's left when facing the viewer
    if view == "front":
        return np.stack([right, up], axis=1)
    if view == "side":
        return np.stack([fwd, up], axis=1)
    return np.stack([right, -fwd, up], axis=1)  # 3-D: subject faces the viewer at azimuth -90


def _limits(clips: Sequence[np.ndarray], skels: Sequence[Skeleton], view: str, aspect: float = 1.0) -> np.ndarray:
    """``(D, 2)`` fixed axis limits holding every frame of every clip, with equal scale and given width/height."""
    proj = np.concatenate([np.asarray(c, dtype=np.float64).reshape(-1, 3) @ _basis(s, view) for c, s in zip(clips, skels)])
    lo, hi = proj.min(0), proj.max(0)
    centre = (lo + hi) / 2
    need = np.maximum((hi - lo) / 2, 1e-3) * (1 + 2 * _MARGIN)  # half extents
    if view == "3d":
        half = np.full(3, need.max())
    else:
        half_y = max(need[1], need[0] / aspect)
        half = np.array([half_y * aspect, half_y])
    return np.stack([centre - half, centre + half], axis=1)


def _style_panel(ax, view: str, limits: np.ndarray, *, flagged: bool = False) -> None:
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    if view == "3d":
        ax.set_zlim(*limits[2])
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=15, azim=-70)
        ax.set_xticklabels([])
        ax.set_yticklabels([])
        ax.set_zticklabels([])
    else:
        ax.set_aspect("equal", adjustable="box")
        ax.set_xticks([])
        ax.set_yticks([])
    ax.set_facecolor("white")
    _set_frame(ax, view, flagged)


def _set_frame(ax, view: str, flagged: bool) -> None:
    """Red frame around a flagged panel, a faint one otherwise."""
    if view == "3d":
        ax.patch.set_edgecolor(_FLAG if flagged else "white")
        ax.patch.set_linewidth(4 if flagged else 0)
        return
    for spine in ax.spines.values():
        spine.set_visible(True)
        spine.set_color(_FLAG if flagged else "#d0d0d0")
        spine.set_linewidth(3.0 if flagged else 0.8)


def _figure(width: float, height: float, *, dpi: int) -> Figure:
    if not (isinstance(dpi, (int, np.integer)) and 10 <= dpi <= 600):
        raise ValueError(f"`dpi` must be an int in 10..600; got {dpi!r}.")
    fig = Figure(figsize=(width, height), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    return fig


def _as_rows(obj, skeleton) -> list[Motion]:
    """Motions from a Motion, a (T, J, 3) / (R, T, J, 3) array or a sequence of either."""
    if isinstance(obj, Motion):
        return [obj]
    if isinstance(obj, (list, tuple)) and obj and all(isinstance(m, Motion) or _ndim(m) == 3 for m in obj):
        items = list(obj)
    else:
        ndim = _ndim(obj)
        if ndim == 4:
            items = list(to_numpy(obj, name="motions"))
        elif ndim == 3:
            items = [obj]
        else:
            raise ValueError(
                "`motions` must be a Motion, an array of shape (T, J, 3) or (R, T, J, 3), or a sequence of "
                f"them; got {type(obj).__name__}" + (f" with {ndim} dimensions." if ndim is not None else ".")
            )
    skel = get_skeleton(skeleton)
    rows = []
    for i, m in enumerate(items):
        if isinstance(m, Motion):
            rows.append(m)
            continue
        try:
            rows.append(Motion(m, skeleton=skel.name, fps=skel.fps))
        except ValueError as e:
            raise ValueError(f"motion {i} of {len(items)}: {e}") from e
    return rows


def _ndim(x) -> int | None:
    if isinstance(x, Motion):
        return None
    try:
        return to_numpy(x, name="motions").ndim
    except ValueError:
        return None


def _check_frames(frames, n_frames: int, *, name: str, allow_mask: bool, unique: bool = True) -> np.ndarray:
    """Sorted unique (or as given) int frame indices in ``0..n_frames-1`` from indices or a bool mask."""
    if frames is None:
        return np.zeros(0, dtype=int)
    arr = to_numpy(frames, name=name)
    if arr.ndim != 1:
        raise ValueError(f"`{name}` must be a 1-D sequence of frame indices; got shape {tuple(arr.shape)}.")
    if arr.dtype == bool:
        if not allow_mask:
            raise ValueError(f"`{name}` must hold frame indices, not booleans.")
        if arr.size != n_frames:
            raise ValueError(f"`{name}` as a boolean mask must have length T={n_frames}; got {arr.size}.")
        return np.flatnonzero(arr)
    if arr.size == 0:
        return np.zeros(0, dtype=int)
    if not np.isfinite(arr).all() or not np.all(arr == np.round(arr)):
        raise ValueError(f"`{name}` must hold integer frame indices; got {arr.tolist()}.")
    idx = arr.astype(int)
    bad = idx[(idx < 0) | (idx >= n_frames)]
    if bad.size:
        raise ValueError(f"`{name}` must be frame indices in 0..{n_frames - 1}; got {bad.tolist()}.")
    return np.unique(idx) if unique else idx


def _check_labels(labels, n_rows: int):
    if labels is None:
        return ("before", "after") if n_rows == 2 else None
    labels = list(labels) if not isinstance(labels, str) else None
    if labels is None or len(labels) != n_rows or not all(isinstance(s, str) for s in labels):
        raise ValueError(f"`labels` must be {n_rows} strings, one per motion.")
    return labels


def _check_pose(joints, skel: Skeleton) -> np.ndarray:
    """A float32 ``(J, 3)`` copy of one pose, or a ValueError naming the problem."""
    arr = to_numpy(joints, name="joints")
    if arr.shape != (skel.n_joints, 3):
        raise ValueError(
            f"`joints` must have shape (J, 3) with J={skel.n_joints} for skeleton {skel.name!r}; got {tuple(arr.shape)}."
        )
    return check_joints(arr[None], name="joints", skeleton=skel, min_frames=1)[0]


def _check_view(view) -> None:
    if view not in VIEWS:
        raise ValueError(f"`view` must be one of {', '.join(VIEWS)}; got {view!r}.")


def _check_axes(ax, view: str) -> None:
    is_3d = getattr(ax, "name", "") == "3d"
    if is_3d != (view == "3d"):
        raise ValueError(
            f"`view={view!r}` needs a {'3-D' if view == '3d' else '2-D'} axes; got a {'3-D' if is_3d else '2-D'} one."
        )


def _out_path(path, suffixes: tuple[str, ...]) -> Path:
    out = Path(path)
    if out.suffix.lower() not in suffixes:
        raise ValueError(f"`path` must end in {' or '.join(suffixes)}; got {str(path)!r}.")
    if not out.parent.is_dir():
        raise ValueError(f"folder of `path` does not exist: {out.parent}.")
    return out


def _resize_nearest(image: np.ndarray, height: int, width: int) -> np.ndarray:
    rows = np.minimum((np.arange(height) * image.shape[0] / height).astype(int), image.shape[0] - 1)
    cols = np.minimum((np.arange(width) * image.shape[1] / width).astype(int), image.shape[1] - 1)
    return image[rows][:, cols]
