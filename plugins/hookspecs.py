"""Hook specifications for motion-refiner plugins (generator adapters).

Hooks are called by refiner itself, always with keyword arguments. A plugin implements any subset
with ``@refiner.plugins.hookimpl`` and may accept fewer arguments than a spec lists; the built-in
adapters in ``refiner.adapters`` are plugins like any other. Arguments are only ever added to these
specs, never renamed or removed.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping

import pluggy

if TYPE_CHECKING:
    from refiner.adapters.base import AdapterInfo
    from refiner.core.motion import Motion

__all__ = [
    "hookspec",
    "refiner_adapter_info",
    "refiner_convert_output",
    "refiner_recognize_generator",
    "refiner_sample_generator",
]

hookspec = pluggy.HookspecMarker("motion_refiner")


# --- discovery ---------------------------------------------------------------------------------


@hookspec
def refiner_adapter_info() -> AdapterInfo:
    """Describe the generator output this plugin converts.

    Called by :func:`refiner.plugins.get_plugin_manager` once per plugin when it is registered
    (to validate it), and by ``PluginManager.adapters()`` / ``get_adapter(name)``, which the
    ``motion-refiner adapters`` command and :class:`refiner.RefinedGenerator` use.

    Returns
    -------
    AdapterInfo
        ``name`` (the adapter, plugin and entry-point name), raw ``format`` description,
        ``skeletons`` it can produce (first = default), ``fps`` and the ``up`` axis of the native
        output. All results are collected, one per plugin; a plugin that raises here, returns
        something else or reuses a taken name is unregistered with a warning.
    """


@hookspec(firstresult=True)
def refiner_recognize_generator(generator: Any) -> str | None:
    """Name the adapter for *generator* if this plugin recognises the object.

    Called by :class:`refiner.RefinedGenerator` when no ``adapter`` name was given, with the
    user's generator object, untouched. Recognise by duck typing (attributes, methods), never by
    importing the generator's own package.

    Parameters
    ----------
    generator : object
        The user's model, sampler or callable.

    Returns
    -------
    str or None
        A registered adapter name, or None for objects you do not handle. Stops at the first
        non-None result. Never raise for foreign objects: an exception is reported as a warning
        naming the plugin and the next plugin is asked.
    """


# --- sampling and conversion -------------------------------------------------------------------


@hookspec(firstresult=True)
def refiner_sample_generator(adapter: str, generator: Any, action: Any, n: int, options: Mapping[str, Any]) -> Any:
    """Run *generator*'s own sampling API and return its raw output.

    Called by :meth:`refiner.RefinedGenerator.sample` before conversion. Implement it when the
    generator's API is not ``generator.sample(action, n=n, **options)`` or
    ``generator(action, n=n, **options)``, which RefinedGenerator uses when every plugin
    returns None.

    Parameters
    ----------
    adapter : str
        The adapter chosen for this generator; return None unless it is yours.
    generator : object
        The user's generator.
    action : int or str
        The requested action (index in the dataset's label set, or a name).
    n : int
        Number of samples wanted (>= 1).
    options : mapping
        Extra keyword arguments the user passed to ``sample``.

    Returns
    -------
    object or None
        Raw generator output, in the form your ``refiner_convert_output`` accepts. Stops at the
        first non-None result.
    """


@hookspec(firstresult=True)
def refiner_convert_output(
    adapter: str, output: Any, generator: Any, skeleton: str | None, options: Mapping[str, Any]
) -> list[Motion] | None:
    """Convert raw generator output into canonical motions.

    Called by ``PluginManager.convert`` / :func:`refiner.plugins.manager.convert` and by
    :meth:`refiner.RefinedGenerator.sample` after sampling.

    Parameters
    ----------
    adapter : str
        Adapter name requested; return None unless it is the name your ``refiner_adapter_info``
        declares.
    output : object
        Raw output exactly as the generator produced it (arrays, tensors, dicts, lists);
        never modify it.
    generator : object or None
        The generator that produced it, when known (e.g. to read its normalisation statistics).
    skeleton : str or None
        Target skeleton, one of your ``AdapterInfo.skeletons``; None means your default or
        what the output's shape implies.
    options : mapping
        Adapter-specific keyword options from the user (e.g. ``mean``, ``std``, ``smpl_path``).
        Raise ``ValueError`` naming any option you do not accept.

    Returns
    -------
    list of Motion or None
        One :class:`~refiner.Motion` per generated clip, in the target skeleton's canonical frame
        (metres; y down and facing -z for HumanAct12 / UESTC; first-frame root at the origin unless
        your format documents otherwise). Stops at the first non-None result. Raise ``ValueError``
        for output of the wrong shape or missing side information.
    """
