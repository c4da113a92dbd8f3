"""Input validation shared by every public entry point (our ``check_array``).

Each public function calls one of these once; the layers below trust their input. All checks
return new arrays, so the caller's data are never modified.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import check_is_fitted

from refiner.core.skeletons import Skeleton, get_skeleton

__all__ = [
    "NotFittedError",
    "check_is_fitted",
    "check_joints",
    "check_action",
    "check_random_state",
    "to_numpy",
]


def to_numpy(x, *, name: str = "seq") -> np.ndarray:
    """Convert an array-like (numpy, torch, nested lists) to a numpy array without sharing memory.

    Torch tensors: bfloat16 becomes float32 (exact; numpy has no bfloat16); sparse tensors and tensors
    on the ``meta`` device (no values) raise ``ValueError``.
    """
    if hasattr(x, "detach") and hasattr(x, "cpu"):
        x = _tensor_to_numpy(x, name)
    try:
        arr = np.array(x, dtype=np.float64 if not isinstance(x, np.ndarray) else None, copy=True)
    except (TypeError, ValueError) as e:
        raise ValueError(f"`{name}` must be convertible to a numeric array; got {type(x).__name__}: {e}") from e
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValueError(f"`{name}` must hold numbers; got dtype {arr.dtype}.")
    if np.issubdtype(arr.dtype, np.complexfloating):  # casting would silently drop the imaginary part
        raise ValueError(f"`{name}` must hold real numbers; got dtype {arr.dtype}.")
    return arr


def check_joints(
    x,
    *,
    name: str = "seq",
    skeleton: str | Skeleton | None = None,
    min_frames: int = 2,
    max_frames: int | None = None,
    batched: bool = False,
) -> np.ndarray:
    """Return a float32 copy of joint positions, raising ``ValueError`` naming any problem.

    Parameters
    ----------
    x : array-like of shape (T, J, 3), or (B, T, J, 3) when ``batched``
        Joint positions.
    name : str, default="seq"
        Argument name used in messages.
    skeleton : str or Skeleton, optional
        When given, J must equal its joint count.
    min_frames, max_frames : int
        Bounds on T.
    batched : bool, default=False
        Expect a leading batch axis.

    Returns
    -------
    ndarray, float32, C-contiguous, a new array.
    """
    arr = to_numpy(x, name=name)
    ndim = 4 if batched else 3
    pattern = "(B, T, J, 3)" if batched else "(T, J, 3)"
    skel = get_skeleton(skeleton) if skeleton is not None else None
    if arr.ndim != ndim or arr.shape[-1] != 3:
        want = f" with J={skel.n_joints} for skeleton {skel.name!r}" if skel else ""
        raise ValueError(f"`{name}` must have shape {pattern}{want}; got {tuple(arr.shape)}.")
    if skel is not None and arr.shape[-2] != skel.n_joints:
        raise ValueError(
            f"`{name}` must have shape {pattern} with J={skel.n_joints} for skeleton {skel.name!r}; "
            f"got {tuple(arr.shape)}."
        )
    n_frames = arr.shape[-3]
    if n_frames < min_frames:
        raise ValueError(f"`{name}` is too short: needs at least {min_frames} frames; got {n_frames}.")
    if max_frames is not None and n_frames > max_frames:
        raise ValueError(f"`{name}` is too long: at most {max_frames} frames; got {n_frames}.")
    if batched and arr.shape[0] == 0:
        raise ValueError(f"`{name}` is an empty batch; got shape {tuple(arr.shape)}.")
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    bad = ~np.isfinite(arr)
    if bad.any():
        first = np.argwhere(bad)[0]
        n_nan, n_inf = int(np.isnan(arr).sum()), int(np.isinf(arr).sum())
        where = (
            f"clip {first[0]}, frame {first[1]}, joint {first[2]}" if batched
            else f"frame {first[0]}, joint {first[1]}"
        )
        raise ValueError(f"`{name}` contains {n_nan} NaN and {n_inf} Inf values (first at {where}).")
    return arr


def check_action(action, actions: Sequence[str], *, name: str = "action") -> int:
    """Return the action index for an index or a name from ``actions``.

    Raises
    ------
    ValueError
        For an out-of-range index or an unknown name, listing the valid ones.
    """
    if isinstance(action, (bool, np.bool_)):
        raise ValueError(f"`{name}` must be an action index or name; got {action!r}.")
    if isinstance(action, (int, np.integer)):
        if 0 <= int(action) < len(actions):
            return int(action)
        raise ValueError(f"`{name}` index must be in 0..{len(actions) - 1}; got {int(action)}.")
    if isinstance(action, str):
        key = action.strip().lower().replace(" ", "_")
        for i, a in enumerate(actions):
            if a.lower().replace(" ", "_") == key:
                return i
        raise ValueError(f"unknown {name} {action!r}; known: {', '.join(actions)}.")
    raise ValueError(f"`{name}` must be an action index or name; got {type(action).__name__}.")


def check_random_state(random_state) -> np.random.Generator:
    """A ``numpy.random.Generator`` from None, an int seed or a Generator (never the global RNG)."""
    if isinstance(random_state, np.random.Generator):
        return random_state
    if random_state is None or isinstance(random_state, (int, np.integer)):
        return np.random.default_rng(random_state)
    raise ValueError(f"`random_state` must be None, an int or a numpy Generator; got {random_state!r}.")


def _tensor_to_numpy(x, name: str) -> np.ndarray:
    """A torch tensor's values as numpy, refusing what has no dense values to read."""
    import torch

    if x.layout != torch.strided:
        raise ValueError(f"`{name}` must be a dense tensor; got layout {x.layout} (call .to_dense() first).")
    if x.device.type == "meta":
        raise ValueError(f"`{name}` is on the 'meta' device, which holds shapes but no values.")
    x = x.detach().cpu()
    return (x.float() if x.dtype == torch.bfloat16 else x).numpy()
