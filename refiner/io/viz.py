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
"""
from __future__ import annotations

from refiner.io.animations import animate
from refiner.io.pictures import draw_pose, keyframe_strip, plot_scores, render_pose_image
from refiner.io.skeleton_drawing import VIEWS

__all__ = [
    "VIEWS",
    "draw_pose",
    "render_pose_image",
    "keyframe_strip",
    "animate",
    "plot_scores",
]
