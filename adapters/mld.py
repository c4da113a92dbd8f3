"""MLD adapter: (B, T, 150) feature-major rot6d features to ACTOR's layout, then SMPL (generator_formats.md §4).

MLD flattens ACTOR's (B, 25, 6, T) tensor per frame as (B, T, 6, 25): for a 150-vector v, joint j's
6D is ``v[j], v[25+j], ..., v[125+j]`` and the translation ``v[24], v[49], v[74]``. After
reshaping, conversion is the ACTOR path (SMPL ``jointstype="smpl"``, ``vertstrans=True``).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from refiner.adapters import actor
from refiner.adapters.conversion import call_with_options, check_raw
from refiner.core.motion import Motion
from refiner.plugins import AdapterInfo, hookimpl

__all__ = ["INFO", "actor_to_features", "features_to_actor", "to_motions"]

INFO = AdapterInfo(
    name="mld",
    format=(
        "m_rst features (B, T, 150) or (T, 150), feature-major ACTOR rot6d + translation; optional "
        "lengths/mask; needs the SMPL neutral model (smpl_path or $MOTION_REFINER_SMPL)"
    ),
    skeletons=("humanact12", "uestc"),
    fps=20.0,
    up="-y",
    description="MLD (Chen et al. 2023), action-conditioned HumanAct12 checkpoint; UESTC layout via SMPL 'a2m'.",
)


def features_to_actor(features) -> np.ndarray:
    """MLD features ``(B, T, 150)`` or ``(T, 150)`` to ACTOR's ``(B, 25, 6, T)`` float32 (MLD's inverse collate).

    Raises ``ValueError`` for any other shape.
    """
    x = check_raw(features, name="features", ndims=(2, 3), last=(150,), what="(B, T, 150) or (T, 150)")
    if x.ndim == 2:
        x = x[None]
    b, t, _ = x.shape
    return x.reshape(b, t, 6, 25).transpose(0, 3, 2, 1).astype(np.float32)  # (B, 25, 6, T)


def actor_to_features(output) -> np.ndarray:
    """ACTOR's ``(B, 25, 6, T)`` to MLD's ``(B, T, 150)`` float32 (MLD's collate; inverse of :func:`features_to_actor`)."""
    x = check_raw(output, name="output", ndims=(4,), what="(B, 25, 6, T)")
    if x.shape[1:3] != (25, 6):
        raise ValueError(f"`output` must have shape (B, 25, 6, T); got {tuple(x.shape)}.")
    return x.transpose(0, 3, 2, 1).reshape(x.shape[0], x.shape[3], 150).astype(np.float32)


def to_motions(output: Any, **options: Any) -> list[Motion]:
    """MLD features ``(B, T, 150)`` (``m_rst``) to canonical motions through SMPL.

    :func:`features_to_actor`, then :func:`refiner.adapters.actor.to_motions` with the same keyword
    options (``mask`` (B, T) or ``lengths`` (B,) select the valid frames of padded batches;
    ``skeleton``, ``smpl_path``, ``j_regressor_extra``, ``vertstrans``, ``actions``, ``fps``).
    """
    return actor.to_motions(features_to_actor(output), **options)


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_convert_output(output: Any, skeleton: str | None, options: Mapping[str, Any]) -> list[Motion]:
    # the options are ACTOR's: check them against its converter, then convert the reshaped features
    return call_with_options(actor.to_motions, features_to_actor(output), options, adapter=INFO.name, skeleton=skeleton)
