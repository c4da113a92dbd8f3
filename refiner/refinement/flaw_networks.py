"""The two networks of learned refinement: :class:`FlawRecognitionNet` and :class:`FlawRepairNet`.

Both read the same per-frame features (:func:`frame_features`): root-relative pose, root path and
the velocity of every joint, because timing flaws (a stall, a warp) change velocities far more
than poses. Both are conditioned on the action through an embedding with one extra *unknown*
entry (index ``n_actions``), trained by dropping the action at random, so an unknown or foreign
action is a first-class input. The repair network also attends to the action's anchor concepts
(K-means centres, §3.1.2) as extra tokens, so in-filled frames are pulled toward poses the action
really takes.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from einops import rearrange
from torch import nn

from refiner.nn.layers import sinusoidal_positions

__all__ = ["FrameTransformerConfig", "FlawRecognitionNet", "FlawRepairNet", "frame_features", "VELOCITY_SCALE"]

#: Velocities (metres per frame) are multiplied by this so they span about the range of positions.
VELOCITY_SCALE = 10.0


def frame_features(x: torch.Tensor, root: int = 0) -> torch.Tensor:
    """Per-frame network input of joints ``(B, T, J, 3)`` metres -> ``(B, T, 6J + 3)``.

    Root-relative pose ``(J*3)``, root position relative to the first frame's ``(3)`` and joint
    velocities ``(J*3)``, scaled by :data:`VELOCITY_SCALE` (the first frame's velocity is zero).
    Translation-invariant: shifting the clip changes nothing.
    """
    r = x[:, :, root : root + 1]
    rel = x - r
    path = r[:, :, 0] - r[:, :1, 0]
    vel = torch.zeros_like(x)
    vel[:, 1:] = (x[:, 1:] - x[:, :-1]) * VELOCITY_SCALE
    return torch.cat([rearrange(rel, "b t j c -> b t (j c)"), path, rearrange(vel, "b t j c -> b t (j c)")], -1)


@dataclass
class FrameTransformerConfig:
    """Sizes of the learned-refinement networks."""

    n_joints: int = 24
    n_actions: int = 12
    d_model: int = 128
    n_layers: int = 3
    n_heads: int = 4
    ffn_dim: int = 256
    dropout: float = 0.1
    max_len: int = 256

    def to_dict(self) -> dict:
        return asdict(self)


class _Backbone(nn.Module):
    """Embed frames (+ positions + action), optionally append context tokens, run a pre-norm transformer."""

    def __init__(self, c: FrameTransformerConfig, in_dim: int):
        super().__init__()
        self.embed = nn.Linear(in_dim, c.d_model)
        self.action = nn.Embedding(c.n_actions + 1, c.d_model)
        self.register_buffer("positions", sinusoidal_positions(c.max_len, c.d_model), persistent=False)
        layer = nn.TransformerEncoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, c.n_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(c.d_model)

    def forward(self, feats, action, valid=None, context=None, context_valid=None):
        n = feats.shape[1]
        h = self.embed(feats) + self.positions[:n][None] + self.action(action)[:, None]
        pad = None if valid is None else ~valid
        if context is not None:
            h = torch.cat([h, context], 1)
            frames_pad = torch.zeros(h.shape[0], n, dtype=torch.bool, device=h.device) if pad is None else pad
            pad = torch.cat([frames_pad, ~context_valid], 1)
        return self.norm(self.encoder(h, src_key_padding_mask=pad))[:, :n]


class FlawRecognitionNet(nn.Module):
    """Recognition: per-frame flaw logit, per-frame anchor logit and action logits.

    ``x (B, T, J, 3)`` metres, ``action (B,)`` long (``n_actions`` = unknown), ``valid (B, T)`` bool
    -> ``flaw (B, T)``, ``anchor (B, T)``, ``action (B, n_actions)`` logits.
    """

    def __init__(self, config: FrameTransformerConfig):
        super().__init__()
        self.config = config
        self.backbone = _Backbone(config, 6 * config.n_joints + 3)
        self.heads = nn.Linear(config.d_model, 2)
        self.action_head = nn.Linear(config.d_model, config.n_actions)

    def forward(self, x, action, valid=None):
        h = self.backbone(frame_features(x), action, valid)
        flaw, anchor = self.heads(h).unbind(-1)
        w = torch.ones(h.shape[:2], device=h.device) if valid is None else valid.float()
        pooled = (h * w[..., None]).sum(1) / w.sum(1, keepdim=True).clamp_min(1.0)
        return flaw, anchor, self.action_head(pooled)


class FlawRepairNet(nn.Module):
    """Repair: corrected joints for every frame, given the clip, which frames are suspect, and the action.

    ``x (B, T, J, 3)`` metres (hidden frames already replaced by linear interpolation), ``infill
    (B, T, J, 3)``: ``x`` with every suspect frame linearly interpolated from the kept ones,
    ``suspect (B, T)`` and ``hidden (B, T)`` bool, ``action (B,)`` long, ``valid (B, T)`` ->
    ``(B, T, J, 3)``.

    The output is a per-frame mixture of the given frames and the in-fill, with one gate per
    joint for the root-relative pose and one for the root path, plus a correction: a flaw that
    moves the whole body (floating, sliding) is undone by taking the in-filled root path while
    keeping the given pose, a wrong pose by taking the in-filled pose, noise by keeping the given
    frames and correcting them. Gates start at "given" and the correction at zero, so an
    untrained network is the identity.
    ``concepts (A, K, J, 3)`` root-relative anchor-concept poses with ``concept_valid (A, K)``.
    """

    def __init__(self, config: FrameTransformerConfig, n_concepts: int = 8):
        super().__init__()
        self.config = config
        c = config
        self.backbone = _Backbone(c, 12 * c.n_joints + 8)
        self.concept_embed = nn.Linear(3 * c.n_joints, c.d_model)
        self.register_buffer("concepts", torch.zeros(c.n_actions, n_concepts, c.n_joints, 3))
        self.register_buffer("concept_valid", torch.zeros(c.n_actions, n_concepts, dtype=torch.bool))
        self.out = nn.Linear(c.d_model, 3 * c.n_joints)
        self.gates = nn.Linear(c.d_model, c.n_joints + 1)
        for layer in (self.out, self.gates):
            nn.init.zeros_(layer.weight)
            nn.init.zeros_(layer.bias)
        nn.init.constant_(self.gates.bias, 4.0)  # sigmoid(4) = 0.98: start by keeping the given frames

    def forward(self, x, infill, suspect, hidden, action, valid=None, root: int = 0):
        feats = torch.cat([frame_features(x, root), frame_features(infill, root), suspect[..., None].float(),
                           hidden[..., None].float()], -1)
        known = action < self.config.n_actions
        idx = action.clamp_max(self.config.n_actions - 1)
        context = self.concept_embed(rearrange(self.concepts[idx], "b k j c -> b k (j c)"))
        context_valid = self.concept_valid[idx] & known[:, None]
        h = self.backbone(feats, action, valid, context, context_valid)
        g = torch.sigmoid(self.gates(h))
        g = torch.where(suspect[..., None], g, torch.ones_like(g))
        rx, ri = x[:, :, root : root + 1], infill[:, :, root : root + 1]
        pose = g[..., :-1, None] * (x - rx) + (1 - g[..., :-1, None]) * (infill - ri)
        path = g[..., -1:, None] * rx + (1 - g[..., -1:, None]) * ri
        delta = rearrange(self.out(h), "b t (j c) -> b t j c", c=3)
        return pose + path + delta / VELOCITY_SCALE


