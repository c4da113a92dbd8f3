"""The one safetensors codec: tensors plus string metadata, and the learned-component envelope."""
from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Mapping

import numpy as np

__all__ = ["save_state", "load_state", "FORMAT_VERSION", "pack_metadata", "check_metadata", "pack_lower", "unpack_lower",
           "quantize_rows", "dequantize_rows"]

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


def quantize_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric int8 codes of a weight array ``(rows, ...)``, one scale per row (an output unit):
    returns ``(codes int8 same shape, scales (rows,) float32)``, ``a ~= codes * scales`` to within half a
    step (``max |row| / 254``). A row of zeros gets scale 1."""
    a = np.asarray(a, np.float32)
    if a.ndim < 2:
        raise ValueError(f"quantize_rows needs an array of at least 2 dimensions; got shape {a.shape}.")
    if not np.isfinite(a).all():
        raise ValueError("quantize_rows needs finite values; got NaN or Inf.")
    peak = np.abs(a.reshape(len(a), -1)).max(1)
    scales = np.where(peak > 0, peak / 127.0, 1.0).astype(np.float32)
    codes = np.clip(np.rint(a / scales.reshape((-1,) + (1,) * (a.ndim - 1))), -127, 127).astype(np.int8)
    return codes, scales


def dequantize_rows(codes: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """Inverse of :func:`quantize_rows`: ``codes (rows, ...)`` int8 times ``scales (rows,)`` as float32."""
    codes, scales = np.asarray(codes), np.asarray(scales, np.float32)
    if codes.dtype != np.int8 or scales.shape != codes.shape[:1]:
        raise ValueError(f"dequantize_rows needs int8 codes (rows, ...) and one scale per row; got "
                         f"{codes.dtype} {codes.shape} and scales {scales.shape}.")
    return codes.astype(np.float32) * scales.reshape((-1,) + (1,) * (codes.ndim - 1))
