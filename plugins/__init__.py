"""Plugin machinery of motion-refiner: the ``hookimpl`` marker adapters use, and the plugin manager.

Write a plugin as a module of ``@hookimpl`` functions named after the specs in
:mod:`refiner.plugins.hookspecs` and expose it in the ``motion_refiner.adapters`` entry-point group.
"""
from __future__ import annotations

import pluggy

__all__ = ["PROJECT_NAME", "get_plugin_manager", "hookimpl"]

#: Name shared by both pluggy markers, the plugin manager and the entry-point group prefix.
PROJECT_NAME = "motion_refiner"

#: Marker for hook implementations: ``@hookimpl def refiner_adapter_info(): ...``.
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)

from refiner.plugins.manager import get_plugin_manager  # noqa: E402  (needs hookimpl defined first)
