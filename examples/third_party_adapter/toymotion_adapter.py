"""motion-refiner adapter for ToyMotion, a made-up generator (an example third-party plugin).

ToyMotion emits joint positions ``(n, T, 24, 3)`` in centimetres, y up and facing +z, SMPL joint
order. The adapter converts them into the HumanAct12 canonical frame: metres, y down, facing -z,
first-frame pelvis at the origin. Install with ``pip install examples/third_party_adapter``; the
entry point in ``pyproject.toml`` does the rest. It uses only the plugin contract (``refiner.plugins``),
:class:`refiner.Motion` and a rotation from :mod:`refiner.core.rotations`; the plugin manager calls its
conversion hook for its own adapter name only.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from refiner.core.motion import Motion
from refiner.core.rotations import yup_to_ydown
from refiner.plugins import AdapterInfo, hookimpl

__all__ = ["INFO", "ToyMotionGenerator", "to_motions"]

INFO = AdapterInfo(
    name="toymotion",
    format="joints (n, T, 24, 3) in centimetres, y up, facing +z, SMPL joint order",
    skeletons=("humanact12",),
    fps=20.0,
    up="+y",
    description="Example plugin: the made-up ToyMotion generator.",
)

# A standing SMPL-like pose in centimetres (y up, facing +z, left = +x).
_REST_CM = np.array([
    [0, 95, 0], [9, 87, 0], [-9, 87, 0], [0, 107, -2], [10, 50, 0], [-10, 50, 0], [0, 120, -2],
    [10, 10, -3], [-10, 10, -3], [0, 126, 0], [11, 2, 9], [-11, 2, 9], [0, 147, -1], [7, 139, 0],
    [-7, 139, 0], [0, 156, 4], [18, 141, -1], [-18, 141, -1], [20, 116, -2], [-20, 116, -2],
    [21, 92, 0], [-21, 92, 0], [21, 84, 1], [-21, 84, 1],
], dtype=np.float64)


class ToyMotionGenerator:
    """The made-up generator: a figure walking along +z and swinging its arms, in centimetres.

    ``sample(action, n=1, n_frames=60, random_state=None)`` returns ``(n, n_frames, 24, 3)``.
    """

    toymotion_version = "1.0"  # what the adapter recognises

    def sample(self, action: int, n: int = 1, n_frames: int = 60, random_state=None) -> np.ndarray:
        rng = np.random.default_rng(random_state)
        t = np.arange(n_frames) / 20.0
        out = np.repeat(_REST_CM[None, None], n, axis=0).repeat(n_frames, axis=1)
        for i in range(n):
            phase = rng.uniform(0, 2 * np.pi)
            swing = 15.0 * np.sin(2 * np.pi * t + phase)  # cm, forward/backward
            out[i, :, [18, 20, 22], 2] += swing[None, :] * np.array([0.5, 1.0, 1.1])[:, None]
            out[i, :, [19, 21, 23], 2] -= swing[None, :] * np.array([0.5, 1.0, 1.1])[:, None]
            out[i, :, :, 2] += (20.0 + 10.0 * (int(action) % 3)) * t[:, None]  # walk forward
        return out.astype(np.float32)


def to_motions(output: Any, *, actions=None) -> list[Motion]:
    """ToyMotion joints ``(n, T, 24, 3)`` (or ``(T, 24, 3)``) in cm, y up -> canonical HumanAct12 motions."""
    x = np.asarray(output, dtype=np.float64)
    if x.ndim == 3:
        x = x[None]
    if x.ndim != 4 or x.shape[2:] != (24, 3):
        raise ValueError(f"ToyMotion output must have shape (n, T, 24, 3); got {tuple(x.shape)}.")
    joints = yup_to_ydown(x / 100.0)
    joints -= joints[:, :1, :1]  # first-frame pelvis at the origin
    actions = [None] * len(joints) if actions is None else list(actions)
    return [Motion(j, skeleton="humanact12", fps=INFO.fps, action=a) for j, a in zip(joints, actions)]


@hookimpl
def refiner_adapter_info() -> AdapterInfo:
    return INFO


@hookimpl
def refiner_recognize_generator(generator: Any) -> str | None:
    return INFO.name if hasattr(generator, "toymotion_version") else None


@hookimpl
def refiner_convert_output(output: Any, options: Mapping[str, Any]) -> list[Motion]:
    unknown = set(options) - {"actions"}
    if unknown:
        raise ValueError(f"unknown option(s) {sorted(unknown)} for adapter 'toymotion'; accepted: actions.")
    return to_motions(output, **options)
