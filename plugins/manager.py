"""The plugin manager: hook specs, built-in adapters, entry-point plugins and adapter look-ups.

Built-in adapters are listed by module name (:data:`BUILTIN_ADAPTERS`, like pytest's
``default_plugins``), imported with importlib and registered exactly like entry-point plugins, so this
module never imports an adapter. Every conversion hook is called on the one plugin that registered the
requested adapter (``subset_hook_caller``), so plugins need not check the adapter name.

Plugins are isolated from each other: one that fails to import, fails pluggy's validation, implements a
misspelled hook or raises while describing itself is skipped with an :class:`AdapterPluginWarning` naming it.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import os
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import pluggy

from refiner.core.motion import Motion
from refiner.core.skeletons import list_skeletons
from refiner.plugins import PROJECT_NAME, hookspecs
from refiner.plugins.adapter_info import AdapterInfo
from refiner.plugins.errors import AdapterPluginError, AdapterPluginWarning

__all__ = [
    "AdapterPluginError", "AdapterPluginWarning", "BUILTIN_ADAPTERS", "BUILTIN_PACKAGE", "DISABLE_AUTOLOAD_ENV",
    "ENTRY_POINT_GROUP", "PluginManager", "convert", "encode", "get_adapter", "get_plugin_manager", "list_adapters",
]

#: Built-in adapter plugins, in registration order: each is the module ``BUILTIN_PACKAGE + "." + name``,
#: registered under ``name`` (= its adapter name = its entry-point name).
BUILTIN_ADAPTERS: tuple[str, ...] = ("action2motion", "actor", "mld", "motiondiffuse", "mogents", "mdm")
BUILTIN_PACKAGE = "refiner.adapters"
ENTRY_POINT_GROUP = "motion_refiner.adapters"
#: Set (to anything non-empty) to skip entry-point plugins, like ``PYTEST_DISABLE_PLUGIN_AUTOLOAD``.
DISABLE_AUTOLOAD_ENV = "MOTION_REFINER_DISABLE_PLUGIN_AUTOLOAD"
BUILTIN_SOURCE = "built-in"


class PluginManager(pluggy.PluginManager):
    """pluggy's manager for the ``motion_refiner`` hooks, plus adapter look-ups.

    Attributes
    ----------
    sources : dict of str to str
        Plugin name -> where it came from (``"built-in"``, ``"<dist> <version>"`` or
        ``"registered"`` for plugins added with :meth:`register` by hand).
    """

    def __init__(self) -> None:
        super().__init__(PROJECT_NAME)
        self.add_hookspecs(hookspecs)
        self.sources: dict[str, str] = {}

    def adapters(self) -> dict[str, AdapterInfo]:
        """Every registered adapter by name, sorted, with ``source`` filled in."""
        infos = {}
        for impl in self.hook.refiner_adapter_info.get_hookimpls():
            info = _call_isolated(impl, {}, "refiner_adapter_info")
            if info is None or info.name in infos:
                continue
            infos[info.name] = replace(info, source=self.sources.get(impl.plugin_name, "registered"))
        return dict(sorted(infos.items()))

    def get_adapter(self, name: str) -> AdapterInfo:
        """The :class:`~refiner.plugins.AdapterInfo` of adapter *name*.

        Raises
        ------
        ValueError
            Unknown name; the message lists the known adapters.
        """
        infos = self.adapters()
        if not isinstance(name, str) or name not in infos:
            raise ValueError(f"unknown adapter {name!r}; known adapters: {', '.join(infos) or '(none)'}.")
        return infos[name]

    def recognize(self, generator: Any) -> str | None:
        """Deprecated name of :meth:`adapter_for` (one meaning per name: *recognition* is the paper's anchor step)."""
        warnings.warn("PluginManager.recognize is now PluginManager.adapter_for; the old name goes in 0.3.",
                      DeprecationWarning, stacklevel=2)
        return self.adapter_for(generator)

    def adapter_for(self, generator: Any) -> str | None:
        """The name of the adapter whose plugin claims *generator* (hook ``refiner_recognize_generator``), or None.

        Each plugin is asked in hook-call order; one that raises or names an unknown adapter
        is reported with a warning and skipped.
        """
        known = self.adapters()
        for impl in reversed(self.hook.refiner_recognize_generator.get_hookimpls()):
            name = _call_isolated(impl, {"generator": generator}, "refiner_recognize_generator", expect=None)
            if name is None:
                continue
            if name not in known:
                warnings.warn(
                    f"motion-refiner plugin {impl.plugin_name!r}: refiner_recognize_generator returned "
                    f"unknown adapter {name!r}; ignored.", AdapterPluginWarning, stacklevel=2,
                )
                continue
            return name
        return None

    def register(self, plugin: object, name: str | None = None) -> str | None:
        """pluggy's ``register``, refusing a plugin whose adapter name another plugin already has.

        Raises
        ------
        ValueError
            The adapter name is taken; the message names both plugins. (The loaders of
            :func:`get_plugin_manager` turn this into an :class:`AdapterPluginWarning` and skip it.)
        """
        plugin_name = super().register(plugin, name)
        if plugin_name is None:
            return None
        for impl in self.hook.refiner_adapter_info.get_hookimpls():
            if impl.plugin is not plugin:
                continue
            info = _call_isolated(impl, {}, "refiner_adapter_info", quiet=True)
            owner = self._owner(info.name, exclude=plugin) if info is not None else None
            if owner is not None:
                self.unregister(plugin=plugin)
                raise ValueError(f"plugin {plugin_name!r} claims adapter name {info.name!r}, but adapter name "
                                 f"{info.name!r} is already taken by plugin {owner!r} "
                                 f"({self.sources.get(owner, 'registered')}).")
        return plugin_name

    def owner_hook(self, adapter: str, hook: str):
        """The hook caller of *hook* restricted to the plugin that registered adapter *adapter*, so that
        another plugin answering for every name cannot take over a built-in (or any other) adapter."""
        owner = self._owner(adapter)
        others = [p for p in self.get_plugins() if p is not self.get_plugin(owner)]
        return self.subset_hook_caller(hook, remove_plugins=others)

    def sample(self, adapter: str, generator: Any, action: Any, n: int, options: Mapping[str, Any]) -> Any:
        """Raw output from the ``refiner_sample_generator`` hook of the plugin that registered *adapter*,
        or None when it does not implement it; :class:`AdapterPluginError` naming the plugin if it raises."""
        return self._call_owner("refiner_sample_generator", adapter=adapter, generator=generator,
                                action=action, n=n, options=dict(options))

    def convert(
        self,
        adapter: str,
        output: Any,
        *,
        generator: Any = None,
        skeleton: str | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> list[Motion]:
        """Convert raw *output* with adapter *adapter* into canonical motions.

        Raises
        ------
        ValueError
            Unknown adapter, a skeleton the adapter cannot produce, or whatever the adapter
            rejects in *output* / *options* (an :class:`AdapterPluginError` naming the plugin).
        """
        info = self.get_adapter(adapter)
        if skeleton is not None and skeleton not in info.skeletons:
            raise ValueError(
                f"adapter {adapter!r} cannot produce skeleton {skeleton!r}; it produces: {', '.join(info.skeletons)}."
            )
        motions = self._call_owner("refiner_convert_output", adapter=adapter, output=output,
                                   generator=generator, skeleton=skeleton, options=dict(options or {}))
        if motions is None:
            raise ValueError(f"adapter {adapter!r} ({info.source}) does not implement refiner_convert_output.")
        if isinstance(motions, Motion):
            motions = [motions]
        motions = list(motions)
        if not all(isinstance(m, Motion) for m in motions):
            kinds = sorted({type(m).__name__ for m in motions})
            raise TypeError(f"adapter {adapter!r} ({info.source}) must return Motion objects; got {', '.join(kinds)}.")
        return motions

    def encode(self, adapter: str, motions: Sequence[Motion], *, options: Mapping[str, Any] | None = None) -> list:
        """Raw generator output of *motions* in adapter *adapter*'s representation (the inverse of :meth:`convert`).

        Returns
        -------
        list
            One raw array per motion, as the plugin's ``refiner_encode_motions`` returns it.

        Raises
        ------
        ValueError
            Unknown adapter, not Motion objects or a skeleton the adapter does not produce, an adapter
            without ``refiner_encode_motions``, or whatever the adapter rejects (an :class:`AdapterPluginError`).
        """
        info = self.get_adapter(adapter)
        motions = [motions] if isinstance(motions, Motion) else list(motions)
        if not all(isinstance(m, Motion) for m in motions):
            kinds = sorted({type(m).__name__ for m in motions})
            raise ValueError(f"`motions` must be Motion objects; got {', '.join(kinds)}.")
        foreign = sorted({m.skeleton for m in motions} - set(info.skeletons))
        if foreign:
            raise ValueError(f"adapter {adapter!r} cannot encode skeleton(s) {', '.join(foreign)}; it handles: "
                             f"{', '.join(info.skeletons)}.")
        raw = self._call_owner("refiner_encode_motions", adapter=adapter, motions=motions, options=dict(options or {}))
        if raw is None:
            raise ValueError(f"adapter {adapter!r} ({info.source}) does not implement refiner_encode_motions.")
        raw = list(raw)
        if len(raw) != len(motions):
            raise TypeError(f"adapter {adapter!r} ({info.source}) must return one output per motion "
                            f"({len(motions)}); got {len(raw)}.")
        return raw

    def read_file(self, adapter: str, path: Path) -> Any:
        """Raw output read from the generator's own file (hook ``refiner_read_file``); None: the adapter reads none."""
        return self._call_owner("refiner_read_file", adapter=self.get_adapter(adapter).name, path=Path(path))

    def write_refined(self, adapter: str, path: Path, output: Any, before: Sequence[Motion],
                      after: Sequence[Motion]) -> Path | None:
        """Write ``after`` at ``path`` in the generator's own format (hook ``refiner_write_refined``); None: no
        writer. ``before``: what the adapter converted ``output`` to; only their difference is written back."""
        return self._call_owner("refiner_write_refined", adapter=self.get_adapter(adapter).name, path=Path(path),
                                output=output, before=list(before), after=list(after))

    def _owner(self, adapter: str, *, exclude: object = None) -> str | None:
        """The name of the plugin whose ``refiner_adapter_info`` names *adapter* (other than *exclude*)."""
        for impl in self.hook.refiner_adapter_info.get_hookimpls():
            if impl.plugin is exclude:
                continue
            info = _call_isolated(impl, {}, "refiner_adapter_info", quiet=True)
            if info is not None and info.name == adapter:
                return impl.plugin_name
        return None

    def _call_owner(self, hook: str, **kwargs: Any) -> Any:
        """Call *hook* of ``kwargs["adapter"]``'s plugin only; wrap what it raises in an error naming the plugin."""
        adapter = kwargs["adapter"]
        try:
            return self.owner_hook(adapter, hook)(**kwargs)
        except Exception as e:  # noqa: BLE001 -- anything a third-party hook raises gets the plugin's name
            owner = self._owner(adapter) or "?"
            detail = str(e) if isinstance(e, ValueError) else f"{type(e).__name__}: {e}"
            raise AdapterPluginError(
                f"adapter {adapter!r} (plugin {owner!r}, {self.sources.get(owner, 'registered')}): {hook} "
                f"failed: {detail}", plugin=owner, hook=hook) from e


def get_plugin_manager(autoload: bool = True) -> PluginManager:
    """A plugin manager with the hook specs, the built-in adapters and installed plugins.

    In order: the built-in modules named in :data:`BUILTIN_ADAPTERS` are imported by name and registered
    under their names; then plugins of the ``motion_refiner.adapters`` entry-point group are
    loaded (skipping names already registered, so built-ins listed there too are harmless),
    unless ``autoload`` is False or ``$MOTION_REFINER_DISABLE_PLUGIN_AUTOLOAD`` is set; finally
    ``check_pending()``. A plugin that fails to import, to register or to describe itself is
    skipped with an :class:`AdapterPluginWarning` naming it.

    Parameters
    ----------
    autoload : bool, default=True
        Load entry-point plugins (hermetic tests pass False).

    Returns
    -------
    PluginManager
    """
    pm = PluginManager()
    for name in BUILTIN_ADAPTERS:
        module = f"{BUILTIN_PACKAGE}.{name}"
        _add_plugin(pm, name, lambda module=module: importlib.import_module(module), BUILTIN_SOURCE)
    if autoload and not os.environ.get(DISABLE_AUTOLOAD_ENV):
        _load_entry_points(pm)
    pm.check_pending()
    return pm


def get_adapter(name: str, pm: PluginManager | None = None) -> AdapterInfo:
    """:class:`AdapterInfo` of adapter *name*; ``ValueError`` listing the known ones if unknown."""
    return (pm or get_plugin_manager()).get_adapter(name)


def list_adapters(pm: PluginManager | None = None) -> list[AdapterInfo]:
    """Every installed adapter, sorted by name."""
    return list((pm or get_plugin_manager()).adapters().values())


def convert(
    adapter: str,
    output: Any,
    *,
    skeleton: str | None = None,
    generator: Any = None,
    pm: PluginManager | None = None,
    **options: Any,
) -> list[Motion]:
    """Convert raw generator *output* (e.g. loaded from a file) with the named adapter.

    Examples
    --------
    >>> import numpy as np
    >>> motions = convert("action2motion", np.zeros((2, 60, 72)), representation="xyz")
    >>> len(motions), motions[0].joints.shape
    (2, (60, 24, 3))
    """
    return (pm or get_plugin_manager()).convert(adapter, output, generator=generator, skeleton=skeleton, options=options)


def encode(adapter: str, motions: Sequence[Motion], *, pm: PluginManager | None = None, **options: Any) -> list:
    """Raw output of *motions* in the named adapter's representation (the inverse of :func:`convert`).

    Examples
    --------
    >>> import numpy as np
    >>> from refiner.core.motion import Motion
    >>> lie = encode("action2motion", [Motion(np.zeros((60, 24, 3)))], representation="lie")
    >>> lie[0].shape
    (60, 72)
    """
    return (pm or get_plugin_manager()).encode(adapter, motions, options=options)


# --- private helpers -----------------------------------------------------------------------------


def _warn(message: str) -> None:
    warnings.warn(message, AdapterPluginWarning, stacklevel=3)


def _add_plugin(pm: PluginManager, name: str, load: Callable[[], object], source: str) -> bool:
    """Load, register and validate one plugin; on any failure warn, undo and return False."""
    try:
        plugin = load()
    except Exception as e:  # noqa: BLE001 -- a broken plugin must not break the others
        _warn(f"motion-refiner plugin {name!r} ({source}) failed to import and was skipped: {type(e).__name__}: {e}")
        return False
    try:
        pm.register(plugin, name=name)
    except Exception as e:  # noqa: BLE001 -- PluginValidationError, duplicate registration
        _warn(f"motion-refiner plugin {name!r} ({source}) could not be registered and was skipped: {e}")
        return False
    problem = _validate(pm, plugin, name)
    if problem:
        pm.unregister(plugin=plugin, name=name)
        _warn(f"motion-refiner plugin {name!r} ({source}) was skipped: {problem}")
        return False
    pm.sources[name] = source
    return True


def _validate(pm: PluginManager, plugin: object, name: str) -> str | None:
    """Why *plugin* cannot be used (misspelled hook, bad adapter info), or None; taken names are refused by
    :meth:`PluginManager.register`."""
    for caller in pm.get_hookcallers(plugin) or []:
        if not caller.has_spec() and any(
            impl.plugin is plugin and not impl.optionalhook for impl in caller.get_hookimpls()
        ):
            return f"hook {caller.name!r} is not a motion-refiner hook (misspelled?)."
    for impl in pm.hook.refiner_adapter_info.get_hookimpls():
        if impl.plugin is not plugin:
            continue
        try:
            info = impl.function()
        except Exception as e:  # noqa: BLE001
            return f"refiner_adapter_info raised {type(e).__name__}: {e}"
        if not isinstance(info, AdapterInfo):
            return f"refiner_adapter_info must return an AdapterInfo; got {type(info).__name__}."
        unknown = [s for s in info.skeletons if s not in list_skeletons()]
        if unknown:
            return f"adapter {info.name!r} names unregistered skeleton(s) {unknown}; register them first."
    return None


def _call_isolated(impl, kwargs: dict, hook: str, *, expect: str | None = "AdapterInfo", quiet: bool = False):
    """Call one hook implementation with the arguments it asks for; warn and return None if it raises."""
    try:
        result = impl.function(*(kwargs[a] for a in impl.argnames))
    except Exception as e:  # noqa: BLE001
        if not quiet:
            _warn(f"motion-refiner plugin {impl.plugin_name!r}: {hook} raised {type(e).__name__}: {e}")
        return None
    if expect == "AdapterInfo" and not isinstance(result, AdapterInfo):
        return None
    return result


def _load_entry_points(pm: PluginManager) -> None:
    """pluggy's ``load_setuptools_entrypoints`` with each plugin isolated from the others."""
    for dist in list(importlib.metadata.distributions()):
        for ep in dist.entry_points:
            if ep.group != ENTRY_POINT_GROUP or pm.get_plugin(ep.name) is not None or pm.is_blocked(ep.name):
                continue
            if ep.name in pm.sources:  # registered earlier, e.g. the same dist seen twice on sys.path
                continue
            source = f"{dist.metadata['Name']} {dist.version}"
            _add_plugin(pm, ep.name, ep.load, source)
