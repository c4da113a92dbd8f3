"""Denoising of flagged frames: a temporal convolution network that corrects the frames it is given.

The repair network (:class:`~refiner.refinement.learned_refinement.FlawRepairer`) squeezes a whole
pose, its velocity and an in-fill into one 128-wide transformer token per frame; given the true
flaw frames it removed 2 % of the benchmark's flaws and made jitter worse. Small flaws (noise,
drifting joints, a limb a few centimetres off) are better served by a network with a short-range
bias that sees each joint's position, velocity and acceleration at their own scale and only
*adds a correction* to the frames marked suspect: :class:`FlawDenoiserNet`, dilated residual
1-D convolutions (receptive field about 3.5 s at 20 fps) over standardised per-frame features.

It is action-agnostic (it serves unknown actions and any skeleton) and trained, like the other
learned steps, on real clips with the synthetic training flaws of
:mod:`refiner.refinement.training_flaws` and the imperfect suspect masks of
:class:`~refiner.refinement.flaw_training.FlawBatches` (never hidden frames: it only denoises).
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from refiner.core.signal import run_peak
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule, fit_network, resolve_device, seeded
from refiner.refinement.flaw_training import FlawBatches

__all__ = ["FlawDenoiser", "FlawDenoiserNet", "CorrectionNetworkComponent", "denoiser_features", "corrected_frames_loss", "checked_batch",
           "DENOISE_KINDS"]

#: Training mechanisms by default: the small flaws a correction of the given frames can undo (noise,
#: drifting or offset joints, stretched bones); a wrong pose or a stall needs the context instead, and
#: trained on all mechanisms the network learned average corrections that made jitter worse.
DENOISE_KINDS = ("white_noise", "burst", "low_freq", "limb_offset", "limb_drift", "bone_stretch")
#: The network's correction is in centimetres (its output layer works at the scale of the flaws).
_OUTPUT_SCALE = 0.01


def denoiser_features(x: torch.Tensor, suspect: torch.Tensor, root: int = 0) -> torch.Tensor:
    """Per-frame input ``(B, T, 9J + 4)`` of joints ``(B, T, J, 3)`` metres and ``suspect (B, T)`` bool.

    Root-relative pose, root path from the first frame, central velocity (x 10, metres per frame)
    and acceleration (x 100) of every joint, and the suspect flag; edges repeat the nearest value.
    """
    r = x[:, :, root : root + 1]
    padded = torch.cat([x[:, :1], x, x[:, -1:]], 1)
    vel = (padded[:, 2:] - padded[:, :-2]) * 5.0
    acc = (padded[:, 2:] - 2 * x + padded[:, :-2]) * 100.0
    flat = [rearrange(v, "b t j c -> b t (j c)") for v in (x - r, vel, acc)]
    return torch.cat([flat[0], r[:, :, 0] - r[:, :1, 0], flat[1], flat[2], suspect[..., None].float()], -1)


def corrected_frames_loss(pred: torch.Tensor, clean: torch.Tensor, frames: torch.Tensor, valid: torch.Tensor,
                          velocity_weight: float) -> torch.Tensor:
    """Mean joint error (metres) of ``pred`` against ``clean`` (both ``(B, T, J, 3)``) on the ``frames (B, T)``
    the network corrects, plus ``velocity_weight`` times the velocity error on the steps that touch them;
    ``valid (B, T)`` marks real (not padded) frames."""
    w = (valid & frames).float()
    err = torch.linalg.vector_norm(pred - clean, dim=-1).mean(-1)
    loss = (err * w).sum() / w.sum().clamp_min(1.0)
    vel = torch.linalg.vector_norm(torch.diff(pred, dim=1) - torch.diff(clean, dim=1), dim=-1).mean(-1)
    vw = (w[:, 1:] + w[:, :-1]).clamp_max(1.0) * (valid[:, 1:] & valid[:, :-1]).float()
    return loss + velocity_weight * (vel * vw).sum() / vw.sum().clamp_min(1.0)


def checked_batch(joints, mask, n_joints: int, mask_name: str) -> tuple[np.ndarray, np.ndarray]:
    """Copies of ``joints (B, T, J, 3)`` as float32 and ``mask (B, T)`` as bool, or a ``ValueError`` naming
    what is wrong (shapes, NaN / Inf)."""
    given = np.array(joints, np.float32, copy=True)
    mask = np.array(mask, bool, copy=True)
    if given.ndim != 4 or given.shape[2:] != (n_joints, 3):
        raise ValueError(f"`joints` must be (B, T, {n_joints}, 3); got shape {given.shape}.")
    if mask.shape != given.shape[:2]:
        raise ValueError(f"`{mask_name}` must be (B, T) = {given.shape[:2]}; got shape {mask.shape}.")
    if not np.isfinite(given).all():
        raise ValueError("`joints` must be finite; got NaN or Inf.")
    return given, mask


class FlawDenoiserNet(nn.Module):
    """``x (B, T, J, 3)`` metres, ``suspect (B, T)`` bool -> corrected ``(B, T, J, 3)``: the given frames
    plus a learned correction on the suspect ones (zero at initialisation: an untrained network is the
    identity). ``mean, scale (9J + 4,)`` standardise :func:`denoiser_features`."""

    def __init__(self, n_joints: int, hidden: int = 128, n_layers: int = 6, kernel: int = 5, root: int = 0):
        super().__init__()
        n_in = 9 * n_joints + 4
        self.root = root
        self.register_buffer("mean", torch.zeros(n_in))
        self.register_buffer("scale", torch.ones(n_in))
        self.inp = nn.Conv1d(n_in, hidden, 1)
        dilations = [2 ** (i % 4) for i in range(n_layers)]
        self.blocks = nn.ModuleList(nn.Conv1d(hidden, hidden, kernel, dilation=d, padding=(kernel // 2) * d)
                                    for d in dilations)
        self.mix = nn.ModuleList(nn.Conv1d(hidden, hidden, 1) for _ in dilations)
        self.norms = nn.ModuleList(nn.GroupNorm(1, hidden) for _ in dilations)
        self.out = nn.Conv1d(hidden, 3 * n_joints, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    @torch.no_grad()
    def standardise(self, x: torch.Tensor, suspect: torch.Tensor, valid: torch.Tensor) -> None:
        """Set ``mean`` and ``scale`` from a batch of inputs ``x (B, T, J, 3)``, ``suspect`` and ``valid (B, T)``."""
        feats = denoiser_features(x, suspect, self.root)[valid]
        self.mean.copy_(feats.mean(0))
        self.scale.copy_(feats.std(0).clamp_min(1e-3))

    def forward(self, x: torch.Tensor, suspect: torch.Tensor) -> torch.Tensor:
        feats = (denoiser_features(x, suspect, self.root) - self.mean) / self.scale
        h = self.inp(feats.transpose(1, 2))
        for conv, mix, norm in zip(self.blocks, self.mix, self.norms):
            h = h + mix(F.gelu(conv(norm(h))))
        delta = rearrange(self.out(h), "b (j c) t -> b t j c", c=3) * _OUTPUT_SCALE
        return x + delta * suspect[..., None, None].to(x.dtype)


class CorrectionNetworkComponent(NetworkComponent):
    """What the two estimators built on :class:`FlawDenoiserNet` share (this denoiser and the motion
    in-filler of :mod:`refiner.refinement.infilling`): the network from the fitted skeleton and joint count,
    and its training on a batch source whose ``inputs`` frames are corrected where ``mask`` is set.
    Subclasses set ``hidden``, ``n_layers``, ``kernel``, ``velocity_weight`` and ``schedule`` and define
    ``_loss``."""

    def _make_network(self, fitted: dict) -> FlawDenoiserNet:
        root = get_skeleton(fitted["skeleton_"]).root
        return FlawDenoiserNet(fitted["n_joints_"], self.hidden, self.n_layers, self.kernel, root)

    def _train(self, batches, val, inputs: str, mask: str, rng, checkpoint, desc: str) -> None:
        """Build ``network_``, standardise its features on a sample of ``batches`` and train it (best weights
        by the loss on ``val.validation_batch``); ``batches`` and ``val`` have ``sample`` / ``validation_batch``."""
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        with seeded(rng):
            self.network_ = self._make_network({"skeleton_": self.skeleton_, "n_joints_": self.n_joints_})
            stats = batches.sample(rng.choice(len(batches), size=min(256, len(batches))), np.random.default_rng(1))
            self.network_.standardise(stats[inputs], stats[mask], stats["valid"])
            self.network_.to(device)
            self.history_ = fit_network(self.network_, self._loss, lambda idx, r: batches.sample(idx, r, device),
                                        len(batches), val.validation_batch(device), schedule, rng,
                                        checkpoint=checkpoint, desc=desc)
        self.network_.to("cpu").eval()


class FlawDenoiser(CorrectionNetworkComponent):
    """Corrects suspect frames from the frames themselves and their context (see the module docstring).

    Parameters
    ----------
    hidden, n_layers, kernel : network sizes
    window : int, default=64
        Training crop length (inference takes any length: the network is convolutional).
    kinds : sequence of str, default=DENOISE_KINDS
        Training flaw mechanisms (:data:`refiner.refinement.training_flaws.MECHANISMS`).
    velocity_weight : float, default=1.0
        Weight of the velocity error beside the position error (both on suspect frames, metres).
    rigid_tolerance : float or None, default=0.005
        Training crops whose bones vary more than this are put on rigid bones after their flaws, as
        the refiner shows clips to its repairs (None: raw flawed crops, as before this parameter).
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=60, batch_size=64, learning_rate=1e-3, patience=60, steps_per_epoch=100)
        6,000 steps: about 20 minutes on one CPU core.
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : FlawDenoiserNet
    skeleton_ : str
    threshold_ : float
        Metres: a frame whose :meth:`correction` exceeds it is flagged (``detect="...+denoiser"``; set by
        :meth:`calibrate`, infinite until then).
    history_ : list of dict
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "threshold_", "history_")

    def __init__(self, *, hidden: int = 128, n_layers: int = 6, kernel: int = 5, window: int = 64,
                 kinds: tuple = DENOISE_KINDS, velocity_weight: float = 1.0, rigid_tolerance: float | None = 0.005,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=60, batch_size=64, learning_rate=1e-3, patience=60,
                                                         steps_per_epoch=100),
                 random_state: int | None = 0):
        self.hidden = hidden
        self.n_layers = n_layers
        self.kernel = kernel
        self.window = window
        self.kinds = kinds
        self.velocity_weight = velocity_weight
        self.rigid_tolerance = rigid_tolerance
        self.schedule = schedule
        self.random_state = random_state

    def fit(self, clips, *, skeleton: str = "humanact12", validation=None, checkpoint=None) -> "FlawDenoiser":
        """Train on real clips ``(T_i, J, 3)`` metres with synthetic flaws; ``validation``: held-out clips."""
        rng = check_random_state(self.random_state)
        clips = [np.asarray(c, np.float32) for c in clips]
        self.skeleton_ = get_skeleton(skeleton).name
        self.n_joints_ = int(clips[0].shape[1])
        self.threshold_ = float("inf")
        batches = FlawBatches(clips, None, None, skeleton=self.skeleton_, lengths=(32, self.window),
                              kinds=list(self.kinds), hide_probability=0.0, n_actions=1,
                              rigid_tolerance=self.rigid_tolerance)
        held = clips if validation is None else [np.asarray(c, np.float32) for c in validation]
        val = FlawBatches(held, None, None, skeleton=self.skeleton_, lengths=(self.window, self.window),
                          kinds=list(self.kinds), hide_probability=0.0, n_actions=1,
                          rigid_tolerance=self.rigid_tolerance)
        self._train(batches, val, "flawed", "suspect", rng, checkpoint, "flaw denoiser")
        return self

    def _loss(self, net, batch, rng) -> torch.Tensor:
        pred = net(batch["flawed"], batch["suspect"])
        return corrected_frames_loss(pred, batch["clean"], batch["suspect"], batch["valid"], self.velocity_weight)

    @torch.no_grad()
    def denoise(self, joints: np.ndarray, suspect: np.ndarray) -> np.ndarray:
        """Corrected joints ``(B, T, J, 3)`` float32 for a batch ``(B, T, J, 3)`` metres and ``suspect (B, T)``
        bool, in one forward pass; frames not suspect come back unchanged."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        given, mask = checked_batch(joints, suspect, self.n_joints_, "suspect")
        out = self.network_(torch.from_numpy(given).to(self.device_), torch.from_numpy(mask).to(self.device_))
        out = out.cpu().numpy()
        out[~mask] = given[~mask]
        return out

    def correction(self, joints: np.ndarray) -> np.ndarray:
        """``(B, T)`` metres: how far the network moves each frame (mean over joints) when every frame is
        suspect. Trained to leave clean frames alone, it moves drifting and noisy ones: a flaw detector
        (on the benchmark's drifting anchors, ROC AUC 0.99 where the flaw classifier has 0.63)."""
        x = np.asarray(joints, np.float32)
        return np.linalg.norm(self.denoise(x, np.ones(x.shape[:2], bool)) - x, axis=-1).mean(-1)

    def calibrate(self, clips, *, clip_rate: float = 0.05, min_run: int = 2) -> float:
        """Set ``threshold_`` (metres) so that at most ``clip_rate`` of these clean clips (held-out subjects)
        have a run of ``min_run`` frames whose :meth:`correction` exceeds it; returns it."""
        peaks = [run_peak(self.correction(np.asarray(c, np.float32)[None])[0], min_run) for c in clips]
        self.threshold_ = float(np.quantile(peaks, 1 - clip_rate))
        return self.threshold_
