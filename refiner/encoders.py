"""Shared networks: the transformer motion encoder of Fig. 3-a-2 and a small MLP (appendix A).

The motion encoder linearly embeds each frame, adds sinusoidal positions, runs a transformer
encoder, then retrieves per-frame features from a transformer decoder whose queries are the
positional encodings. The concept encoder, bias encoder and transformer of the transition
refinement module "have the same structure", so they are instances of this class too.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from einops import rearrange
from torch import nn

__all__ = ["MotionEncoderConfig", "MotionEncoder", "MLP", "sinusoidal_positions", "mpjpe"]


def sinusoidal_positions(n_positions: int, dim: int) -> torch.Tensor:
    """``(n_positions, dim)`` sinusoidal encodings (Vaswani et al.)."""
    pos = torch.arange(n_positions, dtype=torch.float32)[:, None]
    freq = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(10000.0) / dim))
    pe = torch.zeros(n_positions, dim)
    pe[:, 0::2] = torch.sin(pos * freq)
    pe[:, 1::2] = torch.cos(pos * freq[: dim // 2])
    return pe


def mpjpe(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean per-joint position error.

    ``pred``, ``target``: ``(..., J, 3)``; ``mask``: boolean ``(...)``, True = count this frame.
    """
    err = torch.linalg.vector_norm(pred - target, dim=-1).mean(-1)
    if mask is None:
        return err.mean()
    mask = mask.to(err.dtype)
    return (err * mask).sum() / mask.sum().clamp_min(1.0)


@dataclass
class MotionEncoderConfig:
    """Sizes of a :class:`MotionEncoder` (appendix A: 2 blocks, 4 heads, FFN 128)."""

    input_dim: int = 72
    d_model: int = 128
    n_layers: int = 2
    n_heads: int = 4
    ffn_dim: int = 128
    dropout: float = 0.1
    max_len: int = 512

    def to_dict(self) -> dict:
        return asdict(self)


class MotionEncoder(nn.Module):
    """Per-frame features of a motion: ``(B, T, input_dim) -> (B, T, d_model)``.

    A boolean ``keep`` mask ``(B, T)`` (True = visible) replaces hidden frames by a learned mask
    token before the transformer (anchor refinement masks the flawed anchor this way); ``valid``
    ``(B, T)`` marks real (not padded) frames.
    """

    def __init__(self, config: MotionEncoderConfig):
        super().__init__()
        self.config = config
        c = config
        self.embed = nn.Linear(c.input_dim, c.d_model)
        self.mask_token = nn.Parameter(torch.zeros(c.d_model))
        self.register_buffer("positions", sinusoidal_positions(c.max_len, c.d_model), persistent=False)
        self.encoder = nn.TransformerEncoder(
            nn.TransformerEncoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True),
            c.n_layers, enable_nested_tensor=False,
        )
        self.decoder = nn.TransformerDecoder(
            nn.TransformerDecoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True), c.n_layers
        )

    def forward(self, x: torch.Tensor, keep: torch.Tensor | None = None, valid: torch.Tensor | None = None,
                extra: torch.Tensor | None = None) -> torch.Tensor:
        """``x (B, T, input_dim)``, optional ``extra (B, d_model)`` added to every frame -> ``(B, T, d_model)``."""
        n_frames = x.shape[1]
        h = self.embed(x)
        if keep is not None:
            h = torch.where(keep[..., None], h, self.mask_token.expand_as(h))
        pos = self.positions[:n_frames][None]
        h = h + pos
        if extra is not None:
            h = h + extra[:, None]
        pad = None if valid is None else ~valid
        memory = self.encoder(h, src_key_padding_mask=pad)
        queries = pos.expand(x.shape[0], -1, -1)
        return self.decoder(queries, memory, tgt_key_padding_mask=pad, memory_key_padding_mask=pad)


class MLP(nn.Module):
    """Three-layer perceptron (appendix A: embedding dimension 128)."""

    def __init__(self, in_dim: int, out_dim: int, hidden: int = 128, n_layers: int = 3):
        super().__init__()
        dims = [in_dim] + [hidden] * (n_layers - 1)
        layers: list[nn.Module] = []
        for a, b in zip(dims[:-1], dims[1:]):
            layers += [nn.Linear(a, b), nn.GELU()]
        layers.append(nn.Linear(dims[-1], out_dim))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


def flatten_joints(x: torch.Tensor) -> torch.Tensor:
    """``(B, T, J, 3) -> (B, T, J*3)``."""
    return rearrange(x, "b t j c -> b t (j c)")
