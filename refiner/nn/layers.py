"""Small network building blocks shared by the concepts, the refinement steps and the reference generators."""
from __future__ import annotations

import math

import torch
from einops import rearrange
from torch import nn

__all__ = ["MLP", "sinusoidal_positions", "mpjpe", "flatten_joints"]


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
