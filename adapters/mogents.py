"""MoGenTS adapter: HumanML3D features from the RVQ-VAE decoder to canonical joints (generator_formats.md §6, §7).

``RVQVAE.forward_decoder`` returns (x_out1d, x_out2d), each (B, T, 263) normalised; the demo uses
x_out2d, as does this adapter when given the pair. ``*_data.npy`` files hold de-normalised (L, 263)
features (pass ``denormalized=True``); the ``joints/*.npy`` files are IK-refitted and not accepted.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from refiner.adapters.base import AdapterInfo
from refiner.adapters.humanml3d import HAND_LENGTH, convert_output, features_to_motions
from refiner.core.motion import Motion
from refiner.plugins import hookimpl

__all__ = ["INFO", "to_motions"]

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


def to_motions(
    output: Any,
    *,
    mean=None,
    std=None,
    denormalized: bool = False,
    lengths: Sequence[int] | None = None,
    skeleton: str | None = None,
    hand_length: float = HAND_LENGTH,
    actions: Sequence[int | None] | None = None,
    fps: float = 20.0,
) -> list[Motion]:
    """MoGenTS output to canonical motions; see :func:`refiner.adapters.humanml3d.features_to_motions`.

    A 2-tuple ``(x_out1d, x_out2d)`` is taken as the decoder's pair and ``x_out2d`` is used.
    """
    if isinstance(output, tuple) and len(output) == 2 and all(getattr(o, "ndim", 0) == 3 for o in output):
        output = output[1]
    return features_to_motions(
        output, mean=mean, std=std, denormalized=denormalized, lengths=lengths,
        skeleton=skeleton or "humanact12", hand_length=hand_length, actions=actions, fps=fps,
    )


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_convert_output(adapter: str, output: Any, generator: Any, skeleton: str | None, options: Mapping[str, Any]):
    if adapter != INFO.name:
        return None
    return convert_output(to_motions, output, adapter=INFO.name, generator=generator, skeleton=skeleton,
                          options=options)
