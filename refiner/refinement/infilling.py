"""In-filling of frames from their context: the in-betweening half of transition refinement.

The repair network (:class:`~refiner.refinement.learned_refinement.FlawRepairer`) was meant to in-fill
hidden frames too, but it learned not to: on held-out clips its in-fill of a 15-frame gap differs
from linear interpolation by 0.004 cm (linear interpolation's error there: 9.2 cm), so the bench's
"repair network in-fills" oracle equals the linear one. :class:`MotionInfiller` is trained for this
one task: real clips with random gaps (4-30 frames, one or two per crop), the gap first filled by
linear interpolation, and the network (:class:`~refiner.refinement.flaw_denoiser.FlawDenoiserNet`,
dilated temporal convolutions that add a correction to the marked frames, zero at initialisation)
learns what the motion did instead. An untrained in-filler is linear interpolation, so training can
only move it from there, and its figures are always reported beside linear interpolation's.

Action-agnostic, any skeleton.
"""
from __future__ import annotations

import numpy as np
import torch

from refiner.core.signal import linear_infill
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED
from refiner.nn.training import TrainSchedule, crop_start, to_device
from refiner.refinement.flaw_denoiser import CorrectionNetworkComponent, checked_batch, corrected_frames_loss

__all__ = ["MotionInfiller", "GapBatches"]


class GapBatches:
    """Random crops ``(B, L, J, 3)`` of real clips with random gaps linearly in-filled.

    ``sample(indices, rng)`` -> ``given`` (gaps in-filled), ``clean``, ``gap (B, L)`` bool, ``valid (B, L)``.
    """

    def __init__(self, clips, *, length: int = 64, gap: tuple[int, int] = (4, 30)):
        self.clips = [np.asarray(c, np.float32) for c in clips]
        self.length = length
        self.gap = gap

    def __len__(self) -> int:
        return len(self.clips)

    def sample(self, indices, rng: np.random.Generator, device="cpu") -> dict[str, torch.Tensor]:
        n, length = len(indices), self.length
        n_joints = self.clips[0].shape[1]
        out = {k: np.zeros((n, length, n_joints, 3), np.float32) for k in ("given", "clean")}
        out["gap"] = np.zeros((n, length), bool)
        out["valid"] = np.zeros((n, length), bool)
        for b, i in enumerate(indices):
            clip = self.clips[i]
            start = crop_start(len(clip), length, rng)
            crop = clip[start : start + length]
            crop = crop - crop[:1, :1]
            m = len(crop)
            gap = np.zeros(m, bool)
            for _ in range(1 if rng.random() < 0.7 else 2):
                g = int(rng.integers(self.gap[0], min(self.gap[1], m - 2) + 1))
                a = int(rng.integers(1, m - g))  # the first and last frames stay as context
                gap[a : a + g] = True
            out["clean"][b, :m], out["given"][b, :m] = crop, linear_infill(crop, gap)
            out["clean"][b, m:], out["given"][b, m:] = crop[-1], crop[-1]
            out["gap"][b, :m], out["valid"][b, :m] = gap, True
        return to_device(out, device)

    def validation_batch(self, device="cpu", size: int = 256, seed: int = 12345) -> dict[str, torch.Tensor]:
        rng = np.random.default_rng(seed)
        return self.sample(rng.choice(len(self), size=size, replace=len(self) < size), rng, device)


class MotionInfiller(CorrectionNetworkComponent):
    """Frames in-filled from the clip around them (see the module docstring).

    Parameters
    ----------
    hidden, n_layers, kernel : network sizes (:class:`FlawDenoiserNet`)
    window : int, default=64
        Training crop length (inference takes any length: the network is convolutional).
    gap : (int, int), default=(4, 30)
        Range of training gap lengths, frames.
    velocity_weight : float, default=1.0
        Weight of the velocity error beside the position error (both on gap frames, metres).
    schedule : TrainSchedule
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : FlawDenoiserNet
    skeleton_ : str
    n_joints_ : int
    history_ : list of dict
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "history_")

    def __init__(self, *, hidden: int = 128, n_layers: int = 6, kernel: int = 5, window: int = 64,
                 gap: tuple[int, int] = (4, 30), velocity_weight: float = 1.0,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=80, batch_size=64, learning_rate=1e-3, patience=80,
                                                         steps_per_epoch=100),
                 random_state: int | None = 0):
        self.hidden = hidden
        self.n_layers = n_layers
        self.kernel = kernel
        self.window = window
        self.gap = gap
        self.velocity_weight = velocity_weight
        self.schedule = schedule
        self.random_state = random_state

    def fit(self, clips, *, skeleton: str = "humanact12", validation=None, checkpoint=None) -> "MotionInfiller":
        """Train on real clips ``(T_i, J, 3)`` metres; ``validation``: clips of held-out subjects."""
        rng = check_random_state(self.random_state)
        clips = [np.asarray(c, np.float32) for c in clips]
        self.skeleton_ = get_skeleton(skeleton).name
        self.n_joints_ = int(clips[0].shape[1])
        gap = tuple(int(g) for g in self.gap)
        batches = GapBatches(clips, length=self.window, gap=gap)
        val = GapBatches(clips if validation is None else validation, length=self.window, gap=gap)
        self._train(batches, val, "given", "gap", rng, checkpoint, "motion infiller")
        return self

    def _loss(self, net, batch, rng) -> torch.Tensor:
        pred = net(batch["given"], batch["gap"])
        return corrected_frames_loss(pred, batch["clean"], batch["gap"], batch["valid"], self.velocity_weight)

    @torch.no_grad()
    def infill(self, joints: np.ndarray, gap: np.ndarray) -> np.ndarray:
        """Joints ``(B, T, J, 3)`` float32 with the ``gap (B, T)`` frames in-filled from the others; frames
        outside the gaps come back unchanged, and so does a clip with no frame outside its gap (nothing to
        in-fill from, as :func:`~refiner.core.signal.linear_infill`). One forward pass for the batch."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        given, mask = checked_batch(joints, gap, self.n_joints_, "gap")
        mask[mask.all(1)] = False
        lin = np.stack([linear_infill(c, g) if g.any() else c for c, g in zip(given, mask)])
        out = self.network_(torch.from_numpy(lin).to(self.device_), torch.from_numpy(mask).to(self.device_))
        out = out.cpu().numpy()
        out[~mask] = given[~mask]
        return out
