"""Base class of the learned network components: sklearn conventions plus safetensors save/load."""
from __future__ import annotations

import json
import os
from dataclasses import asdict

import numpy as np
import torch
from sklearn.base import BaseEstimator

from refiner.core.serialization import check_metadata, load_state, pack_metadata, save_state
from refiner.core.validation import check_is_fitted
from refiner.nn.training import TrainSchedule, resolve_device

__all__ = ["NetworkComponent", "NOT_FITTED"]

NOT_FITTED = "This %(name)s is not fitted yet; call fit() or load() first."


class NetworkComponent(BaseEstimator):
    """A component whose learned state is ``network_`` plus JSON-able fitted attributes.

    Subclasses implement ``_make_network(fitted: dict) -> nn.Module`` and list their non-network
    fitted attributes in ``_fitted_attributes`` (JSON values) and ``_fitted_arrays`` (numpy arrays).
    """

    _fitted_attributes: tuple[str, ...] = ()
    _fitted_arrays: tuple[str, ...] = ()

    def _schedule(self) -> TrainSchedule:
        return TrainSchedule(
            n_epochs=self.n_epochs, batch_size=self.batch_size, learning_rate=self.learning_rate,
            patience=self.patience, steps_per_epoch=self.steps_per_epoch, max_seconds=self.max_seconds, device=self.device,
            progress=self.verbose,
        )

    @property
    def device_(self) -> torch.device:
        return next(self.network_.parameters()).device

    def to(self, device: str | torch.device) -> "NetworkComponent":
        """Move the fitted network to ``device`` (``"auto"`` picks CUDA when available)."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        self.network_.to(resolve_device(device) if isinstance(device, str) else device)
        return self

    def n_parameters(self) -> int:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return sum(p.numel() for p in self.network_.parameters())

    def save(self, path: str | os.PathLike, *, half: bool = False) -> None:
        """Write network weights and fitted state to one ``.safetensors`` file.

        ``half`` stores floating-point weights as float16 (half the size; loading casts back).
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        tensors = {}
        for k, v in self.network_.state_dict().items():
            v = v.detach().cpu().contiguous()
            tensors[f"network.{k}"] = v.half() if half and v.is_floating_point() else v
        tensors.update({f"array.{name}": np.asarray(getattr(self, name)) for name in self._fitted_arrays})
        fitted = {name: _jsonable(getattr(self, name)) for name in self._fitted_attributes}
        save_state(path, tensors, pack_metadata(self, **fitted))

    @classmethod
    def load(cls, path: str | os.PathLike, *, device: str = "cpu"):
        """Rebuild a fitted component from :meth:`save`'s file (strict: every weight must match)."""
        tensors, metadata = load_state(path)
        params, fitted = check_metadata(path, metadata, cls)
        obj = cls(**params)
        for name in cls._fitted_attributes:
            setattr(obj, name, fitted[name])
        for name in cls._fitted_arrays:
            setattr(obj, name, tensors[f"array.{name}"])
        network = obj._make_network(fitted)
        state = {k[len("network."):]: torch.from_numpy(v.copy()).float() if v.dtype == np.float16 else torch.from_numpy(v.copy())
                 for k, v in tensors.items() if k.startswith("network.")}
        try:
            network.load_state_dict(state, strict=True)
        except RuntimeError as e:
            raise ValueError(f"{str(path)!r} does not match a {cls.__name__} built from its own config: {e}") from e
        obj.network_ = network.to(resolve_device(device)).eval()
        return obj


def _jsonable(value):
    if hasattr(value, "__dataclass_fields__"):
        return asdict(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    json.dumps(value)
    return value
