"""Hook specifications for motion-refiner plugins (generator adapters).

Hooks are called by refiner itself, always with keyword arguments. A plugin implements any subset
with ``@refiner.plugins.hookimpl`` and may accept fewer arguments than a spec lists; the built-in
adapters in ``refiner.adapters`` are plugins like any other. The hooks that take an ``adapter`` name
are called only on the plugin that registered that adapter, so a plugin never has to check the name
(one that still does keeps working). Arguments are only ever added to these specs, never renamed or
removed.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import pluggy

if TYPE_CHECKING:
    from refiner.core.motion import Motion
    from refiner.plugins.adapter_info import AdapterInfo

__all__ = [
    "hookspec",
    "refiner_adapter_info",
    "refiner_convert_output",
    "refiner_encode_motions",
    "refiner_read_file",
    "refiner_recognize_generator",
    "refiner_sample_generator",
    "refiner_write_refined",
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

    Called by :meth:`refiner.RefinedGenerator.sample` (through ``PluginManager.sample``) before
    conversion, on the plugin that registered the generator's adapter only. Implement it when the
    generator's API is not ``generator.sample(action, n=n, **options)`` or
    ``generator(action, n=n, **options)``, which RefinedGenerator uses when this hook returns None.

    Parameters
    ----------
    adapter : str
        The adapter chosen for this generator: always one your ``refiner_adapter_info`` declares.
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

    Called by ``PluginManager.convert`` / :func:`refiner.plugins.manager.convert` (the CLI's
    ``--adapter``, the benchmarks, the reference generators' ``to_motions``) and by
    :meth:`refiner.RefinedGenerator.sample` after sampling, on the plugin that registered *adapter* only.

    Parameters
    ----------
    adapter : str
        Adapter name requested: always the name your ``refiner_adapter_info`` declares.
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


@hookspec(firstresult=True)
def refiner_encode_motions(adapter: str, motions: list[Motion], options: Mapping[str, Any]) -> list[Any] | None:
    """Convert canonical motions into the generator's raw representation: the inverse of ``refiner_convert_output``.

    Called by ``PluginManager.encode`` / :func:`refiner.plugins.manager.encode`, on the plugin that
    registered *adapter* only; the reference generators (:mod:`refiner.reference`) use it to turn real
    clips into training targets in a generator's own representation (Action2Motion's Lie parameters).
    Optional: implement it when your raw format can be computed from joint positions.

    Parameters
    ----------
    adapter : str
        Adapter name requested: always the name your ``refiner_adapter_info`` declares.
    motions : list of Motion
        Canonical motions, each on one of your ``AdapterInfo.skeletons`` (the manager checks);
        never modify them.
    options : mapping
        Adapter-specific keyword options (e.g. ``representation``). Raise ``ValueError`` naming
        any option you do not accept.

    Returns
    -------
    list or None
        One raw output per motion, in order, each in the single-clip layout your
        ``refiner_convert_output`` accepts (so converting it back gives the motion again, up to
        what the representation cannot hold). Stops at the first non-None result; None means the
        plugin does not encode. Raise ``ValueError`` for motions you cannot encode.
    """


# --- files in the generator's own format -------------------------------------------------------


@hookspec(firstresult=True)
def refiner_read_file(adapter: str, path: Path) -> Any | None:
    """Read a file the generator wrote into the raw output your ``refiner_convert_output`` accepts.

    Called by ``PluginManager.read_file`` (the CLI's ``refine IN --adapter NAME``) on the plugin that
    registered *adapter* only. Optional: without it the CLI reads ``.npy`` / ``.npz`` arrays with pickles
    refused. Unpickle only through :func:`refiner.core.safe_pickle.load_npy` / ``load_pickle``.

    Parameters
    ----------
    adapter : str
        Adapter name requested: always the name your ``refiner_adapter_info`` declares.
    path : Path
        The file the user gave.

    Returns
    -------
    object or None
        The raw output. Stops at the first non-None result. Raise ``ValueError`` naming what is wrong with
        a file that is not in your format.
    """


@hookspec(firstresult=True)
def refiner_write_refined(
    adapter: str, path: Path, output: Any, before: list[Motion], after: list[Motion]
) -> Path | None:
    """Write refined motions at *path* in the generator's own format, so that its users' scripts read them.

    Called by ``PluginManager.write_refined`` (the CLI's ``refine IN --adapter NAME -o OUT``) on the plugin
    that registered *adapter* only; when implemented, it replaces the CLI's joint output. Put back only the
    change: frames where *after* equals *before* must be written exactly as *output* holds them.

    Parameters
    ----------
    adapter : str
        Adapter name requested: always the name your ``refiner_adapter_info`` declares.
    path : Path
        Where to write (its folder exists; overwriting was already allowed).
    output : object
        The raw output as read (``refiner_read_file``); never modify it.
    before, after : list of Motion
        What ``refiner_convert_output`` made of *output*, and the refined motions, in the same order.

    Returns
    -------
    Path or None
        The file written. Stops at the first non-None result; None means the plugin writes no files.
    """
