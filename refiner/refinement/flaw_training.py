"""Training batches for learned refinement: random crops of real clips with synthetic flaws and suspect masks.

One batch serves both networks: recognition learns where the flaws are from ``flawed`` and
``flaw_target``; repair learns to give back ``clean`` from ``given`` plus a ``suspect`` mask that
imitates an imperfect detector (the true flaw frames, randomly dilated, with false alarms) and
``infill`` (the suspect frames linearly interpolated from the others); in a share of the items the
suspect frames are ``hidden`` (``given`` = ``infill`` there), so the same network denoises what it
is given and in-fills what it is not.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from scipy.ndimage import binary_dilation

from refiner.core.signal import linear_infill
from refiner.nn.training import crop_start, put_crop, to_device
from refiner.refinement.anchor_recognition import anchor_targets
from refiner.refinement.training_flaws import synthesize

__all__ = ["FlawBatches", "FLAW_LABEL_CM", "IGNORE_BELOW_CM"]

#: A frame counts as flawed when the flaws moved its joints by more than this on average (cm).
FLAW_LABEL_CM = 1.0
#: Touched frames moved less than this are excluded from the recognition loss (too small to call).
IGNORE_BELOW_CM = 0.3


class FlawBatches:
    """Random flawed crops of real clips.

    Parameters
    ----------
    clips : sequence of ndarray (T_i, J, 3), metres
    actions : sequence of int, or None
        None for an action-agnostic network (every item gets action 0 of 1).
    anchors : sequence of int arrays, or None
        Segmentation anchors of each clip (anchor-recognition targets; None: no anchor targets).
    skeleton : str
    lengths : (int, int)
        Crop lengths are drawn per batch from this range; shorter clips are padded (``valid``).
    kinds : sequence of str, optional
        Flaw mechanisms (default all of ``refiner.refinement.training_flaws.MECHANISMS``).
    hide_probability, drop_action_probability : float
    """

    def __init__(self, clips: Sequence[np.ndarray], actions, anchors, *, skeleton: str = "humanact12",
                 lengths: tuple[int, int] = (32, 64), kinds=None, hide_probability: float = 0.3,
                 drop_action_probability: float = 0.2, n_actions: int | None = None):
        self.clips = [np.asarray(c, dtype=np.float32) for c in clips]
        self.actions = np.zeros(len(self.clips), np.int64) if actions is None else np.asarray(actions, dtype=np.int64)
        self.targets = [np.zeros(len(c), np.float32) if anchors is None else anchor_targets(len(c), a).astype(np.float32)
                        for c, a in zip(self.clips, anchors if anchors is not None else self.clips)]
        self.skeleton = skeleton
        self.lengths = lengths
        self.kinds = kinds
        self.hide_probability = hide_probability
        self.drop_action_probability = drop_action_probability
        self.n_actions = int(self.actions.max()) + 1 if n_actions is None else int(n_actions)

    def __len__(self) -> int:
        return len(self.clips)

    def validation_batch(self, device="cpu", size: int = 256, seed: int = 12345) -> dict[str, torch.Tensor]:
        """A fixed batch of ``size`` items (drawn with replacement from fewer clips) for model selection."""
        rng = np.random.default_rng(seed)
        return self.sample(rng.choice(len(self), size=min(size, len(self)), replace=len(self) < size), rng, device)

    def sample(self, indices: Sequence[int], rng: np.random.Generator, device="cpu") -> dict[str, torch.Tensor]:
        """A batch of ``len(indices)`` items as tensors on ``device`` (see the module docstring)."""
        n = len(indices)
        length = int(rng.integers(self.lengths[0], self.lengths[1] + 1))
        n_joints = self.clips[0].shape[1]
        out = {k: np.zeros((n, length, n_joints, 3), np.float32) for k in ("clean", "flawed", "given", "infill")}
        for k in ("valid", "suspect", "hidden", "label_mask"):
            out[k] = np.zeros((n, length), bool)
        out["flaw_target"] = np.zeros((n, length), np.float32)
        out["anchor_target"] = np.zeros((n, length), np.float32)
        out["action"] = np.zeros(n, np.int64)
        out["true_action"] = self.actions[np.asarray(indices)]
        for b, i in enumerate(indices):
            clip = self.clips[i]
            start = crop_start(len(clip), length, rng)
            crop = clip[start : start + length]
            crop = crop - crop[:1, :1]
            m = len(crop)
            donor = self.clips[int(rng.integers(len(self.clips)))]
            flaw = synthesize(crop, rng, skeleton=self.skeleton, kinds=self.kinds, donors=[donor]) if m >= 8 else None
            flawed = crop if flaw is None else flaw.joints
            touched = np.zeros(m, bool) if flaw is None else flaw.touched
            disp_cm = 100 * np.linalg.norm(flawed - crop, axis=-1).mean(-1)
            suspect = self._suspect(touched & (disp_cm > IGNORE_BELOW_CM), rng)
            hidden = suspect & (rng.random() < self.hide_probability)
            infill = linear_infill(flawed, suspect) if suspect.any() else flawed
            given = np.where(hidden[:, None, None], infill, flawed)
            for key, value in (("clean", crop), ("flawed", flawed), ("given", given), ("infill", infill)):
                put_crop(out[key], b, value, 0.0)
            out["valid"][b, :m] = True
            out["suspect"][b, :m] = suspect
            out["hidden"][b, :m] = hidden
            out["flaw_target"][b, :m] = disp_cm > FLAW_LABEL_CM
            out["label_mask"][b, :m] = ~(touched & (disp_cm > IGNORE_BELOW_CM) & (disp_cm <= FLAW_LABEL_CM))
            out["anchor_target"][b, :m] = self.targets[i][start : start + m]
            drop = rng.random() < self.drop_action_probability
            out["action"][b] = self.n_actions if drop else self.actions[i]
        return to_device(out, device)

    @staticmethod
    def _suspect(flawed: np.ndarray, rng) -> np.ndarray:
        """An imperfect detector's output: the flaw frames dilated by 0-3 frames, sometimes with a false alarm;
        in 15 % of the items every frame is suspect (so the repair network's correction of a whole clip
        tells where it sees flaws)."""
        if rng.random() < 0.15:
            return np.ones_like(flawed)
        s = flawed.copy()
        r = int(rng.integers(0, 4))
        if r and s.any():
            s = binary_dilation(s, iterations=r)
        if rng.random() < 0.3 and len(s) > 6:
            a = int(rng.integers(0, len(s) - 3))
            s[a : a + int(rng.integers(3, 13))] = True
        return s
