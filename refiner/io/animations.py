"""Animations of motions: one clip, or a before / after pair side by side, as GIF (and MP4 when ffmpeg exists).

Views, colours and limits are those of :mod:`refiner.io.skeleton_drawing`; still pictures are
:mod:`refiner.io.pictures`.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.animation import FFMpegWriter, PillowWriter
from tqdm.auto import tqdm

from refiner.core.skeletons import Skeleton
from refiner.io.skeleton_drawing import (
    FLAG,
    PoseArtist,
    as_rows,
    axis_limits,
    check_frames,
    check_labels,
    check_out_path,
    check_view,
    new_figure,
    set_frame,
    style_panel,
)

__all__ = ["animate", "check_fps", "output_targets", "write_frames"]


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
    rows = as_rows([before] if after is None else [before, after], skeleton)
    check_view(view)
    n_frames = max(m.n_frames for m in rows)
    flags = set(check_frames(flagged, rows[0].n_frames, name="flagged", allow_mask=True).tolist())
    labels = check_labels(labels, len(rows))
    fps = check_fps(rows[0].fps if fps is None else fps)
    targets = output_targets(path, mp4)

    skels = [m.skeleton_info for m in rows]
    fig = new_figure(panel_size * len(rows), panel_size + 0.4, dpi=dpi)
    limits = axis_limits([m.joints for m in rows], skels, view)
    axes, artists = [], []
    for i, skel in enumerate(skels):
        ax = fig.add_subplot(1, len(rows), i + 1, projection="3d" if view == "3d" else None)
        style_panel(ax, view, limits)
        if labels is not None:
            ax.set_title(labels[i], fontsize=10)
        axes.append(ax)
        artists.append(PoseArtist(ax, skel, view))
    counter = fig.text(0.5, 0.02, "", ha="center", va="bottom", fontsize=9)
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.1, top=0.9, wspace=0.05)

    def draw(t: int) -> None:
        is_flagged = t in flags
        for r, (motion, artist, ax) in enumerate(zip(rows, artists, axes)):
            artist.draw(motion.joints[min(t, motion.n_frames - 1)], highlight=is_flagged and r == 0)
            set_frame(ax, view, is_flagged)
        counter.set_text(f"frame {t + 1}/{n_frames}" + ("   flagged" if is_flagged else ""))
        counter.set_color(FLAG if is_flagged else "black")

    write_frames(fig, targets, draw, n_frames, fps=fps, dpi=dpi, progress=progress)
    return targets


def check_fps(fps) -> float:
    """``fps`` when it is a playback rate in (0, 100] frames per second, else a ValueError."""
    if not (isinstance(fps, (int, float, np.number)) and np.isfinite(fps) and 0 < fps <= 100):
        raise ValueError(f"`fps` must be a number in (0, 100]; got {fps!r}.")
    return fps


def output_targets(path, mp4: bool | None) -> list[Path]:
    """The files an animation writes: ``path`` (.gif or .mp4) and, for a GIF, an MP4 beside it when ``mp4`` is True
    or None with ffmpeg on PATH; a ValueError for another suffix or an MP4 without ffmpeg."""
    out = check_out_path(path, (".gif", ".mp4"))
    ffmpeg = shutil.which("ffmpeg") is not None
    targets = [out]
    if out.suffix.lower() == ".gif" and (mp4 or (mp4 is None and ffmpeg)):
        targets.append(out.with_suffix(".mp4"))
    if any(t.suffix.lower() == ".mp4" for t in targets) and not ffmpeg:
        raise ValueError("MP4 output needs `ffmpeg` on PATH; install it or write a .gif with mp4=False.")
    return targets


def write_frames(fig, targets: Sequence[Path], draw, n_frames: int, *, fps: float, dpi: int, progress: bool) -> None:
    """Call ``draw(t)`` for every frame ``t`` and grab ``fig`` into each of ``targets`` (GIF by Pillow, MP4 by
    ffmpeg); ``progress`` shows a bar on stderr."""
    writers = [PillowWriter(fps=fps) if t.suffix.lower() == ".gif" else FFMpegWriter(fps=fps) for t in targets]
    for writer, target in zip(writers, targets):
        writer.setup(fig, str(target), dpi=dpi)
    try:
        for t in tqdm(range(n_frames), desc=f"drawing {targets[0].name}", unit="frame", disable=not progress):
            draw(t)
            for writer in writers:
                writer.grab_frame(facecolor="white")
    finally:
        for writer in writers:
            writer.finish()
