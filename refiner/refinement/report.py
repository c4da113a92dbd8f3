"""What ``refine`` found and changed in a clip: :class:`RefinementReport`, and the reports a batch starts with."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from refiner.core.validation import check_action
from refiner.refinement.inputs import MIN_FRAMES

__all__ = ["RefinementReport", "start_reports"]


@dataclass
class RefinementReport:
    """What ``refine`` found and changed in one clip (JSON-serialisable via :meth:`to_dict`): ``flagged_frames``
    are the frames a detector flagged, ``changes`` the runs a step changed, ``not_kept`` the runs a step proposed
    and left as given (with the figures it would have made worse)."""

    mode: str
    n_frames: int
    action: int | None = None
    action_name: str | None = None
    action_inferred: bool = False
    anchors: list[int] = field(default_factory=list)
    anchor_probability: list[float] = field(default_factory=list)
    flaw_probability: list[float] = field(default_factory=list)
    anchor_scores: list[float] = field(default_factory=list)
    threshold: float | None = None
    flagged_anchors: list[int] = field(default_factory=list)
    refined_anchors: list[dict] = field(default_factory=list)
    transition_residuals_cm: list[float] = field(default_factory=list)
    transition_thresholds_cm: list[float] = field(default_factory=list)
    flagged_transitions: list[list[int]] = field(default_factory=list)
    flagged_frames: list[int] = field(default_factory=list)
    changes: list[dict] = field(default_factory=list)
    not_kept: list[dict] = field(default_factory=list)
    note: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def changed_frames(self) -> np.ndarray:
        """Boolean ``(T,)`` mask of frames that changed."""
        mask = np.zeros(self.n_frames, dtype=bool)
        for c in self.changes:
            mask[c["start"] : c["stop"]] = True
        return mask

    @property
    def threshold_quantity(self) -> str | None:
        """The field ``threshold`` applies to: ``"flaw_probability"`` (motion method) or ``"anchor_scores"``
        (concepts method: the anchors' pose scores, a log-likelihood, not ``anchor_probability``)."""
        if self.threshold is None:
            return None
        return "flaw_probability" if self.flaw_probability else "anchor_scores"

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict, with ``threshold_quantity`` after ``threshold``."""
        out = {}
        for key, value in asdict(self).items():
            out[key] = value
            if key == "threshold":
                out["threshold_quantity"] = self.threshold_quantity
        return out


def start_reports(n_frames: int, actions, mode: str, action_names, *, batched: bool) -> list[RefinementReport]:
    """One report per clip of ``n_frames`` frames, with its given action (None: to infer) checked against
    ``action_names`` (in a batch, an error names the clip) and, for clips too short to refine, a note."""
    reports = []
    for i, action in enumerate(actions):
        report = RefinementReport(mode=mode, n_frames=n_frames)
        if action is not None:
            try:
                report.action = check_action(action, action_names)
            except ValueError as e:
                if not batched:
                    raise
                raise ValueError(f"clip {i} of {len(actions)}: {e}") from e
        if n_frames < MIN_FRAMES:
            report.note = f"clip has {n_frames} frames; at least {MIN_FRAMES} are needed to refine, returned unchanged"
        reports.append(report)
    return reports
