"""An MDM-style action-conditioned diffusion generator: a transformer denoiser that predicts the clean motion.

Following MDM (Tevet et al. 2023): the network sees the noised clip ``x_t`` (normalised joint positions,
one token per frame) after one conditioning token (timestep embedding + action embedding), and
predicts the clean clip ``x_0``; training drops the action to a *null* token with probability
``cond_dropout`` so that sampling can use classifier-free guidance
(``x0 = x0(null) + guidance * (x0(action) - x0(null))``). The noise schedule is the cosine one over
``diffusion_steps`` steps; sampling is deterministic DDIM over ``sampling_steps`` of them (the first
noise from the seeded numpy stream). The loss is MSE on ``x_0`` plus ``velocity_weight`` times MSE on
its frame-to-frame differences (MDM's velocity term). Its output, joint positions, is converted by the
``action2motion`` adapter's ``representation="xyz"`` path, like the transformer CVAE's.

Shipped as ``mdm``: 35 minutes on two CPU threads (epoch 676 of 3,000), then 800 more epochs from those
weights (``warm_start``) with the learning rate decaying to 0 (about an hour on one thread); its figures
before and after: docs/decisions.md D13.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from torch import nn

from refiner.nn.layers import sinusoidal_positions
from refiner.nn.training import TrainSchedule
from refiner.reference.base import N_FRAMES, JointsGenerator, normal_noise

__all__ = ["MotionDenoiser", "MotionDenoiserConfig", "MotionDiffusionGenerator", "cosine_alpha_bars"]


def cosine_alpha_bars(n_steps: int) -> torch.Tensor:
    """``(n_steps,)`` cumulative signal shares of the cosine schedule (Nichol & Dhariwal), from ~1 down to ~0."""
    t = torch.arange(n_steps + 1, dtype=torch.float64) / n_steps
    f = torch.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2
    return (f[1:] / f[0]).clamp(1e-5, 1.0).float()


@dataclass
class MotionDenoiserConfig:
    """Sizes of a :class:`MotionDenoiser` (MDM: d_model 512, 8 layers; ours is small)."""

    n_actions: int = 12
    n_joints: int = 24
    d_model: int = 128
    n_layers: int = 4
    n_heads: int = 4
    ffn_dim: int = 256
    dropout: float = 0.1
    max_len: int = 64
    diffusion_steps: int = 100


class MotionDenoiser(nn.Module):
    """``(x_t (B, T, J*3), t (B,), action (B,)) -> x_0 (B, T, J*3)``; action ``n_actions`` is the null condition."""

    def __init__(self, config: MotionDenoiserConfig):
        super().__init__()
        self.config = c = config
        self.embed = nn.Linear(c.n_joints * 3, c.d_model)
        self.action = nn.Embedding(c.n_actions + 1, c.d_model)
        self.time = nn.Sequential(nn.Linear(c.d_model, c.d_model), nn.SiLU(), nn.Linear(c.d_model, c.d_model))
        self.register_buffer("positions", sinusoidal_positions(c.max_len + 1, c.d_model), persistent=False)
        self.register_buffer("steps", sinusoidal_positions(c.diffusion_steps, c.d_model), persistent=False)
        self.register_buffer("alpha_bars", cosine_alpha_bars(c.diffusion_steps), persistent=False)
        layer = nn.TransformerEncoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, c.n_layers, enable_nested_tensor=False)
        self.out = nn.Sequential(nn.LayerNorm(c.d_model), nn.Linear(c.d_model, c.n_joints * 3))

    def forward(self, x_t: torch.Tensor, t: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        cond = (self.time(self.steps[t]) + self.action(action))[:, None]
        h = torch.cat([cond, self.embed(x_t)], 1) + self.positions[: x_t.shape[1] + 1]
        return self.out(self.encoder(h)[:, 1:])

    def noised(self, x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """``x_t`` of the forward process: ``sqrt(a_t) x0 + sqrt(1 - a_t) noise``."""
        a = self.alpha_bars[t][:, None, None]
        return a.sqrt() * x0 + (1 - a).sqrt() * noise


class MotionDiffusionGenerator(JointsGenerator):
    """MDM-style diffusion generator of HumanAct12 joint positions (see the module docstring).

    Parameters
    ----------
    d_model, n_layers, n_heads, ffn_dim : int
        Denoiser sizes (:class:`MotionDenoiserConfig`).
    diffusion_steps : int, default=100
    sampling_steps : int, default=50
        DDIM steps at sampling (at most ``diffusion_steps``).
    guidance : float, default=2.5
        Classifier-free guidance scale (1: conditional model alone).
    cond_dropout : float, default=0.1
    velocity_weight : float, default=1.0
    n_frames : int, default=60
    action_names : sequence of str, optional
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=3000, batch_size=64, learning_rate=2e-4, patience=3000)
        No early stopping (the validation loss of random timesteps is noisy); the shipped weights stopped
        at the 2,100 s time limit (``--max-seconds``), epoch 676, and went on for 800 epochs of
        ``TrainSchedule(n_epochs=800, ...)`` (``train-generator --init ... --epochs 800``).
    random_state : int or None, default=0
    warm_start : bool, default=False
        When fitted already, :meth:`fit` goes on training the fitted network (a fresh ``schedule``)
        instead of starting anew; ``history_`` and ``train_seconds_`` then add up.

    Attributes
    ----------
    network_ : MotionDenoiser
    action_names_ : list of str
    mean_, std_ : ndarray (24, 3)
        Normalisation of the training crops (metres).
    history_ : list of dict
    train_seconds_ : float
    """

    _fitted_attributes = ("action_names_", "history_", "train_seconds_")
    _desc = "MDM-style diffusion"

    def __init__(self, d_model: int = 128, *, n_layers: int = 4, n_heads: int = 4, ffn_dim: int = 256,
                 diffusion_steps: int = 100, sampling_steps: int = 50, guidance: float = 2.5, cond_dropout: float = 0.1,
                 velocity_weight: float = 1.0, n_frames: int = N_FRAMES, action_names: Sequence[str] | None = None,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=3000, batch_size=64, learning_rate=2e-4, patience=3000),
                 random_state: int | None = 0, warm_start: bool = False):
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.diffusion_steps = diffusion_steps
        self.sampling_steps = sampling_steps
        self.guidance = guidance
        self.cond_dropout = cond_dropout
        self.velocity_weight = velocity_weight
        self.n_frames = n_frames
        self.action_names = action_names
        self.schedule = schedule
        self.random_state = random_state
        self.warm_start = warm_start

    def _make_network(self, fitted: dict) -> MotionDenoiser:
        if not 1 <= self.sampling_steps <= self.diffusion_steps:
            raise ValueError(f"`sampling_steps` must be in 1..diffusion_steps ({self.diffusion_steps}); "
                             f"got {self.sampling_steps!r}.")
        return MotionDenoiser(MotionDenoiserConfig(len(fitted["action_names_"]), 24, self.d_model, self.n_layers,
                                                   self.n_heads, self.ffn_dim, max_len=max(self.n_frames, 64),
                                                   diffusion_steps=self.diffusion_steps))

    def _batch(self, crops: dict, actions: torch.Tensor, device) -> dict:
        return {"x": self._normalised(crops, device).flatten(2), "actions": actions}

    def _loss(self, net: MotionDenoiser, batch: dict, rng) -> torch.Tensor:
        x0, actions = batch["x"], batch["actions"]
        t = torch.from_numpy(rng.integers(0, self.diffusion_steps, len(x0))).to(x0.device)
        drop = torch.from_numpy(rng.random(len(x0)) < self.cond_dropout).to(x0.device)
        cond = torch.where(drop, torch.full_like(actions, net.config.n_actions), actions)
        pred = net(net.noised(x0, t, normal_noise(rng, x0.shape, x0)), t, cond)
        vel = nn.functional.mse_loss(pred[:, 1:] - pred[:, :-1], x0[:, 1:] - x0[:, :-1])
        return nn.functional.mse_loss(pred, x0) + self.velocity_weight * vel

    def _draw(self, net: MotionDenoiser, actions: torch.Tensor, rng: np.random.Generator) -> np.ndarray:
        """DDIM samples with guidance, ``(n, n_frames, 24, 3)`` float32: joint positions in metres,
        HumanAct12's y-down frame, first-frame root near the origin."""
        n, dim = len(actions), net.config.n_joints * 3
        x = normal_noise(rng, (n, self.n_frames, dim), actions)
        both = torch.cat([torch.full_like(actions, net.config.n_actions), actions])  # unconditional, conditional
        times = np.linspace(self.diffusion_steps - 1, 0, self.sampling_steps).round().astype(np.int64)
        a_bars = net.alpha_bars
        for k, t in enumerate(times):
            tt = torch.full((2 * n,), int(t), dtype=torch.long, device=x.device)
            x0, cond = net(torch.cat([x, x]), tt, both).chunk(2)  # one forward pass for both halves of the guidance
            x0 = x0 + self.guidance * (cond - x0)
            a = a_bars[t]
            eps = (x - a.sqrt() * x0) / (1 - a).sqrt().clamp_min(1e-6)
            a_next = a_bars[times[k + 1]] if k + 1 < len(times) else torch.tensor(1.0, device=x.device)
            x = a_next.sqrt() * x0 + (1 - a_next).sqrt() * eps
        return self._metres(x.reshape(n, self.n_frames, net.config.n_joints, 3).cpu().numpy())
