"""Transition data: every spline transition of a dataset with its end anchors (paper §3.1.3).

A :class:`TransitionSet` is what the transition generator (the CVAE of the transition concepts)
trains on: for each transition its start and end anchors, duration, spline coefficients, action
and the real frames it covers.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, fields
from typing import Sequence

import numpy as np

from refiner.segmentation import Segmentation
from refiner.serialization import load_state, save_state

__all__ = ["TransitionSet", "collect_transitions"]


@dataclass(frozen=True)
class TransitionSet:
    """All transitions of a set of clips, flat arrays of N transitions.

    Attributes
    ----------
    start, end : ndarray of shape (N, J, 3), float32
        Anchor poses at both ends, metres, in the clip's frame.
    durations : ndarray of int, shape (N,)
        Frame intervals (the transition covers ``duration + 1`` frames).
    coeffs : ndarray of shape (N, 4, J, 3), float32
        Fitted spline coefficients (``refiner.splines`` convention).
    actions, clips, start_frames : ndarray of int, shape (N,)
        Action label, source clip index and first frame of each transition.
    frames : ndarray of shape (F, J, 3), float32
        Real frames of all transitions, concatenated; transition i is
        ``frames[offsets[i]:offsets[i + 1]]`` (``durations[i] + 1`` frames).
    offsets : ndarray of int, shape (N + 1,)
    """

    start: np.ndarray
    end: np.ndarray
    durations: np.ndarray
    coeffs: np.ndarray
    actions: np.ndarray
    clips: np.ndarray
    start_frames: np.ndarray
    frames: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.durations)

    def transition_frames(self, i: int) -> np.ndarray:
        """Real frames ``(duration + 1, J, 3)`` of transition ``i``."""
        return self.frames[self.offsets[i] : self.offsets[i + 1]]

    def subset(self, indices) -> "TransitionSet":
        idx = np.asarray(indices, dtype=np.int64)
        pieces = [self.transition_frames(i) for i in idx]
        lengths = np.array([len(p) for p in pieces], dtype=np.int64)
        frames = np.concatenate(pieces) if pieces else self.frames[:0]
        return TransitionSet(
            self.start[idx], self.end[idx], self.durations[idx], self.coeffs[idx], self.actions[idx],
            self.clips[idx], self.start_frames[idx], frames, np.concatenate([[0], np.cumsum(lengths)]),
        )

    def save(self, path: str | os.PathLike) -> None:
        save_state(path, {f.name: getattr(self, f.name) for f in fields(self)}, {"refiner.class": "TransitionSet"})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TransitionSet":
        tensors, metadata = load_state(path)
        if metadata.get("refiner.class") != "TransitionSet":
            raise ValueError(f"{str(path)!r} holds a {metadata.get('refiner.class')!r}, expected a 'TransitionSet'.")
        return cls(**{f.name: tensors[f.name] for f in fields(cls)})


def collect_transitions(
    clips: Sequence[np.ndarray], segmentations: Sequence[Segmentation], actions: Sequence[int]
) -> TransitionSet:
    """Gather the transitions of segmented clips.

    Parameters
    ----------
    clips : sequence of ndarray (T_i, J, 3)
    segmentations : sequence of Segmentation, one per clip
    actions : sequence of int, one per clip
    """
    if not (len(clips) == len(segmentations) == len(actions)):
        raise ValueError(
            f"need one segmentation and action per clip; got {len(clips)} clips, "
            f"{len(segmentations)} segmentations, {len(actions)} actions."
        )
    start, end, durations, coeffs, acts, clip_ids, starts, frames = [], [], [], [], [], [], [], []
    for c, (clip, seg, action) in enumerate(zip(clips, segmentations, actions)):
        clip = np.asarray(clip, dtype=np.float32)
        if seg.n_frames != len(clip):
            raise ValueError(f"clip {c}: segmentation covers {seg.n_frames} frames, the clip has {len(clip)}.")
        k, n = seg.anchors[:-1], seg.anchors[1:]
        start.append(clip[k])
        end.append(clip[n])
        durations.append(n - k)
        coeffs.append(seg.coeffs)
        acts.append(np.full(len(k), int(action)))
        clip_ids.append(np.full(len(k), c))
        starts.append(k)
        frames.extend(clip[a : b + 1] for a, b in zip(k, n))
    durations = np.concatenate(durations).astype(np.int64)
    return TransitionSet(
        start=np.concatenate(start),
        end=np.concatenate(end),
        durations=durations,
        coeffs=np.concatenate(coeffs).astype(np.float32),
        actions=np.concatenate(acts).astype(np.int64),
        clips=np.concatenate(clip_ids).astype(np.int64),
        start_frames=np.concatenate(starts).astype(np.int64),
        frames=np.concatenate(frames).astype(np.float32),
        offsets=np.concatenate([[0], np.cumsum(durations + 1)]).astype(np.int64),
    )
