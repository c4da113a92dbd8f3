"""Plugin contract of motion-refiner: the ``hookimpl`` marker, :class:`AdapterInfo` and the plugin manager.

Write a plugin as a module of ``@hookimpl`` functions named after the specs in
:mod:`refiner.plugins.hookspecs` and expose it in the ``motion_refiner.adapters`` entry-point group.
The built-in adapters (:data:`BUILTIN_ADAPTERS`, modules of ``refiner.adapters``) are loaded by name
and registered exactly the same way; nothing here imports them.
"""
from __future__ import annotations

import pluggy

from refiner.plugins.adapter_info import AdapterInfo

__all__ = ["AdapterInfo", "BUILTIN_ADAPTERS", "PROJECT_NAME", "get_plugin_manager", "hookimpl"]

#: Name shared by both pluggy markers, the plugin manager and the entry-point group prefix.
PROJECT_NAME = "motion_refiner"

#: Marker for hook implementations: ``@hookimpl def refiner_adapter_info(): ...``.
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)

from refiner.plugins.manager import BUILTIN_ADAPTERS, get_plugin_manager  # noqa: E402  (needs PROJECT_NAME first)
