"""The one safetensors codec: tensors plus string metadata, and the learned-component envelope."""
from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Mapping

import numpy as np

__all__ = ["save_state", "load_state", "FORMAT_VERSION", "pack_metadata", "check_metadata", "pack_lower", "unpack_lower"]

FORMAT_VERSION = "1"


def save_state(path: str | os.PathLike, tensors: Mapping[str, object], metadata: Mapping[str, str]) -> None:
    """Write tensors (numpy arrays or torch tensors) and string metadata to one ``.safetensors`` file.

    Arrays are saved with their dtype and shape unchanged, so a load gives them back bit-exact.
    """
    from safetensors.numpy import save_file

    arrays = {}
    for key, value in tensors.items():
        if hasattr(value, "detach"):
            value = value.detach().cpu().numpy()
        arr = np.ascontiguousarray(np.asarray(value))
        if arr.dtype == object:
            raise ValueError(f"tensor {key!r} must be numeric; got dtype object.")
        arrays[key] = arr
    bad = {k: type(v).__name__ for k, v in metadata.items() if not isinstance(v, str)}
    if bad:
        raise ValueError(f"metadata values must be strings; got {bad}.")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    save_file(arrays, str(path), metadata=dict(metadata))


def load_state(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Read a ``.safetensors`` file into ``({name: ndarray}, metadata)``."""
    from safetensors import safe_open

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no weights file at {str(path)!r}.")
    try:
        with safe_open(str(path), framework="np") as f:
            metadata = dict(f.metadata() or {})
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except Exception as e:  # safetensors raises its own error types for corrupt headers
        raise ValueError(f"{str(path)!r} is not a readable safetensors file: {e}") from e
    return tensors, metadata


def pack_metadata(obj, **fitted) -> dict[str, str]:
    """Metadata envelope of a learned component: class, format version, params and fitted state."""
    return {
        "refiner.class": type(obj).__name__,
        "refiner.format_version": FORMAT_VERSION,
        "refiner.params": json.dumps(obj.get_params(), default=asdict),  # a dataclass parameter as its dict
        "refiner.fitted": json.dumps(fitted),
    }


def check_metadata(path, metadata: Mapping[str, str], cls) -> tuple[dict, dict]:
    """Check a file's envelope against ``cls``; return ``(params, fitted)``."""
    found = metadata.get("refiner.class")
    if found != cls.__name__:
        raise ValueError(f"{str(path)!r} holds a {found!r}, expected a {cls.__name__!r}.")
    version = metadata.get("refiner.format_version")
    if version != FORMAT_VERSION:
        raise ValueError(f"{str(path)!r} has format version {version!r}, expected {FORMAT_VERSION!r}.")
    return json.loads(metadata["refiner.params"]), json.loads(metadata.get("refiner.fitted", "{}"))


def pack_lower(a: np.ndarray) -> np.ndarray:
    """The lower triangles of square matrices ``(..., n, n)`` as ``(..., n (n + 1) / 2)`` (row by row):
    a Cholesky factor or a symmetric matrix stored in about half the bytes."""
    a = np.asarray(a)
    if a.ndim < 2 or a.shape[-1] != a.shape[-2]:
        raise ValueError(f"pack_lower needs square matrices (..., n, n); got shape {a.shape}.")
    rows, cols = np.tril_indices(a.shape[-1])
    return a[..., rows, cols]


def unpack_lower(packed: np.ndarray, *, symmetric: bool = False) -> np.ndarray:
    """Inverse of :func:`pack_lower`: ``(..., m)`` -> ``(..., n, n)``, zeros above the diagonal, or the
    mirror of the lower triangle with ``symmetric``. Raises ValueError if ``m`` is not a triangular number."""
    packed = np.asarray(packed)
    m = packed.shape[-1]
    n = int(round((np.sqrt(8 * m + 1) - 1) / 2))
    if n * (n + 1) // 2 != m:
        raise ValueError(f"{m} values are not the lower triangle of a square matrix.")
    out = np.zeros(packed.shape[:-1] + (n, n), packed.dtype)
    rows, cols = np.tril_indices(n)
    out[..., rows, cols] = packed
    if symmetric:
        out[..., cols, rows] = packed
    return out
