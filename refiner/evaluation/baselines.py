"""Baseline refiners (identity, classic filters, concept-free spline refit) and the benchmark's refiner registry.

Every refiner has one method, ``refine(motion, *, action=None) -> Motion``, returning a new clip of
the same length, skeleton and fps; hyper-parameters are set in ``__init__`` and validated on use
(scikit-learn convention). ``action`` is accepted for interface parity with the refiners that read it and
ignored by the baselines.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import savgol_filter
from sklearn.base import BaseEstimator

from refiner.concepts.segmentation import DEFAULT_PENALTY, segment
from refiner.core.motion import Motion

__all__ = [
    "IdentityRefiner",
    "SavgolRefiner",
    "GaussianRefiner",
    "SplineFitRefiner",
    "PipelineRefiner",
    "FLAW_REFINERS",
    "clean_clip_change",
]


def _as_motion(motion) -> Motion:
    """A Motion as is; an array-like ``(T, J, 3)`` becomes a HumanAct12 Motion at 20 fps."""
    if isinstance(motion, Motion):
        return motion
    try:
        return Motion(motion)
    except ValueError as e:
        raise ValueError(f"`motion` must be a Motion or a (T, 24, 3) HumanAct12 array: {e}") from e


class _Refiner(BaseEstimator):
    """Shared ``refine`` plumbing: validate, transform the joints, rebuild the Motion."""

    def refine(self, motion: Motion, *, action=None) -> Motion:
        """Refine one clip.

        Parameters
        ----------
        motion : Motion, or array-like of shape (T, J, 3)
            Joint positions in metres (an array is taken as HumanAct12 at 20 fps).
        action : int or str, optional
            Ignored by the baselines.

        Returns
        -------
        Motion
            New clip, same shape, skeleton, fps and action.
        """
        m = _as_motion(motion)
        return m.with_joints(self._transform(m.numpy()))

    def _transform(self, joints: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


class IdentityRefiner(_Refiner):
    """Returns the clip unchanged (the "no refinement" row of every table)."""

    def _transform(self, joints):
        return joints


class SavgolRefiner(_Refiner):
    """Savitzky-Golay filter along time, per joint and axis (``scipy.signal.savgol_filter``).

    Parameters
    ----------
    window_length : int, default=5
        Odd number of frames; shortened to the clip's length (largest odd value) when longer.
    polyorder : int, default=2
    mode : str, default="interp"
        Edge handling, see ``savgol_filter``.
    """

    def __init__(self, window_length: int = 5, polyorder: int = 2, mode: str = "interp"):
        self.window_length = window_length
        self.polyorder = polyorder
        self.mode = mode

    def _transform(self, joints):
        w, p = self.window_length, self.polyorder
        if not isinstance(w, (int, np.integer)) or w < 1 or w % 2 == 0:
            raise ValueError(f"`window_length` must be a positive odd int; got {w!r}.")
        if not isinstance(p, (int, np.integer)) or not 0 <= p < w:
            raise ValueError(f"`polyorder` must be an int in [0, window_length); got {p!r}.")
        w = min(w, len(joints) if len(joints) % 2 else len(joints) - 1)
        if w <= p:  # clip too short for the filter: nothing to smooth
            return joints
        return savgol_filter(joints, w, p, axis=0, mode=self.mode)


class GaussianRefiner(_Refiner):
    """Gaussian filter along time (``scipy.ndimage.gaussian_filter1d``).

    Parameters
    ----------
    sigma : float, default=1.0
        Standard deviation in frames.
    mode : str, default="nearest"
        Edge handling, see ``gaussian_filter1d``.
    """

    def __init__(self, sigma: float = 1.0, mode: str = "nearest"):
        self.sigma = sigma
        self.mode = mode

    def _transform(self, joints):
        if not (isinstance(self.sigma, (int, float, np.number)) and self.sigma > 0):
            raise ValueError(f"`sigma` must be a positive number of frames; got {self.sigma!r}.")
        return gaussian_filter1d(joints, float(self.sigma), axis=0, mode=self.mode)


class SplineFitRefiner(_Refiner):
    """Spline refit without concepts: segment the clip (Eq. 2) and return its piecewise-cubic reconstruction.

    Parameters
    ----------
    penalty : float, default=200.0
        Segmentation λ in cm² per joint (see :func:`refiner.concepts.segmentation.segment`).
    """

    def __init__(self, penalty: float = DEFAULT_PENALTY):
        self.penalty = penalty

    def _transform(self, joints):
        if len(joints) < 4:  # a cubic needs 4 frames; shorter clips are left as they are
            return joints
        return segment(joints, penalty=self.penalty).reconstruct()


class PipelineRefiner:
    """The concepts method's refiner (``refiner.refinement.pipeline.Refiner.pretrained()``) in one mode, with the baseline
    interface.

    Parameters
    ----------
    mode : {"anchor", "transition", "full"}
    **pretrained_kwargs
        Passed to ``Refiner.pretrained``.

    Raises
    ------
    ImportError
        When ``refiner.refinement.pipeline`` is not available.
    """

    def __init__(self, mode: str, **pretrained_kwargs):
        from refiner.refinement.pipeline import Refiner  # imports torch: here, so that importing the baselines stays cheap

        self.mode = mode
        self.kwargs = pretrained_kwargs
        self.refiner_ = Refiner.pretrained(**pretrained_kwargs)

    def refine(self, motion: Motion, *, action=None) -> Motion:
        m = _as_motion(motion)
        out = self.refiner_.refine(m, action=action, mode=self.mode)
        return out if isinstance(out, Motion) else m.with_joints(out)

    def __repr__(self) -> str:
        extra = "".join(f", {k}={v!r}" for k, v in sorted(self.kwargs.items()))
        return f"PipelineRefiner(mode={self.mode!r}{extra})"


def _motion_refiner(weights=None):
    """The default refiner, ``MotionRefiner.pretrained("humanact12", weights=weights)``: its model learned on subjects
    1-8 and was calibrated on 9-10, so the benchmark's subjects 11-12 are new to it."""
    from refiner.refinement.motion_refiner import MotionRefiner  # imports torch: here, so that importing stays cheap

    return MotionRefiner.pretrained("humanact12", weights=weights)


#: Refiners compared by ``motion-refiner bench flaws``: name -> factory of keyword ``weights`` (a folder of weight sets
#: looked in before the shipped ones; the baselines have none). ``ours_full`` is the default refiner (the motion
#: model, :func:`_motion_refiner`); the other ``ours_*`` are the concepts method (the paper's) with the weights trained
#: on subjects 1-10 only (``split="train"``), since the benchmark runs on subjects 11-12: ``ours_anchor`` and
#: ``ours_transition`` its anchor and transition refinement alone, ``ours_concepts`` both, ``ours_concept_snap`` both
#: with the concept-snap option (every anchor moved onto a concept). A factory that raises (ValueError without its
#: weights) makes the bench skip that row with a note.
FLAW_REFINERS: dict[str, Callable[..., object]] = {
    "identity": lambda weights=None: IdentityRefiner(),
    "savgol": lambda weights=None: SavgolRefiner(),
    "gaussian": lambda weights=None: GaussianRefiner(),
    "spline_fit": lambda weights=None: SplineFitRefiner(),
    "ours_full": _motion_refiner,
    "ours_anchor": lambda weights=None: PipelineRefiner("anchor", split="train", weights=weights),
    "ours_transition": lambda weights=None: PipelineRefiner("transition", split="train", weights=weights),
    "ours_concepts": lambda weights=None: PipelineRefiner("full", split="train", weights=weights),
    "ours_concept_snap": lambda weights=None: PipelineRefiner("full", split="train", concept_snap=1.0, weights=weights),
}


def clean_clip_change(refiner, motions: Sequence[Motion]) -> float:
    """How much a refiner moves clips that need no refinement: mean MPJPE between input and output.

    Parameters
    ----------
    refiner : object with ``refine(motion, *, action=None) -> Motion``
    motions : sequence of Motion
        Clean (real) clips; each is refined with its own ``action``.

    Returns
    -------
    float
        Centimetres: MPJPE of each clip (mean over frames and joints), averaged over clips.
    """
    motions = list(motions)
    if not motions:
        raise ValueError("`motions` is empty.")
    errors = []
    for i, m in enumerate(motions):
        if not isinstance(m, Motion):
            raise ValueError(f"`motions` item {i} must be a Motion; got {type(m).__name__}.")
        out = refiner.refine(m, action=m.action)
        if out.joints.shape != m.joints.shape:
            raise ValueError(f"{refiner!r} changed the shape of clip {i} from {m.joints.shape} to {out.joints.shape}.")
        errors.append(np.linalg.norm(out.joints.astype(np.float64) - m.joints, axis=-1).mean())
    return float(100.0 * np.mean(errors))
