"""MotionDiffuse adapter: normalised HumanML3D features to canonical joints (generator_formats.md §5, §7).

``DDPMTrainer.generate`` returns a list of (T_b, 263) tensors padded to the batch maximum; they are
de-normalised with the checkpoint's ``meta/mean.npy`` and ``meta/std.npy``, decoded with
``recover_from_ric`` and mapped onto HumanAct12 (24 joints) or UESTC (18 joints).
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from refiner.adapters.base import AdapterInfo
from refiner.adapters.humanml3d import HAND_LENGTH, convert_output, features_to_motions
from refiner.core.motion import Motion
from refiner.plugins import hookimpl

__all__ = ["INFO", "to_motions"]

INFO = AdapterInfo(
    name="motiondiffuse",
    format=(
        "list of (T_b, 263) or array (B, T, 263) normalised HumanML3D features + the checkpoint's mean/std "
        "(263,); lengths (m_lens) slice padded clips"
    ),
    skeletons=("humanact12", "uestc"),
    fps=20.0,
    up="+y",
    description="MotionDiffuse (Zhang et al. 2022), text-to-motion; 22 joints mapped to 24 (hands) or 18 (estimated).",
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
    """MotionDiffuse output to canonical motions; see :func:`refiner.adapters.humanml3d.features_to_motions`.

    ``mean`` and ``std`` (arrays of shape (263,) or ``.npy`` paths) are required unless
    ``denormalized``; missing ones raise ``ValueError``. Saved ``*.npy`` joints of the visualiser
    are smoothed and not accepted: use the raw features.
    """
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
