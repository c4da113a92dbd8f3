"""How a skeleton is drawn: views, bone colours, fixed axis limits, panels and the checks of drawing inputs.

Shared by :mod:`refiner.io.pictures` and :mod:`refiner.io.animations`; the views and colours are
described in :mod:`refiner.io.viz`. Figures are explicit :class:`matplotlib.figure.Figure` objects on the
Agg canvas (:func:`new_figure`), so no pyplot state is touched.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from refiner.core.motion import Motion
from refiner.core.skeletons import Skeleton, get_skeleton
from refiner.core.validation import check_joints, to_numpy

__all__ = [
    "VIEWS", "LEFT", "RIGHT", "CENTRE", "FLAG", "PoseArtist", "colour_legend", "view_basis", "axis_limits",
    "style_panel", "set_frame", "new_figure", "as_rows", "check_frames", "check_labels", "check_pose", "check_view",
    "check_axes", "check_out_path",
]

#: Accepted values of ``view``.
VIEWS = ("front", "side", "3d")
#: Bone colours: left side, right side, centre, and the bones of a flagged frame.
LEFT, RIGHT, CENTRE, FLAG = "#1f77b4", "#2ca02c", "#404040", "#d62728"
_MARGIN = 0.08  # fraction of the body's extent left free around it


class PoseArtist:
    """The bones of one skeleton on one axes, redrawn in place frame after frame."""

    def __init__(self, ax, skel: Skeleton, view: str, *, color=None, linewidth: float = 2.5, alpha: float = 1.0):
        self.ax, self.skel, self.view, self.linewidth, self.alpha = ax, skel, view, linewidth, alpha
        self.bones = skel.bones
        self.basis = view_basis(skel, view)
        if color is None:
            names = [skel.joint_names[j] for j in self.bones[:, 1]]
            self.colors = [LEFT if n.startswith("left") else RIGHT if n.startswith("right") else CENTRE for n in names]
        else:
            self.colors = [color] * len(self.bones)
        self.collection = None

    def draw(self, pose: np.ndarray, *, highlight: bool = False):
        proj = np.asarray(pose, dtype=np.float64) @ self.basis  # (J, 2) or (J, 3)
        segments = np.stack([proj[self.bones[:, 0]], proj[self.bones[:, 1]]], axis=1)
        colors = [FLAG] * len(self.bones) if highlight else self.colors
        width = self.linewidth * (1.4 if highlight else 1.0)
        if self.collection is None:
            if self.view == "3d":
                self.collection = Line3DCollection(segments, colors=colors, linewidths=width, capstyle="round",
                                                   alpha=self.alpha)
                self.ax.add_collection3d(self.collection)
            else:
                self.collection = LineCollection(segments, colors=colors, linewidths=width, capstyle="round",
                                                 alpha=self.alpha)
                self.ax.add_collection(self.collection)
                self.ax.autoscale_view()
        else:
            self.collection.set_segments(segments)
            self.collection.set_color(colors)
            self.collection.set_linewidth(width)
        return self.collection


def colour_legend(fig: Figure, *, y: float) -> None:
    """One legend line naming the bone colours and the flag colour, centred at height ``y``."""
    entries = [("left side", LEFT), ("right side", RIGHT), ("centre", CENTRE), ("flagged frame", FLAG)]
    handles = [Line2D([], [], color=c, lw=2.5, label=n) for n, c in entries]
    fig.legend(handles=handles, loc="center", bbox_to_anchor=(0.5, y), ncol=len(handles), fontsize=7,
               frameon=False, handlelength=1.5, columnspacing=1.0)


def view_basis(skel: Skeleton, view: str) -> np.ndarray:
    """``(3, 2)`` or ``(3, 3)`` projection: columns are the skeleton-frame directions of the screen axes.

    Besides :data:`VIEWS`, ``"top"``: the ground seen from above, screen right as in the front view, the subject
    facing down the screen (used for foot paths, not for whole poses)."""
    up, fwd = skel.up_vector, skel.forward_vector
    right = np.cross(up, fwd)  # the subject's left when facing the viewer
    if view == "front":
        return np.stack([right, up], axis=1)
    if view == "side":
        return np.stack([fwd, up], axis=1)
    if view == "top":
        return np.stack([right, -fwd], axis=1)
    return np.stack([right, -fwd, up], axis=1)  # 3-D: subject faces the viewer at azimuth -90


def axis_limits(clips: Sequence[np.ndarray], skels: Sequence[Skeleton], view: str, aspect: float = 1.0) -> np.ndarray:
    """``(D, 2)`` fixed axis limits holding every frame of every clip, with equal scale and given width/height."""
    proj = np.concatenate([np.asarray(c, dtype=np.float64).reshape(-1, 3) @ view_basis(s, view) for c, s in zip(clips, skels)])
    lo, hi = proj.min(0), proj.max(0)
    centre = (lo + hi) / 2
    need = np.maximum((hi - lo) / 2, 1e-3) * (1 + 2 * _MARGIN)  # half extents
    if view == "3d":
        half = np.full(3, need.max())
    else:
        half_y = max(need[1], need[0] / aspect)
        half = np.array([half_y * aspect, half_y])
    return np.stack([centre - half, centre + half], axis=1)


def style_panel(ax, view: str, limits: np.ndarray, *, flagged: bool = False) -> None:
    """Fixed limits, equal scale, no ticks, white background and the panel frame."""
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
    set_frame(ax, view, flagged)


def set_frame(ax, view: str, flagged: bool) -> None:
    """Red frame around a flagged panel, a faint one otherwise."""
    if view == "3d":
        ax.patch.set_edgecolor(FLAG if flagged else "white")
        ax.patch.set_linewidth(4 if flagged else 0)
        return
    for spine in ax.spines.values():
        spine.set_visible(True)
        spine.set_color(FLAG if flagged else "#d0d0d0")
        spine.set_linewidth(3.0 if flagged else 0.8)


def new_figure(width: float, height: float, *, dpi: int) -> Figure:
    """A white Figure of ``width`` x ``height`` inches on the Agg canvas (no pyplot state); checks ``dpi``."""
    if not (isinstance(dpi, (int, np.integer)) and 10 <= dpi <= 600):
        raise ValueError(f"`dpi` must be an int in 10..600; got {dpi!r}.")
    fig = Figure(figsize=(width, height), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    return fig


def as_rows(obj, skeleton) -> list[Motion]:
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
    """Dimensions of ``x`` as an array, or None when it is not one."""
    if isinstance(x, Motion):
        return None
    try:
        return to_numpy(x, name="motions").ndim
    except ValueError:
        return None


def check_frames(frames, n_frames: int, *, name: str, allow_mask: bool, unique: bool = True) -> np.ndarray:
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


def check_labels(labels, n_rows: int):
    """One label per row (``("before", "after")`` for two rows by default), or a ValueError."""
    if labels is None:
        return ("before", "after") if n_rows == 2 else None
    labels = list(labels) if not isinstance(labels, str) else None
    if labels is None or len(labels) != n_rows or not all(isinstance(s, str) for s in labels):
        raise ValueError(f"`labels` must be {n_rows} strings, one per motion.")
    return labels


def check_pose(joints, skel: Skeleton) -> np.ndarray:
    """A float32 ``(J, 3)`` copy of one pose, or a ValueError naming the problem."""
    arr = to_numpy(joints, name="joints")
    if arr.shape != (skel.n_joints, 3):
        raise ValueError(
            f"`joints` must have shape (J, 3) with J={skel.n_joints} for skeleton {skel.name!r}; got {tuple(arr.shape)}."
        )
    return check_joints(arr[None], name="joints", skeleton=skel, min_frames=1)[0]


def check_view(view) -> None:
    """A ValueError unless ``view`` is one of :data:`VIEWS`."""
    if view not in VIEWS:
        raise ValueError(f"`view` must be one of {', '.join(VIEWS)}; got {view!r}.")


def check_axes(ax, view: str) -> None:
    """A ValueError when a 2-D axes is given for ``view="3d"`` or the reverse."""
    is_3d = getattr(ax, "name", "") == "3d"
    if is_3d != (view == "3d"):
        raise ValueError(
            f"`view={view!r}` needs a {'3-D' if view == '3d' else '2-D'} axes; got a {'3-D' if is_3d else '2-D'} one."
        )


def check_out_path(path, suffixes: tuple[str, ...]) -> Path:
    """``path`` as a Path when it ends in one of ``suffixes`` and its folder exists, else a ValueError."""
    out = Path(path)
    if out.suffix.lower() not in suffixes:
        raise ValueError(f"`path` must end in {' or '.join(suffixes)}; got {str(path)!r}.")
    if not out.parent.is_dir():
        raise ValueError(f"folder of `path` does not exist: {out.parent}.")
    return out
