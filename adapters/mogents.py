"""MoGenTS adapter: HumanML3D features from the RVQ-VAE decoder to canonical joints (generator_formats.md §6, §7).

``RVQVAE.forward_decoder`` returns (x_out1d, x_out2d), each (B, T, 263) normalised; the demo uses
x_out2d, as does this adapter when given the pair. ``*_data.npy`` files hold de-normalised (L, 263)
features (pass ``denormalized=True``); the ``joints/*.npy`` files are IK-refitted and not accepted.
"""
from __future__ import annotations

from typing import Any, Mapping

from refiner.adapters.humanml3d import convert_output, features_to_motions
from refiner.core.motion import Motion
from refiner.plugins import AdapterInfo, hookimpl

__all__ = ["INFO", "decoder_output", "to_motions"]

INFO = AdapterInfo(
    name="mogents",
    format=(
        "(B, T, 263) normalised HumanML3D features (or the decoder's (x_out1d, x_out2d) pair) + the "
        "checkpoint's mean/std (263,); or de-normalised *_data.npy (L, 263) with denormalized=True"
    ),
    skeletons=("humanact12", "uestc"),
    fps=20.0,
    up="+y",
    description="MoGenTS (Yuan et al. 2024), text-to-motion; lengths are multiples of 4; 22 joints mapped to 24 or 18.",
)


def decoder_output(output: Any) -> Any:
    """``x_out2d`` of the decoder's ``(x_out1d, x_out2d)`` pair (a 2-tuple of 3-D arrays); anything else as given."""
    if isinstance(output, tuple) and len(output) == 2 and all(getattr(o, "ndim", 0) == 3 for o in output):
        return output[1]
    return output


def to_motions(output: Any, **options: Any) -> list[Motion]:
    """MoGenTS output to canonical motions: :func:`decoder_output`, then
    :func:`refiner.adapters.humanml3d.features_to_motions` with the same keyword options
    (``mean``, ``std``, ``denormalized``, ``lengths``, ``skeleton``, ``hand_length``, ``actions``, ``fps``).
    """
    return features_to_motions(decoder_output(output), **options)


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_convert_output(output: Any, generator: Any, skeleton: str | None, options: Mapping[str, Any]) -> list[Motion]:
    return convert_output(decoder_output(output), adapter=INFO.name, generator=generator, skeleton=skeleton,
                          options=options)
