"""The scene of a before / after picture: both clips in one view (before faint, after solid), the ground, the feet.

Shared by :mod:`refiner.io.change_views` (still pictures) and :mod:`refiner.io.change_animation`. Heights, contact
joints and feet are :mod:`refiner.core.contact`'s; the ground is the *before* clip's, as the benchmark judges a
refined clip on its source's ground, placed as :func:`~refiner.evaluation.ground_metrics.ground_height` does (the
lowest a contact joint reaches), and a foot is on the ground less than :data:`CONTACT_M` above it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from refiner.core.contact import contact_joints, foot_joints, heights
from refiner.core.motion import Motion
from refiner.io.change_marks import ChangeMarks
from refiner.io.skeleton_drawing import CENTRE, LEFT, RIGHT, PoseArtist, as_rows, view_basis

__all__ = ["GHOST_ALPHA", "CONTACT_M", "Scene", "make_scene", "draw_ground", "draw_feet", "feet_limits",
           "pose_artists", "mark_change", "status_text", "scene_legend"]

#: Opacity of the *before* clip drawn under the *after* one (where they agree, only the solid one shows).
GHOST_ALPHA = 0.3
#: A foot this close to the ground (metres) is on it: ``foot_skating_ratio``'s contact height (GMD's; a test keeps
#: them equal, as io may not import the evaluation layer).
CONTACT_M = 0.05
GROUND, GROUND_FILL = "#8c6d46", "#efe9dc"
_FOOT_COLOURS = (LEFT, RIGHT)  # the left and the right foot, as their bones


@dataclass
class Scene:
    """Two clips of one skeleton and length, the ground height (metres along up), the feet and their contacts.

    ``feet``: ``(2,)`` joint indices (left, right), or ``()``; ``contact``: per clip ``(T, len(feet))`` bool."""

    before: Motion
    after: Motion
    ground: float
    feet: tuple[int, int]
    contact: tuple[np.ndarray, np.ndarray]

    @property
    def skel(self):
        return self.before.skeleton_info

    @property
    def n_frames(self) -> int:
        return self.before.n_frames


def make_scene(before, after, skeleton) -> Scene:
    """A :class:`Scene` of ``before`` and ``after`` (Motions or ``(T, J, 3)`` arrays of ``skeleton``), or a
    ValueError when they differ in skeleton or length. ``feet`` is empty for a skeleton without named feet."""
    rows = as_rows([before, after], skeleton)
    if rows[0].skeleton != rows[1].skeleton or rows[0].joints.shape != rows[1].joints.shape:
        raise ValueError("`before` and `after` must share a skeleton and shape (T, J, 3); got "
                         f"{rows[0].skeleton} {rows[0].joints.shape} and {rows[1].skeleton} {rows[1].joints.shape}.")
    skel = rows[0].skeleton_info
    try:
        feet, low = foot_joints(skel), contact_joints(skel)
    except ValueError:  # a skeleton without named feet: the lowest joint stands on the ground, no foot paths
        feet, low = (), tuple(range(skel.n_joints))
    ground = float(heights(rows[0].joints[:, list(low)], skel).min())
    contact = tuple(heights(m.joints[:, list(feet)], skel) - ground < CONTACT_M for m in rows)
    return Scene(rows[0], rows[1], ground, feet, contact)


def draw_ground(ax, scene: Scene, view: str) -> None:
    """The ground: a line with the earth below it in a front or side view, the whole panel seen from above."""
    if view == "top":
        ax.set_facecolor(GROUND_FILL)
        return
    lo = ax.get_ylim()[0]
    ax.axhspan(min(lo, scene.ground), scene.ground, color=GROUND_FILL, lw=0, zorder=0)
    ax.axhline(scene.ground, color=GROUND, lw=1.0, zorder=1)


def draw_feet(ax, scene: Scene, view: str, *, size: float = 1.0) -> None:
    """Both feet's paths over the clip (before faint and dashed, after solid) with their ground-contact frames as
    dots, projected on ``view``; ``size`` scales lines and dots (1 for a 1.6-inch panel)."""
    basis = view_basis(scene.skel, view)
    for motion, contact, ghost in ((scene.before, scene.contact[0], True), (scene.after, scene.contact[1], False)):
        alpha = GHOST_ALPHA if ghost else 0.9
        for f, (joint, colour) in enumerate(zip(scene.feet, _FOOT_COLOURS)):
            path = motion.joints[:, joint].astype(np.float64) @ basis  # (T, 2)
            ax.plot(path[:, 0], path[:, 1], color=colour, lw=0.9 * size, alpha=alpha, ls="--" if ghost else "-",
                    zorder=2)
            on = contact[:, f]
            ax.plot(path[on, 0], path[on, 1], "o", ms=2.6 * size, alpha=alpha, zorder=3,
                    mfc="none" if ghost else colour, mec=colour, mew=0.7 * size)


def feet_limits(scene: Scene, view: str, *, aspect: float = 1.0, least_m: float = 0.4) -> np.ndarray:
    """``(2, 2)`` equal-scale limits around both clips' feet (and the ground, in a front or side view), at least
    ``least_m`` metres high, ``aspect`` = width / height."""
    basis = view_basis(scene.skel, view)
    joints = list(scene.feet) or list(range(scene.skel.n_joints))
    pts = np.concatenate([m.joints[:, joints].reshape(-1, 3) for m in (scene.before, scene.after)]) @ basis
    lo, hi = pts.min(0), pts.max(0)
    if view != "top":
        lo[1] = min(lo[1], scene.ground)
    centre = (lo + hi) / 2
    half_y = max((hi[1] - lo[1]) / 2 * 1.15, (hi[0] - lo[0]) / 2 * 1.15 / aspect, least_m / 2)
    return np.array([[centre[0] - half_y * aspect, centre[0] + half_y * aspect],
                     [centre[1] - half_y, centre[1] + half_y]])


def pose_artists(ax, scene: Scene, view: str, *, linewidth: float = 2.5) -> tuple[PoseArtist, PoseArtist]:
    """The before (faint, under) and after (solid) skeletons of ``ax`` in their own bone colours."""
    ghost = PoseArtist(ax, scene.skel, view, linewidth=linewidth, alpha=GHOST_ALPHA)
    solid = PoseArtist(ax, scene.skel, view, linewidth=linewidth)
    return ghost, solid


def mark_change(ax, marks: ChangeMarks, t: int, *, width: float = 3.0) -> None:
    """The panel frame of frame ``t``: the step's colour where a kept change covers it, dashed where only a change
    not kept does, faint grey elsewhere (a detector's flag is marked in the panel's title, not here)."""
    change = marks.at(t)
    for spine in ax.spines.values():
        spine.set_visible(True)
        if change is None:
            spine.set_color("#d0d0d0")
            spine.set_linewidth(0.8)
            spine.set_linestyle("-")
        else:
            spine.set_color(marks.colour(change.step))
            spine.set_linewidth(width if change.kept else width * 0.7)
            spine.set_linestyle("-" if change.kept else (0, (3, 2)))


def status_text(marks: ChangeMarks, t: int) -> tuple[str, str | None]:
    """The changes of frame ``t`` in words (``"infill"``, ``"infill not kept"``, ``"infill + concept_snap"``, or
    ``""``) and the colour of the one that shapes it (:meth:`ChangeMarks.at`)."""
    change = marks.at(t)
    if change is None:
        return "", None
    words = dict.fromkeys(c.step if c.kept else f"{c.step} not kept" for c in marks.covering(t))
    return " + ".join(words), marks.colour(change.step)


def scene_legend(labels: tuple[str, str]) -> list:
    """Legend handles of the scene: bone colours, before faint / after solid, the ground and a foot contact."""
    return [Line2D([], [], color=LEFT, lw=2.5, label="left side"),
            Line2D([], [], color=RIGHT, lw=2.5, label="right side"),
            Line2D([], [], color=CENTRE, lw=2.5, label="centre"),
            Line2D([], [], color=CENTRE, lw=2.5, alpha=GHOST_ALPHA, label=f"{labels[0]} (faint)"),
            Line2D([], [], color=CENTRE, lw=2.5, label=f"{labels[1]} (solid)"),
            Patch(facecolor=GROUND_FILL, edgecolor=GROUND, label="ground"),
            Line2D([], [], color=CENTRE, marker="o", ls="-", lw=0.9, ms=4, label="foot path, dots: on the ground")]
