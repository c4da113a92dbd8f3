"""MotionDiffuse adapter: normalised HumanML3D features to canonical joints (generator_formats.md §5, §7).

``DDPMTrainer.generate`` returns a list of (T_b, 263) tensors padded to the batch maximum; they are
de-normalised with the checkpoint's ``meta/mean.npy`` and ``meta/std.npy``, decoded with
``recover_from_ric`` and mapped onto HumanAct12 (24 joints) or UESTC (18 joints). The converter is
the shared HumanML3D one: ``to_motions`` is :func:`refiner.adapters.humanml3d.features_to_motions`
(``mean`` / ``std`` are required unless ``denormalized``; the visualiser's saved ``*.npy`` joints
are smoothed and not accepted: use the raw features).
"""
from __future__ import annotations

from typing import Any, Mapping

from refiner.adapters.humanml3d import convert_output, features_to_motions as to_motions
from refiner.core.motion import Motion
from refiner.plugins import AdapterInfo, hookimpl

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


# --- plugin hooks ------------------------------------------------------------------------------


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_convert_output(output: Any, generator: Any, skeleton: str | None, options: Mapping[str, Any]) -> list[Motion]:
    return convert_output(output, adapter=INFO.name, generator=generator, skeleton=skeleton, options=options)
