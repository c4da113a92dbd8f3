"""How plugin failures reach the user: a warning for a plugin that is skipped, an error naming the plugin that raised."""
from __future__ import annotations

__all__ = ["AdapterPluginError", "AdapterPluginWarning"]


class AdapterPluginWarning(UserWarning):
    """A plugin was skipped or misbehaved; the message names it."""


class AdapterPluginError(ValueError):
    """A plugin's ``refiner_convert_output``, ``refiner_encode_motions`` or ``refiner_sample_generator`` raised.

    The message names the plugin, where it comes from, the hook and the adapter, then the original
    error (kept as ``__cause__``). A ``ValueError`` subclass, so the CLI reports it in one line and
    callers catching ``ValueError`` for bad generator output are covered.

    Attributes
    ----------
    plugin : str
        The plugin's registered name.
    hook : str
        The hook that raised.
    """

    def __init__(self, message: str, *, plugin: str, hook: str):
        super().__init__(message)
        self.plugin, self.hook = plugin, hook
