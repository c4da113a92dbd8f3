"""The motion model's network: a dilated temporal convolution over rigid motion that says, per frame and per part
(each bone, and the root), how likely it is flawed, and what the clean motion is (in-filling what the mask hides)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

__all__ = ["MotionNetConfig", "MotionNet"]


@dataclass(frozen=True)
class MotionNetConfig:
    """Sizes of :class:`MotionNet`; ``n_parts`` = bones + 1 (the root), ``n_features`` = 3 per bone + 3 (root velocity);
    ``differences``: the features' frame-to-frame change is an input too; ``n_context``: input-only channels (heights
    above the ground, foot speeds) that are not reconstructed."""

    n_bones: int
    n_actions: int
    width: int = 128
    dilations: tuple = (1, 2, 4, 8, 1, 2, 4, 1)
    kernel: int = 3
    differences: bool = True
    n_context: int = 0

    @property
    def n_parts(self) -> int:
        return self.n_bones + 1

    @property
    def n_features(self) -> int:
        return 3 * self.n_bones + 3

    def to_dict(self) -> dict:
        return {**asdict(self), "dilations": list(self.dilations)}

    @classmethod
    def from_dict(cls, d: dict) -> "MotionNetConfig":
        return cls(**{**d, "dilations": tuple(d["dilations"])})


class _Block(nn.Module):
    """Pre-norm residual block: GroupNorm, GELU, dilated convolution, twice."""

    def __init__(self, width: int, kernel: int, dilation: int):
        super().__init__()
        pad = dilation * (kernel - 1) // 2
        self.net = nn.Sequential(nn.GroupNorm(8, width), nn.GELU(), nn.Conv1d(width, width, kernel, padding=pad, dilation=dilation),
                                 nn.GroupNorm(8, width), nn.GELU(), nn.Conv1d(width, width, kernel, padding=pad, dilation=dilation))

    def forward(self, h):
        return h + self.net(h)


class MotionNet(nn.Module):
    """``features (N, T, F + n_context)``, ``hidden (N, T, P)`` bool mask of the parts hidden (their features linearly in-filled, to be corrected),
    ``action (N,)`` long (``n_actions`` = unknown) -> ``clean (N, T, F)`` features, ``flaw_logits (N, T, P)``."""

    def __init__(self, config: MotionNetConfig):
        super().__init__()
        self.config = c = config
        self.inp = nn.Conv1d((c.n_features + c.n_context) * (2 if c.differences else 1) + c.n_parts, c.width, 1)
        self.action = nn.Embedding(c.n_actions + 1, c.width)
        self.blocks = nn.Sequential(*[_Block(c.width, c.kernel, d) for d in c.dilations])
        self.out = nn.Sequential(nn.GroupNorm(8, c.width), nn.GELU(), nn.Conv1d(c.width, c.n_features + c.n_parts, 1))

    def forward(self, features, hidden, action):
        c = self.config
        parts = [features]
        if c.differences:  # frame-to-frame change, where holds, jumps and jitter show at once
            parts.append(torch.diff(features, dim=1, prepend=features[:, :1]))
        x = torch.cat([*parts, hidden.float()], -1).transpose(1, 2)
        h = self.inp(x) + self.action(action)[:, :, None]
        y = self.out(self.blocks(h)).transpose(1, 2)
        return features[..., :c.n_features] + y[..., :c.n_features], y[..., c.n_features:]
