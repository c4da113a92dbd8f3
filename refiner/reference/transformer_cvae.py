"""The ACTOR-style reference generator ``"actor"``: a transformer CVAE emitting joint positions.

Follows ACTOR (Petrovich et al. 2021): per-action distribution tokens in the encoder and time
queries in the decoder. Its output, joint positions, is converted by the ``action2motion`` adapter's
``representation="xyz"`` path (passed through and re-centred).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from einops import rearrange
from torch import nn

from refiner.nn.layers import sinusoidal_positions
from refiner.nn.training import TrainSchedule
from refiner.reference.base import N_FRAMES, JointsGenerator, normal_noise

__all__ = ["TransformerCVAE", "TransformerCVAEConfig", "TransformerCVAEGenerator"]


@dataclass
class TransformerCVAEConfig:
    """Sizes of a :class:`TransformerCVAE` (ACTOR uses d_model 256 and 8 layers; ours is small)."""

    n_actions: int = 12
    n_joints: int = 24
    d_model: int = 128
    n_layers: int = 2
    n_heads: int = 4
    ffn_dim: int = 256
    dropout: float = 0.1
    max_len: int = 64


class TransformerCVAE(nn.Module):
    """ACTOR's transformer CVAE on normalised joint positions.

    Encoder: ``[mu_token[a], sigma_token[a], frames + positions]`` through a transformer encoder;
    linear heads on the first two outputs give ``mu`` and ``logvar`` (latent size = ``d_model``). Decoder: time
    queries attend to the single memory token ``z + action_bias[a]``. Unlike ACTOR the queries are
    the sinusoidal positions *plus* that token, and the layers are pre-norm: with ACTOR's
    position-only queries and post-norm layers our small model ignored the action within a CPU
    training budget (recogniser accuracy of its samples at chance).
    """

    def __init__(self, config: TransformerCVAEConfig):
        super().__init__()
        self.config = config
        c = config
        self.embed = nn.Linear(c.n_joints * 3, c.d_model)
        # Unit-scale action parameters, as ACTOR: at 0.02 the action is lost beside z ~ N(0, I).
        self.mu_token = nn.Parameter(torch.randn(c.n_actions, c.d_model))
        self.sigma_token = nn.Parameter(torch.randn(c.n_actions, c.d_model))
        self.action_bias = nn.Parameter(torch.randn(c.n_actions, c.d_model))
        self.register_buffer("positions", sinusoidal_positions(c.max_len + 2, c.d_model), persistent=False)
        self.encoder = nn.TransformerEncoder(
            nn.TransformerEncoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True, norm_first=True),
            c.n_layers, norm=nn.LayerNorm(c.d_model), enable_nested_tensor=False,
        )
        self.decoder = nn.TransformerDecoder(
            nn.TransformerDecoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True, norm_first=True),
            c.n_layers, norm=nn.LayerNorm(c.d_model),
        )
        self.mu_head = nn.Linear(c.d_model, c.d_model)
        self.logvar_head = nn.Linear(c.d_model, c.d_model)
        # Start from a narrow posterior: Adam moves a bias by about the learning rate per step, so
        # from logvar 0 it takes thousands of steps to get there, and until then z is mostly noise.
        nn.init.constant_(self.logvar_head.bias, -4.0)
        self.head = nn.Linear(c.d_model, c.n_joints * 3)

    def encode(self, x: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x (B, T, J, 3)`` normalised joints, ``actions (B,)`` -> ``mu, logvar (B, d_model)``."""
        h = self.embed(rearrange(x, "b t j c -> b t (j c)"))
        tokens = torch.cat([self.mu_token[actions][:, None], self.sigma_token[actions][:, None], h], 1)
        out = self.encoder(tokens + self.positions[: tokens.shape[1]][None])
        return self.mu_head(out[:, 0]), self.logvar_head(out[:, 1]).clamp(-10, 10)

    def decode(self, z: torch.Tensor, actions: torch.Tensor, n_frames: int) -> torch.Tensor:
        """``z (B, d_model)``, ``actions (B,)`` -> normalised joints ``(B, T, J, 3)``."""
        memory = (z + self.action_bias[actions])[:, None]
        # ACTOR's queries are the positions alone; adding the condition to every query as well
        # made a small model fit in a CPU budget (with positions alone it ignored the action).
        queries = self.positions[:n_frames][None] + memory
        out = self.head(self.decoder(queries, memory))
        return rearrange(out, "b t (j c) -> b t j c", c=3)

    def forward(self, x: torch.Tensor, actions: torch.Tensor, noise: torch.Tensor):
        """``x (B, T, J, 3)``, ``actions (B,)``, ``noise (B, d_model)`` -> reconstruction, mu, logvar."""
        mu, logvar = self.encode(x, actions)
        z = mu + noise * torch.exp(0.5 * logvar)
        return self.decode(z, actions, x.shape[1]), mu, logvar


class TransformerCVAEGenerator(JointsGenerator):
    """ACTOR-style transformer CVAE emitting joint positions ``(N, 60, 24, 3)``.

    Joints are standardised per coordinate with the training crops' mean and standard deviation.
    The loss is the MSE of the standardised joints plus ``velocity_weight`` times the MSE of
    their frame differences plus ``kl_weight`` times the KL divergence to N(0, I) (summed over
    latent dimensions).

    Parameters
    ----------
    d_model : int, default=64
    n_layers : int, default=2
        Encoder and decoder layers each.
    n_heads : int, default=4
    ffn_dim : int, default=128
    dropout : float, default=0.0
    kl_weight : float, default=1e-2
        Weaker KL let the latent carry the action, so samples from the prior lost it (recogniser
        accuracy 29 % at 1e-3 against 42 % at 1e-2 in 150 s trials).
    velocity_weight : float, default=1.0
    n_frames : int, default=60
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=150, batch_size=64, learning_rate=1e-3, patience=40)
    random_state : int or None, default=0
    warm_start : bool, default=False
        When fitted already, :meth:`fit` goes on training the fitted network (a fresh ``schedule``)
        instead of starting anew; ``history_`` and ``train_seconds_`` then add up.

    Attributes
    ----------
    network_ : TransformerCVAE
    action_names_ : list of str
    mean_, std_ : ndarray of shape (24, 3), float32
        Standardisation of the joints (metres).
    history_ : list of dict
    train_seconds_ : float
    """

    _fitted_attributes = ("action_names_", "history_", "train_seconds_")
    _desc = "actor transformer CVAE"

    def __init__(self, d_model: int = 64, *, n_layers: int = 2, n_heads: int = 4, ffn_dim: int = 128, dropout: float = 0.0,
                 kl_weight: float = 1e-2, velocity_weight: float = 1.0, n_frames: int = N_FRAMES,
                 action_names: Sequence[str] | None = None,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=150, batch_size=64, learning_rate=1e-3, patience=40),
                 random_state: int | None = 0, warm_start: bool = False):
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.dropout = dropout
        self.kl_weight = kl_weight
        self.velocity_weight = velocity_weight
        self.n_frames = n_frames
        self.action_names = action_names
        self.schedule = schedule
        self.random_state = random_state
        self.warm_start = warm_start

    def _make_network(self, fitted: dict) -> TransformerCVAE:
        return TransformerCVAE(TransformerCVAEConfig(len(fitted["action_names_"]), 24, self.d_model, self.n_layers,
                                                     self.n_heads, self.ffn_dim, self.dropout, max(self.n_frames, 2)))

    def _batch(self, crops: dict, actions: torch.Tensor, device) -> dict:
        return {"x": self._normalised(crops, device), "actions": actions}

    def _loss(self, net: TransformerCVAE, batch: dict, rng) -> torch.Tensor:
        x, actions = batch["x"], batch["actions"]
        recon, mu, logvar = net(x, actions, normal_noise(rng, (len(x), net.config.d_model), x))
        kl = -0.5 * (1 + logvar - mu**2 - logvar.exp()).sum(-1).mean()
        vel = nn.functional.mse_loss(recon[:, 1:] - recon[:, :-1], x[:, 1:] - x[:, :-1])
        return nn.functional.mse_loss(recon, x) + self.velocity_weight * vel + self.kl_weight * kl

    def _draw(self, net: TransformerCVAE, actions: torch.Tensor, rng: np.random.Generator) -> np.ndarray:
        """Samples from the prior N(0, I), ``(n, n_frames, 24, 3)`` float32: joint positions in metres,
        HumanAct12's y-down frame, first-frame root near the origin."""
        z = normal_noise(rng, (len(actions), net.config.d_model), actions)
        x = net.decode(z, actions, self.n_frames).cpu().numpy()
        return self._metres(x)
