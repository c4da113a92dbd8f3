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
from refiner.core.skeletons import rigid_skeleton
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
    rigid_tolerance : float or None
        Flawed crops whose bones vary more than this are put on rigid bones after their flaws
        (:func:`refiner.core.skeletons.rigid_skeleton`), as the refiner shows clips to its steps; the labels
        are what is left of the flaw (None: raw flawed crops).
    """

    def __init__(self, clips: Sequence[np.ndarray], actions, anchors, *, skeleton: str = "humanact12",
                 lengths: tuple[int, int] = (32, 64), kinds=None, hide_probability: float = 0.3,
                 drop_action_probability: float = 0.2, n_actions: int | None = None,
                 rigid_tolerance: float | None = None):
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
        self.rigid_tolerance = rigid_tolerance

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
        crops, flaws = [], []
        for i in indices:
            clip = self.clips[i]
            start = crop_start(len(clip), length, rng)
            crop = clip[start : start + length]
            crops.append((crop - crop[:1, :1], start))
            donor = self.clips[int(rng.integers(len(self.clips)))]
            flaws.append(synthesize(crops[-1][0], rng, skeleton=self.skeleton, kinds=self.kinds, donors=[donor])
                         if len(crop) >= 8 else None)
        flawed_all = [c if f is None else f.joints for (c, _), f in zip(crops, flaws)]
        if self.rigid_tolerance is not None:
            flawed_all = self._rigid(flawed_all, length)
        for b, i in enumerate(indices):
            (crop, start), flaw, flawed = crops[b], flaws[b], flawed_all[b]
            m = len(crop)
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

    def _rigid(self, flawed: list, length: int) -> list:
        """The flawed crops on rigid bones: the full-length ones in one batched projection."""
        full = [k for k, f in enumerate(flawed) if len(f) == length]
        out = list(flawed)
        if full:
            rigid, _ = rigid_skeleton(np.stack([flawed[k] for k in full]), self.skeleton, self.rigid_tolerance)
            for k, r in zip(full, rigid):
                out[k] = r.astype(np.float32)
        for k, f in enumerate(flawed):
            if len(f) != length and len(f) >= 2:
                out[k] = rigid_skeleton(f, self.skeleton, self.rigid_tolerance)[0].astype(np.float32)
        return out

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
