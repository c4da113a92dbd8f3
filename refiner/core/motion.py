"""Canonical motion: joint positions of one clip in its skeleton's own frame (paper §3, appendix A).

The canonical frame is the target dataset's: for HumanAct12 and UESTC, metres, y down, facing -z,
first-frame root at the origin once :meth:`Motion.normalized` is applied. Adapters convert
generator outputs into it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable, Sequence

import numpy as np

from refiner.core.skeletons import Skeleton, convert, get_skeleton
from refiner.core.validation import check_joints

__all__ = ["Motion", "stack_motions", "unstack_motions"]


@dataclass(frozen=True, eq=False)
class Motion:
    """One motion clip: joint positions with their skeleton, frame rate and optional action.

    Parameters
    ----------
    joints : array-like of shape (T, J, 3)
        Joint positions in metres, in the skeleton's frame. Copied to a read-only float32 array;
        numpy arrays, torch tensors and nested lists are accepted.
    skeleton : str, default="humanact12"
        Registered skeleton name; J must match it.
    fps : float, default=20.0
    action : int, optional
        Action index in the dataset's label set.

    Raises
    ------
    ValueError
        Wrong shape, joint count not matching the skeleton, fewer than 2 frames, NaN or Inf,
        unknown skeleton, non-positive fps.

    Examples
    --------
    >>> import numpy as np
    >>> m = Motion(np.zeros((60, 24, 3)), skeleton="humanact12", action=1)
    >>> m.n_frames, m.n_joints, m.joints.dtype
    (60, 24, dtype('float32'))
    """

    joints: np.ndarray
    skeleton: str = "humanact12"
    fps: float = 20.0
    action: int | None = None

    def __post_init__(self) -> None:
        skel = get_skeleton(self.skeleton)
        joints = check_joints(self.joints, name="joints", skeleton=skel)
        joints.flags.writeable = False
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "skeleton", skel.name)
        if not (isinstance(self.fps, (int, float, np.number)) and np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"`fps` must be a positive number; got {self.fps!r}.")
        object.__setattr__(self, "fps", float(self.fps))
        if self.action is not None:
            if isinstance(self.action, (bool, np.bool_)) or not isinstance(self.action, (int, np.integer)) or self.action < 0:
                raise ValueError(f"`action` must be a non-negative int index or None; got {self.action!r}.")
            object.__setattr__(self, "action", int(self.action))

    @property
    def n_frames(self) -> int:
        return self.joints.shape[0]

    @property
    def n_joints(self) -> int:
        return self.joints.shape[1]

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return (self.n_frames - 1) / self.fps

    @property
    def skeleton_info(self) -> Skeleton:
        return get_skeleton(self.skeleton)

    def numpy(self) -> np.ndarray:
        """A writable float32 copy of the joints, ``(T, J, 3)``."""
        return self.joints.copy()

    def torch(self, device=None):
        """The joints as a new float32 ``torch.Tensor`` ``(T, J, 3)``."""
        import torch

        return torch.tensor(self.joints, dtype=torch.float32, device=device)

    def with_joints(self, joints) -> "Motion":
        """Same skeleton, fps and action with new joints (validated)."""
        return replace(self, joints=joints)

    def to(self, skeleton: str) -> "Motion":
        """The same clip on another skeleton (:func:`refiner.core.skeletons.convert`).

        Joints shared by both skeletons are copied, rotated into the target's frame; the others
        are estimates (:func:`refiner.core.skeletons.estimated_joints` names them). Fps and action are
        kept (the action stays an index in the clip's original label set). The same skeleton
        returns an equal copy.

        Examples
        --------
        >>> import numpy as np
        >>> Motion(np.zeros((60, 24, 3)), skeleton="humanact12").to("uestc").n_joints
        18
        """
        return Motion(convert(self.joints, self.skeleton, skeleton), skeleton=get_skeleton(skeleton).name,
                      fps=self.fps, action=self.action)

    def normalized(self) -> "Motion":
        """Translate so that the root of the first frame is at the origin (appendix A)."""
        root = self.skeleton_info.root
        return self.with_joints(self.joints - self.joints[:1, root : root + 1])

    def crop(self, start: int, stop: int) -> "Motion":
        """Frames ``start:stop`` (at least 2 frames)."""
        return self.with_joints(self.joints[start:stop])

    def __len__(self) -> int:
        return self.n_frames

    def __eq__(self, other) -> bool:
        return (
            isinstance(other, Motion)
            and self.skeleton == other.skeleton
            and self.fps == other.fps
            and self.action == other.action
            and np.array_equal(self.joints, other.joints)
        )

    def __repr__(self) -> str:
        return (
            f"Motion(frames={self.n_frames}, joints={self.n_joints}, skeleton={self.skeleton!r}, "
            f"fps={self.fps:g}, action={self.action!r})"
        )


def stack_motions(motions: Sequence[Motion]) -> np.ndarray:
    """Stack equal-length motions of one skeleton into a ``(B, T, J, 3)`` float32 array."""
    motions = list(motions)
    if not motions:
        raise ValueError("`motions` is empty.")
    shapes = {m.joints.shape for m in motions}
    if len(shapes) != 1:
        raise ValueError(f"`motions` must share one shape to stack; got {sorted(shapes)}.")
    if len({m.skeleton for m in motions}) != 1:
        raise ValueError("`motions` must share one skeleton to stack.")
    return np.stack([m.joints for m in motions]).astype(np.float32)


def unstack_motions(
    batch, *, skeleton: str = "humanact12", fps: float = 20.0, actions: Iterable[int | None] | None = None
) -> list[Motion]:
    """Split a ``(B, T, J, 3)`` array into ``B`` motions (the inverse of :func:`stack_motions`)."""
    arr = check_joints(batch, name="batch", skeleton=skeleton, batched=True)
    actions = list(actions) if actions is not None else [None] * len(arr)
    if len(actions) != len(arr):
        raise ValueError(f"`actions` must have one entry per clip ({len(arr)}); got {len(actions)}.")
    return [Motion(a, skeleton=skeleton, fps=fps, action=act) for a, act in zip(arr, actions)]
