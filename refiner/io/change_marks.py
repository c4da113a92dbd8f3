"""What a refinement report says of each frame, for pictures: where a detector flagged, and which step changed what.

A report is a :class:`~refiner.refinement.report.RefinementReport` or its ``to_dict()`` (a ``_report.json``).
Two things are kept apart, since a step may change frames no detector flagged (a whole-clip step) and a detector
may flag frames no step changed (a change not kept):

- *flagged*: the frames a detector found flawed: the ``flagged_frames`` field (the motion method's), the
  ``flagged_anchors`` and the inner frames of ``flagged_transitions`` whose residual was above its threshold;
- *changes*: the ``changes`` entries (``step``, ``start``, ``stop``; ``kept`` True unless it says otherwise) and
  the ``not_kept`` entries (runs a step proposed and left as given).

Entries without integer ``start`` / ``stop`` are skipped, so a report of a newer refiner still draws.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from matplotlib.cbook import contiguous_regions
from matplotlib.patches import Patch

from refiner.io.skeleton_drawing import FLAG

__all__ = ["Change", "ChangeMarks", "read_marks", "STEP_COLOURS", "NOT_KEPT_HATCH", "draw_timeline", "marks_legend"]

#: Colours of the shipped steps; other steps take :data:`_SPARE` colours in order. None is a bone or flag colour.
STEP_COLOURS = {"retime": "#ff7f0e", "infill": "#bcbd22", "anchor": "#9467bd", "transition": "#8c564b", "concept_snap": "#e377c2"}
_SPARE = ("#17becf", "#7f7f7f", "#aec7e8", "#c5b0d5")
NOT_KEPT_HATCH = "////"  # a change not kept: hatched in its step's colour


@dataclass(frozen=True)
class Change:
    """One run of frames ``start <= t < stop`` a step changed (``kept``) or proposed and left (not kept)."""

    step: str
    start: int
    stop: int
    kept: bool = True
    reason: str = ""


@dataclass
class ChangeMarks:
    """Per-frame marks of one clip of ``n_frames`` frames: ``flagged (T,)`` bool and the :class:`Change` runs."""

    n_frames: int
    flagged: np.ndarray
    changes: list[Change] = field(default_factory=list)

    @property
    def steps(self) -> list[str]:
        """Step names in order of first appearance."""
        return list(dict.fromkeys(c.step for c in self.changes))

    def colour(self, step: str) -> str:
        """The step's colour: :data:`STEP_COLOURS`, else the next spare one."""
        if step in STEP_COLOURS:
            return STEP_COLOURS[step]
        others = [s for s in self.steps if s not in STEP_COLOURS]
        return _SPARE[(others.index(step) if step in others else 0) % len(_SPARE)]

    def changed(self, kept: bool = True) -> np.ndarray:
        """``(T,)`` bool: frames in a change that was (``kept=True``) or was not kept."""
        mask = np.zeros(self.n_frames, bool)
        for c in self.changes:
            if c.kept == kept:
                mask[c.start:c.stop] = True
        return mask

    def at(self, t: int) -> Change | None:
        """The change that shapes frame ``t``: the shortest kept one covering it (the most local; a whole-clip step
        would hide every other), else the shortest not-kept one, else None."""
        covering = sorted(self.covering(t), key=lambda c: (not c.kept, c.stop - c.start))
        return covering[0] if covering else None

    def crop(self, stop: int) -> "ChangeMarks":
        """The marks of frames ``0 <= t < stop`` (changes cut at ``stop``)."""
        changes = [Change(c.step, c.start, min(c.stop, stop), c.kept, c.reason) for c in self.changes if c.start < stop]
        return ChangeMarks(stop, self.flagged[:stop].copy(), changes)

    def covering(self, t: int) -> list[Change]:
        """Every change covering frame ``t``, in report order."""
        return [c for c in self.changes if c.start <= t < c.stop]


def read_marks(report, n_frames: int) -> ChangeMarks:
    """The :class:`ChangeMarks` of ``report`` (a RefinementReport, its dict, ChangeMarks, or None: no marks) for a
    clip of ``n_frames`` frames."""
    if isinstance(report, ChangeMarks):
        if report.n_frames != n_frames:
            raise ValueError(f"the marks are of {report.n_frames} frames, the clip has {n_frames}; crop them.")
        return report
    flagged = np.zeros(n_frames, bool)
    if report is None:
        return ChangeMarks(n_frames, flagged)
    flagged |= _frame_mask(_get(report, "flagged_frames", []), n_frames)
    flagged |= _frame_mask(_get(report, "flagged_anchors", []), n_frames)
    flagged |= _transition_flags(report, n_frames)
    changes = []
    for entry in [*(_get(report, "changes", []) or []), *({**e, "kept": False} for e in _get(report, "not_kept", []) or [])]:
        change = _as_change(entry, n_frames)
        if change is not None:
            changes.append(change)
    return ChangeMarks(n_frames, flagged, changes)


def draw_timeline(ax, marks: ChangeMarks, *, keyframes=(), labels: bool = True):
    """Lanes over the frames of ``ax``: the flagged frames on top (red), then one lane per step, kept runs filled
    in the step's colour and runs not kept hatched. Returns a vertical cursor line (move it with ``set_xdata``)."""
    lanes = ["flagged"] + marks.steps
    for i, lane in enumerate(lanes):
        y = len(lanes) - 1 - i
        if lane == "flagged":
            spans = contiguous_regions(marks.flagged)
            ax.broken_barh([(s - 0.5, e - s) for s, e in spans], (y + 0.15, 0.7), facecolors=FLAG)
            continue
        colour = marks.colour(lane)
        for c in marks.changes:
            if c.step == lane:
                ax.broken_barh([(c.start - 0.5, c.stop - c.start)], (y + 0.15, 0.7), linewidth=0.8, edgecolors=colour,
                               facecolors=colour if c.kept else "none", hatch=None if c.kept else NOT_KEPT_HATCH)
    if labels and not marks.flagged.any() and not marks.changes:
        ax.text(0.5, 0.5, "no frame flagged by a detector, none changed", transform=ax.transAxes, ha="center",
                va="center", fontsize=8, color="#606060")
    for t in keyframes:
        ax.axvline(t, color="#909090", lw=0.6, ls=":")
    ax.set_xlim(-0.5, marks.n_frames - 0.5)
    ax.set_ylim(0, len(lanes))
    ax.set_yticks(np.arange(len(lanes)) + 0.5 if labels else [])
    ax.set_yticklabels(lanes[::-1] if labels else [], fontsize=7)
    ax.tick_params(axis="x", labelsize=7, length=2)
    for spine in ax.spines.values():
        spine.set_color("#d0d0d0")
    return ax.axvline(0, color="black", lw=1.0, visible=False)


def marks_legend(marks: ChangeMarks) -> list[Patch]:
    """Legend patches: flagged (where a frame is), then each step's kept and (where one exists) not-kept runs."""
    handles = [Patch(facecolor=FLAG, label="flagged by a detector")] if marks.flagged.any() else []
    for step in marks.steps:
        colour = marks.colour(step)
        kinds = {c.kept for c in marks.changes if c.step == step}
        if True in kinds:
            handles.append(Patch(facecolor=colour, label=f"{step}: changed"))
        if False in kinds:
            handles.append(Patch(facecolor="none", edgecolor=colour, hatch=NOT_KEPT_HATCH, label=f"{step}: not kept"))
    return handles


def _get(report, name: str, default):
    """A report field from a RefinementReport or its dict."""
    return report.get(name, default) if isinstance(report, dict) else getattr(report, name, default)


def _as_number(value) -> float | None:
    """``value`` as a finite float, or None for anything else (bools, strings, None, NaN)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return None
    return float(value) if np.isfinite(value) else None


def _as_int(value) -> int | None:
    """``value`` as an int when it is a whole number, else None."""
    number = _as_number(value)
    return int(number) if number is not None and number.is_integer() else None


def _as_change(entry, n_frames: int) -> Change | None:
    """A :class:`Change` clipped to the clip, or None for an entry without integer ``start`` / ``stop``."""
    if not isinstance(entry, dict):
        return None
    start, stop = _as_int(entry.get("start")), _as_int(entry.get("stop"))
    if start is None or stop is None:
        return None
    start, stop = max(start, 0), min(stop, n_frames)
    if stop <= start:
        return None
    worse = entry.get("worse")
    reason = str(entry.get("reason", "") or (", ".join(map(str, worse)) if isinstance(worse, (list, tuple)) else ""))
    return Change(str(entry.get("step", "change")), start, stop, bool(entry.get("kept", True)), reason)


def _frame_mask(frames, n_frames: int) -> np.ndarray:
    """``(T,)`` bool from frame indices or a bool mask; indices outside the clip are left out."""
    arr = np.asarray(frames if frames is not None else [])
    mask = np.zeros(n_frames, bool)
    if arr.dtype == bool and arr.shape == (n_frames,):
        return arr.copy()
    idx = [i for i in (_as_int(v) for v in arr.ravel().tolist()) if i is not None and 0 <= i < n_frames]
    mask[idx] = True
    return mask


def _transition_flags(report, n_frames: int) -> np.ndarray:
    """Inner frames of the flagged transitions whose residual was above its threshold (not those re-timed only
    because an anchor next to them changed)."""
    mask = np.zeros(n_frames, bool)
    anchors = [_as_int(a) for a in _get(report, "anchors", []) or []]
    residuals = _get(report, "transition_residuals_cm", []) or []
    thresholds = _get(report, "transition_thresholds_cm", []) or []
    for pair in _get(report, "flagged_transitions", []) or []:
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            continue
        a, b = _as_int(pair[0]), _as_int(pair[1])
        if a is None or b is None or a not in anchors:
            continue
        m = anchors.index(a)
        if m < min(len(residuals), len(thresholds)) and residuals[m] > thresholds[m]:
            mask[max(a + 1, 0):min(b, n_frames)] = True
    return mask

