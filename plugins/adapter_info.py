"""The adapter description every plugin returns from ``refiner_adapter_info``: part of the plugin contract."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["AdapterInfo"]

_AXES = {"+x", "-x", "+y", "-y", "+z", "-z"}


@dataclass(frozen=True)
class AdapterInfo:
    """What an adapter plugin converts, returned by its ``refiner_adapter_info`` hook.

    Parameters
    ----------
    name : str
        Adapter name: the generator's short name, also the plugin and entry-point name
        (``"action2motion"``, ``"actor"``, ...). Lower-case letters, digits, ``_`` and ``-``.
    format : str
        One-line description of the raw generator output the adapter accepts, with shapes.
    skeletons : tuple of str
        Registered skeletons (:func:`refiner.get_skeleton`) it can produce; the first is the default.
    fps : float, default=20.0
        Frame rate of the generator's output (and of the produced motions).
    up : str, default="-y"
        Up axis of the generator's *native* output, with sign (``"+y"`` for HumanML3D generators).
        Converted motions are always in the target skeleton's own frame.
    description : str, default=""
    source : str, default=""
        Where the plugin came from; filled in by the plugin manager (``"built-in"`` or the
        distribution name and version), plugins leave it empty.
    """

    name: str
    format: str
    skeletons: tuple[str, ...]
    fps: float = 20.0
    up: str = "-y"
    description: str = ""
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or not all(
            c.isalnum() or c in "_-" for c in self.name
        ) or self.name.lower() != self.name:
            raise ValueError(f"AdapterInfo `name` must be a lower-case identifier like 'actor'; got {self.name!r}.")
        if not isinstance(self.format, str) or not self.format.strip():
            raise ValueError(f"AdapterInfo {self.name!r}: `format` must describe the raw output; got {self.format!r}.")
        skeletons = (self.skeletons,) if isinstance(self.skeletons, str) else tuple(self.skeletons)
        if not skeletons or not all(isinstance(s, str) and s for s in skeletons):
            raise ValueError(
                f"AdapterInfo {self.name!r}: `skeletons` must be a non-empty tuple of skeleton names; "
                f"got {self.skeletons!r}."
            )
        object.__setattr__(self, "skeletons", skeletons)
        if isinstance(self.fps, bool) or not isinstance(self.fps, (int, float)) or not math.isfinite(self.fps) or self.fps <= 0:
            raise ValueError(f"AdapterInfo {self.name!r}: `fps` must be a positive number; got {self.fps!r}.")
        object.__setattr__(self, "fps", float(self.fps))
        if self.up not in _AXES:
            raise ValueError(f"AdapterInfo {self.name!r}: `up` must be one of {sorted(_AXES)}; got {self.up!r}.")
