"""Base class of the learned network components: sklearn conventions plus safetensors save/load."""
from __future__ import annotations

import json
import os
from dataclasses import asdict, fields, replace

import numpy as np
import torch
from sklearn.base import BaseEstimator

from refiner.core.serialization import (check_metadata, dequantize_rows, load_state, pack_lower, pack_metadata,
                                        quantize_rows, save_state, unpack_lower)
from refiner.core.validation import check_is_fitted
from refiner.nn.training import TrainSchedule, fit_network, random_crops, resolve_device, seeded, to_device

__all__ = ["NetworkComponent", "NOT_FITTED", "INT8_MIN_SIZE"]

NOT_FITTED = "This %(name)s is not fitted yet; call fit() or load() first."
#: Constructor arguments of estimators that declare the schedule field by field (files saved before
#: ``schedule`` was one hyper-parameter hold them so), with the schedule field each one sets.
_FLAT_SCHEDULE = {**{f.name: f.name for f in fields(TrainSchedule)}, "verbose": "progress"}
#: Weight matrices at least this large are stored as int8 codes by ``save(int8=True)``; biases and
#: norms, a small share of the bytes, keep float16 (their rounding shifts every unit alike).
INT8_MIN_SIZE = 1024


class NetworkComponent(BaseEstimator):
    """A component whose learned state is ``network_`` plus JSON-able fitted attributes.

    Subclasses implement ``_make_network(fitted: dict) -> nn.Module`` and list their non-network
    fitted attributes in ``_fitted_attributes`` (JSON values) and ``_fitted_arrays`` (numpy arrays);
    ``_optional_arrays`` are saved when fitted (float16 with ``half``, like the weights) and loaded
    when in the file (state that only some hyper-parameter values fit). Arrays in
    ``_lower_triangular_arrays`` (Cholesky factors) or ``_symmetric_arrays`` (covariances) are stored
    as their lower triangles.
    Their training settings are one hyper-parameter, ``schedule`` (a :class:`~refiner.nn.training.TrainSchedule`,
    saved as a dict); a subclass that still declares the schedule's fields one by one (``n_epochs``,
    ``batch_size``, ..., ``verbose``) is served too.
    """

    _fitted_attributes: tuple[str, ...] = ()
    #: Values of fitted attributes that files saved before the attribute existed lack (others are required).
    _attribute_defaults: dict = {}
    _fitted_arrays: tuple[str, ...] = ()
    _optional_arrays: tuple[str, ...] = ()
    _lower_triangular_arrays: tuple[str, ...] = ()
    _symmetric_arrays: tuple[str, ...] = ()

    def _fit_on_crops(self, clips: list, validation, flawed, loss, rng: np.random.Generator, *, checkpoint=None,
                      desc: str = "train") -> None:
        """Fit ``network_`` (from ``_make_network`` of ``n_joints_`` and ``skeleton_``) on random ``crop``-frame crops
        of real ``clips`` spoiled by ``flawed(clean, rng)``: batches ``{"flawed", "clean"}`` (N, crop, J, 3) for
        ``loss(network, batch, rng)``; 256 crops of ``validation`` (default the clips) judge the epochs."""
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        held = [np.asarray(c, np.float32) for c in (validation if validation is not None else clips)]
        val_rng = np.random.default_rng(7)
        val_clean = random_crops(held, self.crop, 256, val_rng)
        val = to_device({"flawed": flawed(val_clean, val_rng), "clean": val_clean}, device)

        def batch(idx, r):
            clean = random_crops(clips, self.crop, len(idx), r)
            return to_device({"flawed": flawed(clean, r), "clean": clean}, device)

        with seeded(rng):
            self.network_ = self._make_network({"n_joints_": self.n_joints_, "skeleton_": self.skeleton_}).to(device)
            self.history_ = fit_network(self.network_, loss, batch, len(clips), val, schedule, rng,
                                        checkpoint=checkpoint, desc=desc)
        self.network_.to("cpu").eval()

    def _schedule(self) -> TrainSchedule:
        """The schedule ``fit`` trains with (``ValueError`` when ``schedule`` is not a TrainSchedule)."""
        if "schedule" not in self._get_param_names():
            return TrainSchedule(**{field: getattr(self, name) for name, field in _FLAT_SCHEDULE.items()
                                    if hasattr(self, name)})
        if not isinstance(self.schedule, TrainSchedule):
            raise ValueError(f"`schedule` must be a refiner.nn.training.TrainSchedule; got {self.schedule!r}.")
        return self.schedule

    @classmethod
    def _init_params(cls, params: dict) -> dict:
        """Constructor arguments from a file's params: ``schedule`` back to a TrainSchedule; the flat
        schedule fields of files saved before it was one parameter folded into it (over the class default)."""
        if "schedule" not in cls._get_param_names():
            return params
        params = dict(params)
        saved = params.pop("schedule", None)
        flat = {_FLAT_SCHEDULE[k]: params.pop(k) for k in list(params) if k in _FLAT_SCHEDULE}
        base = cls().schedule if saved is None else TrainSchedule(**saved)
        return {**params, "schedule": replace(base, **flat)}

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

    def save(self, path: str | os.PathLike, *, half: bool = False, int8: bool = False) -> None:
        """Write network weights and fitted state to one ``.safetensors`` file.

        ``half`` stores floating-point weights as float16 (half the size; loading casts back). ``int8``
        stores every weight matrix (a parameter, not a buffer) of at least :data:`INT8_MIN_SIZE` values as
        int8 codes with one float32 scale per output row (about half of float16; loading multiplies back)
        and the rest as with ``half``.
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        tensors = {}
        half = half or int8
        weights = {name for name, _ in self.network_.named_parameters()}  # buffers (fitted arrays) stay exact
        for k, v in self.network_.state_dict().items():
            v = v.detach().cpu().contiguous()
            if int8 and k in weights and v.is_floating_point() and v.ndim >= 2 and v.numel() >= INT8_MIN_SIZE:
                tensors[f"network.{k}.int8"], tensors[f"network.{k}.int8_scale"] = quantize_rows(v.float().numpy())
                continue
            tensors[f"network.{k}"] = v.half() if half and v.is_floating_point() else v
        arrays = {name: np.asarray(getattr(self, name)) for name in self._fitted_arrays}
        arrays.update({name: np.asarray(getattr(self, name), np.float16 if half else None)
                       for name in self._optional_arrays if hasattr(self, name)})
        for name, value in arrays.items():
            lower = name in self._lower_triangular_arrays + self._symmetric_arrays  # the rest follows from it
            tensors[f"array.{name}" + (".lower" if lower else "")] = pack_lower(value) if lower else value
        fitted = {name: _jsonable(getattr(self, name)) for name in self._fitted_attributes}
        save_state(path, tensors, pack_metadata(self, **fitted))

    @classmethod
    def load(cls, path: str | os.PathLike, *, device: str = "cpu"):
        """Rebuild a fitted component from :meth:`save`'s file (strict: every weight must match)."""
        tensors, metadata = load_state(path)
        params, fitted = check_metadata(path, metadata, cls)
        obj = cls(**cls._init_params(params))
        for name in cls._fitted_attributes:
            if name not in fitted and name not in cls._attribute_defaults:
                raise ValueError(f"{str(path)!r} lacks the fitted attribute {name!r} of a {cls.__name__}.")
            setattr(obj, name, fitted[name] if name in fitted else cls._attribute_defaults[name])
        for name in cls._fitted_arrays + cls._optional_arrays:
            if f"array.{name}" in tensors:  # files before the packed layout hold whole matrices
                setattr(obj, name, tensors[f"array.{name}"])
            elif f"array.{name}.lower" in tensors:
                setattr(obj, name, unpack_lower(tensors[f"array.{name}.lower"], symmetric=name in cls._symmetric_arrays))
            elif name in cls._fitted_arrays:
                raise ValueError(f"{str(path)!r} lacks the fitted array {name!r} of a {cls.__name__}.")
        network = obj._make_network(fitted)
        state = {k[len("network."):]: torch.from_numpy(v.copy()).float() if v.dtype == np.float16 else torch.from_numpy(v.copy())
                 for k, v in tensors.items() if k.startswith("network.") and not k.endswith((".int8", ".int8_scale"))}
        for k in [k for k in tensors if k.startswith("network.") and k.endswith(".int8")]:
            name = k[len("network."):-len(".int8")]
            if f"network.{name}.int8_scale" not in tensors:
                raise ValueError(f"{str(path)!r} holds int8 codes for {name!r} without their scales.")
            state[name] = torch.from_numpy(dequantize_rows(tensors[k], tensors[f"network.{name}.int8_scale"]))
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
