"""What every converter shares besides its maths: raw-input and option checks, model-file look-up, re-centring.

Input side: :func:`check_raw` (a checked float64 copy of a raw generator tensor), :func:`call_with_options`
(the body of a ``refiner_convert_output`` hook: user options checked against the converter's
keyword-only parameters) and :func:`resolve_path` (model files given by argument or environment
variable). Output side: :func:`recenter`, the first-frame re-centring of generator_formats.md §0.
"""
from __future__ import annotations

import inspect
import os
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from refiner.core.validation import to_numpy

__all__ = ["call_with_options", "check_raw", "recenter", "resolve_path"]


def check_raw(x, *, name: str, ndims: tuple[int, ...], last: tuple[int, ...] | None = None, what: str = "") -> np.ndarray:
    """Float64 copy of a raw generator tensor, checking its rank, last axis and finiteness.

    Raises ``ValueError`` naming ``name``, the expected shape ``what`` and the shape found.
    """
    arr = to_numpy(x, name=name).astype(np.float64, copy=False)
    expected = what or f"{' or '.join(f'{d}-D' for d in ndims)} with last axis in {last}"
    if arr.ndim not in ndims or (last is not None and arr.shape[-1] not in last):
        raise ValueError(f"`{name}` must have shape {expected}; got {tuple(arr.shape)}.")
    if arr.size == 0:
        raise ValueError(f"`{name}` is empty; got shape {tuple(arr.shape)}.")
    if not np.isfinite(arr).all():
        raise ValueError(f"`{name}` contains {int((~np.isfinite(arr)).sum())} NaN or Inf values.")
    return arr


def call_with_options(fn: Callable[..., Any], output: Any, options: Mapping[str, Any], *, adapter: str,
                      skeleton: str | None = None) -> Any:
    """Call ``fn(output, **options)``, turning unknown option names into a ``ValueError`` listing the valid ones.

    The accepted names are ``fn``'s keyword-only parameters. A target ``skeleton`` (the hook's argument)
    is passed as the option of that name when it is not None.
    """
    if skeleton is not None:
        options = {**options, "skeleton": skeleton}
    params = inspect.signature(fn).parameters
    accepted = [p for p, v in params.items() if v.kind is inspect.Parameter.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise ValueError(
            f"unknown option(s) {', '.join(map(repr, unknown))} for adapter {adapter!r}; "
            f"accepted: {', '.join(accepted)}."
        )
    return fn(output, **options)


def resolve_path(value, *, param: str, env: str, what: str, default_name: str | None = None,
                 origin: str = "") -> Path:
    """The file given by ``value``, else by ``$env``; a folder is searched for ``default_name``.

    Raises ``ValueError`` naming the parameter, the environment variable, the expected file name and
    where the file comes from (``origin``) when neither points to an existing file.
    """
    source = f"`{param}`"
    if value is None:
        value = os.environ.get(env)
        source = f"${env}"
    where = f" Get it from {origin}." if origin else ""
    if value is None or str(value) == "":
        raise ValueError(f"{what} is needed: pass `{param}=` (a file path) or set the environment variable {env}"
                         + (f" (a file, or a folder holding {default_name})." if default_name else ".") + where)
    path = Path(value).expanduser()
    if path.is_dir() and default_name is not None:
        path = path / default_name
    if not path.is_file():
        raise ValueError(f"{what} not found: {source} points to {str(path)!r}, which is not a file.{where}")
    return path


def recenter(joints, root: int = 0) -> np.ndarray:
    """Translate ``(..., T, J, 3)`` so that the root of the first frame is at the origin (a new float64 array)."""
    joints = np.asarray(joints, dtype=np.float64)
    return joints - joints[..., :1, root : root + 1, :]
