"""The transformer motion encoder of Fig. 3-a-2 (appendix A).

The motion encoder linearly embeds each frame, adds sinusoidal positions, runs a transformer
encoder, then retrieves per-frame features from a transformer decoder whose queries are the
positional encodings. The concept encoder, bias encoder and transformer of the transition
refinement module "have the same structure", so they are instances of this class too.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from refiner.nn.layers import sinusoidal_positions

__all__ = ["MotionEncoderConfig", "MotionEncoder", "encoder_config"]


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


def encoder_config(component, n_joints: int) -> MotionEncoderConfig:
    """The motion encoder of a §3.2 component (its ``d_model``, ``n_layers``, ``n_heads``, ``ffn_dim``,
    ``dropout`` and ``crop_frames``) for ``n_joints`` joints; positions for four crops (inference windows are two)."""
    return MotionEncoderConfig(n_joints * 3, component.d_model, component.n_layers, component.n_heads, component.ffn_dim,
                               component.dropout, max_len=4 * component.crop_frames)
