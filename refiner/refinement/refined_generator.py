"""RefinedGenerator: wrap any action-conditioned generator so that its samples come out refined (paper §3.2).

Sampling calls the generator's own API, an adapter plugin converts the raw output into canonical
:class:`~refiner.Motion` s, and a refiner fixes them. Adapters are found through
:mod:`refiner.plugins`; this module never names one.
"""
from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any, Callable, Mapping

import numpy as np

from refiner.core.motion import Motion
from refiner.core.validation import check_action
from refiner.io.datasets import HUMANACT12_ACTIONS

__all__ = ["RefinedGenerator", "identity_refiner"]


def identity_refiner(motion: Motion) -> Motion:
    """The refiner that returns its input unchanged."""
    return motion


class RefinedGenerator:
    """A generator whose samples are converted to canonical motions and refined.

    Parameters
    ----------
    generator : object
        The user's generator: an object with ``sample(action, n=n, **kwargs)``, any callable
        ``generator(action, n=n, **kwargs)``, or an object an adapter plugin knows how to sample
        (``refiner_sample_generator`` hook, e.g. ACTOR's ``generate``). It must return the raw
        output its adapter converts.
    adapter : str, optional
        Adapter name (``motion-refiner adapters`` lists them). Default: the first plugin whose
        ``refiner_recognize_generator`` hook recognises ``generator``.
    refiner : object or callable, optional
        An object with ``refine(motion, *, action=None, return_report=False)`` returning a Motion
        (or ``(Motion, report)`` when ``return_report``), or a callable ``(Motion) -> Motion``.
        Default: ``refiner.refinement.motion_refiner.MotionRefiner.pretrained(skeleton)``, the default refiner
        (:func:`refiner.refine`'s ``method="motion"``); when that cannot be imported, the identity with a warning.
    skeleton : str, optional
        Target skeleton, one the adapter produces. Default: the adapter's first.
    adapter_options : mapping, optional
        Keyword options for the adapter's conversion (e.g. ``mean``/``std`` for HumanML3D
        generators, ``smpl_path`` for ACTOR/MLD, ``representation`` for Action2Motion).
    plugin_manager : refiner.plugins.manager.PluginManager, optional
        Default: :func:`refiner.plugins.get_plugin_manager` (built-ins plus installed plugins).

    Attributes
    ----------
    adapter_info : AdapterInfo
        The adapter in use.

    Raises
    ------
    ValueError
        Unknown adapter, no adapter recognises the generator, or a skeleton the adapter cannot produce.
    TypeError
        ``refiner`` is neither a refiner object nor callable.

    Examples
    --------
    >>> import numpy as np
    >>> def a2m_like(action, n=1):                # stands in for Action2Motion's xyz VAE
    ...     return np.zeros((n, 60, 72), dtype=np.float32)
    >>> gen = RefinedGenerator(a2m_like, adapter="action2motion", refiner=lambda m: m,
    ...                        adapter_options={"representation": "xyz"})
    >>> motions = gen.sample(1, n=2)
    >>> len(motions), motions[0].joints.shape, motions[0].action
    (2, (60, 24, 3), 1)
    """

    def __init__(
        self,
        generator: Any,
        adapter: str | None = None,
        refiner: Any = None,
        skeleton: str | None = None,
        *,
        adapter_options: Mapping[str, Any] | None = None,
        plugin_manager: Any = None,
    ) -> None:
        # the plugin machinery loads when a generator is wrapped, not on `import refiner`
        from refiner.plugins.manager import get_plugin_manager

        self.generator = generator
        self.adapter_options = dict(adapter_options or {})
        self._pm = plugin_manager if plugin_manager is not None else get_plugin_manager()
        if adapter is None:
            adapter = self._pm.adapter_for(generator)
            if adapter is None:
                raise ValueError(
                    f"no adapter recognises generator of type {type(generator).__name__}; pass adapter=..., "
                    f"one of: {', '.join(self._pm.adapters()) or '(none installed)'}."
                )
        self.adapter_info = self._pm.get_adapter(adapter)
        self.adapter = self.adapter_info.name
        if skeleton is None:
            skeleton = self.adapter_info.skeletons[0]
        elif skeleton not in self.adapter_info.skeletons:
            raise ValueError(
                f"adapter {self.adapter!r} cannot produce skeleton {skeleton!r}; "
                f"it produces: {', '.join(self.adapter_info.skeletons)}."
            )
        self.skeleton = skeleton
        self.refiner = _default_refiner(skeleton) if refiner is None else refiner
        if not (callable(getattr(self.refiner, "refine", None)) or callable(self.refiner)):
            raise TypeError(
                f"`refiner` must have a refine(motion, *, action, return_report) method or be a callable "
                f"(Motion) -> Motion; got {type(self.refiner).__name__}."
            )

    def sample(self, action: Any, n: int = 1, return_raw: bool = False, return_report: bool = False, **kwargs: Any):
        """Draw ``n`` samples of ``action``, convert them to canonical motions and refine them.

        Parameters
        ----------
        action : int or str
            Action index in the dataset's label set (or a name the generator understands),
            passed to the generator as is. An index (or a HumanAct12 action name) is also given
            to the refiner and stored on motions that carry no label.
        n : int, default=1
            Number of samples.
        return_raw : bool, default=False
            Also return the generator's raw output.
        return_report : bool, default=False
            Also return one refinement report per motion (None from plain-callable refiners).
        **kwargs
            Passed to the generator's sampling call.

        Returns
        -------
        list of Motion
            Refined motions in the target skeleton's canonical frame. With ``return_raw`` and/or
            ``return_report``, a tuple ``(motions, raw, reports)`` holding only the requested parts
            in that order.
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"`n` must be a positive int; got {n!r}.")
        label = _action_index(action, self.skeleton)
        raw = self._pm.sample(self.adapter, self.generator, action, n, kwargs)
        if raw is None:
            raw = self._call_generator(action, n, kwargs)
        motions = self._pm.convert(
            self.adapter, raw, generator=self.generator, skeleton=self.skeleton, options=self.adapter_options
        )
        refined, reports = [], []
        for motion in motions:
            if motion.skeleton != self.skeleton:
                raise ValueError(
                    f"adapter {self.adapter!r} returned skeleton {motion.skeleton!r}; expected {self.skeleton!r}."
                )
            if motion.action is None and label is not None:
                motion = replace(motion, action=label)
            out, report = self._refine(motion, label, return_report)
            refined.append(out)
            reports.append(report)
        extra = ([raw] if return_raw else []) + ([reports] if return_report else [])
        return (refined, *extra) if extra else refined

    def _call_generator(self, action: Any, n: int, kwargs: dict) -> Any:
        """The generator's own ``sample``, else the generator called directly."""
        sample: Callable | None = getattr(self.generator, "sample", None)
        if callable(sample):
            return sample(action, n=n, **kwargs)
        if callable(self.generator):
            return self.generator(action, n=n, **kwargs)
        raise TypeError(
            f"generator of type {type(self.generator).__name__} has no sample() method, is not callable and no "
            f"adapter plugin knows how to sample it."
        )

    def _refine(self, motion: Motion, action: int | None, return_report: bool):
        """Apply the refiner to one motion; returns ``(motion, report)``."""
        refine = getattr(self.refiner, "refine", None)
        report = None
        if callable(refine):
            out = refine(motion, action=action, return_report=return_report)
            if return_report:
                if not (isinstance(out, tuple) and len(out) == 2):
                    raise TypeError("`refiner.refine(..., return_report=True)` must return (Motion, report).")
                out, report = out
        else:
            out = self.refiner(motion)
        if not isinstance(out, Motion):
            raise TypeError(f"the refiner must return a Motion; got {type(out).__name__}.")
        return out, report

    def __repr__(self) -> str:
        return (
            f"RefinedGenerator(generator={type(self.generator).__name__}, adapter={self.adapter!r}, "
            f"skeleton={self.skeleton!r}, refiner={type(self.refiner).__name__})"
        )


def _default_refiner(skeleton: str):
    """``refiner.refinement.motion_refiner.MotionRefiner.pretrained(skeleton)``, the default refiner, or the identity
    with a warning if it cannot be imported."""
    try:
        # on first use: the refiner brings torch and the networks, which `import refiner` must not load
        from refiner.refinement.motion_refiner import MotionRefiner

        pretrained = MotionRefiner.pretrained
    except (ImportError, AttributeError) as e:
        warnings.warn(
            f"the default refiner (refiner.refinement.motion_refiner.MotionRefiner.pretrained) is not available ({e}); "
            f"samples are returned unrefined. Pass refiner=... to choose one.",
            UserWarning,
            stacklevel=3,
        )
        return identity_refiner
    try:
        return pretrained(skeleton)
    except ValueError as e:
        raise ValueError(f"the default refiner MotionRefiner.pretrained({skeleton!r}) failed: {e} Pass refiner=... "
                         f"to choose one.") from e


def _action_index(action: Any, skeleton: str) -> int | None:
    """The action as a label index when it is one (or a HumanAct12 action name), else None."""
    if isinstance(action, (bool, np.bool_)):
        return None
    if isinstance(action, (int, np.integer)):
        return int(action) if action >= 0 else None
    if isinstance(action, str) and skeleton == "humanact12":
        try:
            return check_action(action, HUMANACT12_ACTIONS)
        except ValueError:
            return None
    return None
