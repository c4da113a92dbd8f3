"""Built-in generator adapters: one pluggy plugin module per generator (generator_formats.md §2-§7).

Each module listed in :data:`BUILTIN_ADAPTERS` is registered under its own name by
:func:`refiner.plugins.get_plugin_manager`, exactly like a third-party plugin. Nothing is imported
here, so ``import refiner.adapters`` stays cheap.
"""
from __future__ import annotations

__all__ = ["BUILTIN_ADAPTERS"]

#: Module names under ``refiner.adapters`` registered as built-in plugins, in registration order.
BUILTIN_ADAPTERS: tuple[str, ...] = ("action2motion", "actor", "mld", "motiondiffuse", "mogents")
