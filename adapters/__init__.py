"""Built-in generator adapters: one pluggy plugin module per generator (generator_formats.md §2-§7).

The plugin manager imports the modules named in :data:`refiner.plugins.BUILTIN_ADAPTERS` and registers
each under its own name, exactly like a third-party plugin. Beside them: the converters they share
(:mod:`~refiner.adapters.conversion`, :mod:`~refiner.adapters.humanml3d`) and Action2Motion's Lie
kinematics (:mod:`~refiner.adapters.lie_kinematics`); rotations live in :mod:`refiner.core.rotations`.
Nothing is imported here, so ``import refiner.adapters`` stays cheap.
"""
from __future__ import annotations

import warnings

__all__: list[str] = []


def __getattr__(name: str):
    if name == "BUILTIN_ADAPTERS":  # its 0.1 home; the list belongs to the plugin contract now
        warnings.warn("refiner.adapters.BUILTIN_ADAPTERS moved to refiner.plugins.BUILTIN_ADAPTERS; the old name "
                      "goes in 0.3.", DeprecationWarning, stacklevel=2)
        from refiner.plugins.manager import BUILTIN_ADAPTERS  # on demand: the package itself imports nothing

        return BUILTIN_ADAPTERS
    raise AttributeError(f"module 'refiner.adapters' has no attribute {name!r}")
