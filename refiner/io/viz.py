"""Skeleton pictures of motions: single poses, key-frame strips, before/after animations and anchor-score plots.

The pictures are :mod:`refiner.io.pictures`, the animations :mod:`refiner.io.animations` and what both
share (views, colours, limits) :mod:`refiner.io.skeleton_drawing`; this module gathers their public
functions.

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

A refinement is drawn from its report by :func:`change_figure` (key frames) and :func:`animate_change` (GIF):
before faint under after, front and side, the ground and the feet's paths, frames framed in the colour of the
step that changed them and "flagged" only where a detector flagged (:mod:`refiner.io.change_views`,
:mod:`refiner.io.change_animation`); :func:`refiner.evaluation.clip_summary.summary_figure` draws its figures.
"""
from __future__ import annotations

from refiner.io.animations import animate
from refiner.io.change_animation import animate_change
from refiner.io.change_marks import read_marks
from refiner.io.change_views import change_figure
from refiner.io.pictures import draw_pose, keyframe_strip, plot_scores, render_pose_image
from refiner.io.skeleton_drawing import VIEWS

__all__ = [
    "VIEWS",
    "draw_pose",
    "render_pose_image",
    "keyframe_strip",
    "animate",
    "plot_scores",
    "read_marks",
    "change_figure",
    "animate_change",
]
