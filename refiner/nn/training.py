"""The one shared training loop (appendix A / E.2), its schedule, and the batch helpers: crops and devices.

Adam at 5e-4 with polynomial decay (power 0.95), batch 128, each module trained on its own.
The paper trains for thousands of epochs; we stop early on a validation loss instead, keep the
best weights, and can resume from a checkpoint (safetensors, no pickle).
"""
from __future__ import annotations

import json
import logging
import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from refiner.core.serialization import load_state, save_state

__all__ = ["ClipCrops", "TrainSchedule", "crop_start", "fit_network", "put_crop", "random_crops", "resolve_device", "seeded", "to_device"]

log = logging.getLogger(__name__)


def resolve_device(device: str | None) -> torch.device:
    """``"auto"``/None -> CUDA when available, else CPU; ``ValueError`` for an unknown or unavailable device."""
    if device in (None, "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError) as e:
        raise ValueError(f"unknown `device` {device!r}: {e}") from e
    if resolved.type == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(f"`device` is {device!r} but CUDA is not available here (torch {torch.__version__}); "
                             "use device='cpu' or 'auto'.")
        if resolved.index is not None and resolved.index >= torch.cuda.device_count():
            raise ValueError(f"`device` is {device!r} but only {torch.cuda.device_count()} CUDA device(s) exist.")
    if resolved.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"`device` is {device!r} but MPS is not available here; use device='cpu' or 'auto'.")
    return resolved


def to_device(batch: dict[str, np.ndarray], device) -> dict[str, torch.Tensor]:
    """A batch of numpy arrays as tensors on ``device`` (made contiguous first)."""
    return {k: torch.from_numpy(np.ascontiguousarray(v)).to(device) for k, v in batch.items()}


class seeded:
    """Context manager: torch's RNG forked and seeded from a numpy Generator (the user's RNG untouched)."""

    def __init__(self, rng: np.random.Generator):
        self.seed = int(rng.integers(2**31))
        self._fork = None

    def __enter__(self):
        devices = list(range(torch.cuda.device_count())) if torch.cuda.is_available() else []
        self._fork = torch.random.fork_rng(devices=devices)
        self._fork.__enter__()
        torch.manual_seed(self.seed)
        return self

    def __exit__(self, *exc):
        return self._fork.__exit__(*exc)


@dataclass(frozen=True)
class TrainSchedule:
    """How a learned component is trained: one hyper-parameter, ``schedule``, of every estimator.

    Frozen, so that an estimator's default schedule can be a default argument and ``get_params``
    gives back what was passed. ``n_epochs`` x ``steps_per_epoch`` steps (default: one pass over the
    training items per epoch) of ``batch_size`` items; Adam at ``learning_rate`` with polynomial decay
    (``power``); early stop after ``patience`` epochs without a better validation loss or after
    ``max_seconds``; ``device`` ("auto": CUDA when available); ``progress`` shows a progress bar;
    ``keep_best``: with validation data, training ends on the weights of the best validation loss,
    else on the last epoch's (a generator's samples can go on improving after its validation loss
    stops: docs/decisions.md D13).
    """

    n_epochs: int = 200
    batch_size: int = 128
    learning_rate: float = 5e-4
    power: float = 0.95
    patience: int = 15
    steps_per_epoch: int | None = None
    max_seconds: float | None = None
    device: str = "auto"
    progress: bool = False
    keep_best: bool = True


def crop_start(n_frames: int, length: int, rng: np.random.Generator, *, holding: int | None = None) -> int:
    """A random first frame of a ``length``-frame crop of an ``n_frames`` clip (0 when the clip is no
    longer); with ``holding``, of a crop that contains that frame."""
    lo, hi = 0, max(n_frames - length, 0)
    if holding is not None:
        lo, hi = max(0, holding - length + 1), min(holding, hi)
    return int(rng.integers(lo, max(hi, lo) + 1))


def random_crops(clips: Sequence[np.ndarray], length: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` random ``length``-frame crops ``(n, length, J, 3)`` float32 of clips ``(T_i, J, 3)``, in place (not
    re-centred); a shorter clip's crop repeats its last frame."""
    out = np.zeros((n, length, *np.shape(clips[0])[1:]), np.float32)
    for k, i in enumerate(rng.integers(len(clips), size=n)):
        s = crop_start(len(clips[i]), length, rng)
        put_crop(out, k, clips[i][s : s + length], 0.0)
    return out


def put_crop(out: np.ndarray, b: int, frames: np.ndarray, origin, *, pad: bool = True) -> int:
    """Write ``frames - origin`` to the start of row ``b`` of ``out (B, L, ...)``; with ``pad`` the rest of
    the row repeats the last frame (the A2M convention), else it stays as it was. Returns ``len(frames)``."""
    n = len(frames)
    out[b, :n] = frames - origin
    if pad:
        out[b, n:] = out[b, n - 1]
    return n


class ClipCrops:
    """Random fixed-length crops of clips, re-centred so the crop's first root is at the origin.

    Parameters
    ----------
    clips : sequence of ndarray (T_i, J, 3)
    length : int
        Crop length; shorter clips are padded (``valid`` marks real frames).
    labels : dict of name -> sequence of per-frame arrays (T_i, ...), optional
        Cropped alongside the clips.
    """

    def __init__(self, clips: Sequence[np.ndarray], length: int, labels: dict | None = None):
        self.clips = [np.asarray(c, dtype=np.float32) for c in clips]
        self.length = int(length)
        self.labels = labels or {}

    def __len__(self) -> int:
        return len(self.clips)

    def sample(self, indices: Sequence[int], rng: np.random.Generator) -> dict[str, np.ndarray]:
        n, length = len(indices), self.length
        joints = self.clips[0].shape[1]
        x = np.zeros((n, length, joints, 3), dtype=np.float32)
        valid = np.zeros((n, length), dtype=bool)
        out = {name: None for name in self.labels}
        starts = np.zeros(n, dtype=np.int64)
        for b, i in enumerate(indices):
            clip = self.clips[i]
            start = crop_start(len(clip), length, rng)
            crop = clip[start : start + length]
            valid[b, : put_crop(x, b, crop, crop[:1, :1])] = True
            starts[b] = start
            for name, per_clip in self.labels.items():
                lab = per_clip[i][start : start + length]
                if out[name] is None:
                    out[name] = np.zeros((n, length) + lab.shape[1:], dtype=lab.dtype)
                out[name][b, : len(lab)] = lab
        return {"joints": x, "valid": valid, "starts": starts, **out}


def fit_network(
    network: nn.Module,
    loss_fn: Callable[[nn.Module, dict, np.random.Generator], torch.Tensor],
    make_batch: Callable[[np.ndarray, np.random.Generator], dict],
    n_train: int,
    val_batch: dict | None,
    schedule: TrainSchedule,
    rng: np.random.Generator,
    *,
    checkpoint: str | os.PathLike | None = None,
    desc: str = "train",
) -> list[dict]:
    """Train ``network`` in place; return the per-epoch history of train and validation losses.

    ``make_batch(indices, rng)`` builds a batch (tensors on the right device) for training items
    ``indices``; ``loss_fn(network, batch, rng)`` returns a scalar loss. With ``val_batch`` the
    best weights by validation loss are kept (``schedule.keep_best``) and training stops after ``patience`` epochs without
    improvement. With ``checkpoint`` the state is saved every epoch and a run resumes from it.
    """
    started = time.perf_counter()
    steps = schedule.steps_per_epoch or max(1, int(np.ceil(n_train / schedule.batch_size)))
    total = steps * schedule.n_epochs
    opt = torch.optim.Adam(network.parameters(), lr=schedule.learning_rate)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: max(1.0 - s / total, 0.0) ** schedule.power)
    history: list[dict] = []
    best = (np.inf, None)
    start_epoch = 0
    if checkpoint is not None and Path(checkpoint).is_file():
        start_epoch, history, best = _resume(checkpoint, network, opt, sched)
        log.info("resumed %s from epoch %d", desc, start_epoch)
    bar = tqdm(range(start_epoch, schedule.n_epochs), desc=desc, disable=not schedule.progress)
    for epoch in bar:
        network.train()
        order = rng.permutation(n_train)
        losses = []
        for s in range(steps):
            idx = order[(s * schedule.batch_size) % n_train :][: schedule.batch_size]
            if len(idx) < min(schedule.batch_size, n_train):
                idx = rng.choice(n_train, size=min(schedule.batch_size, n_train), replace=False)
            loss = loss_fn(network, make_batch(idx, rng), rng)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(network.parameters(), 1.0)
            opt.step()
            sched.step()
            losses.append(float(loss.detach()))
        record = {"epoch": epoch, "train": float(np.mean(losses))}
        if val_batch is not None:
            network.eval()
            with torch.no_grad():
                record["val"] = float(loss_fn(network, val_batch, np.random.default_rng(0)))
            if record["val"] < best[0]:
                best = (record["val"], {k: v.detach().clone() for k, v in network.state_dict().items()})
        history.append(record)
        bar.set_postfix({k: f"{v:.4f}" for k, v in record.items() if k != "epoch"})
        if checkpoint is not None:
            _save_checkpoint(checkpoint, network, opt, sched, epoch + 1, history, best)
        if schedule.max_seconds is not None and time.perf_counter() - started > schedule.max_seconds:
            log.info("%s: stopped at the time limit after epoch %d", desc, epoch)
            break
        if val_batch is not None and epoch - int(np.argmin([h["val"] for h in history]) + history[0]["epoch"]) >= schedule.patience:
            break
    if best[1] is not None and schedule.keep_best:
        network.load_state_dict(best[1])
    network.eval()
    return history


def _save_checkpoint(path, network, opt, sched, epoch, history, best) -> None:
    tensors = {f"network.{k}": v for k, v in network.state_dict().items()}
    if best[1] is not None:
        tensors.update({f"best.{k}": v for k, v in best[1].items()})
    params = [p for g in opt.param_groups for p in g["params"]]
    for i, p in enumerate(params):
        for name, value in opt.state.get(p, {}).items():
            tensors[f"adam.{i}.{name}"] = value if torch.is_tensor(value) else torch.tensor(value)
    meta = {"epoch": str(epoch), "history": json.dumps(history), "best": repr(float(best[0])),
            "scheduler_step": str(sched.last_epoch)}
    tmp = Path(str(path) + ".tmp")
    save_state(tmp, {k: v.detach().cpu().contiguous() for k, v in tensors.items()}, meta)
    os.replace(tmp, path)


def _resume(path, network, opt, sched):
    tensors, meta = load_state(path)
    device = next(network.parameters()).device
    network.load_state_dict({k[8:]: torch.from_numpy(v).to(device) for k, v in tensors.items() if k.startswith("network.")})
    params = [p for g in opt.param_groups for p in g["params"]]
    for i, p in enumerate(params):
        state = {k.split(".", 2)[2]: torch.from_numpy(v).to(device) for k, v in tensors.items() if k.startswith(f"adam.{i}.")}
        if state:
            if "step" in state:
                state["step"] = state["step"].cpu()
            opt.state[p] = state
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # stepping the schedule forward without optimizer steps is the point here
        for _ in range(int(meta["scheduler_step"])):
            sched.step()
    best_state = {k[5:]: torch.from_numpy(v).to(device) for k, v in tensors.items() if k.startswith("best.")}
    best = (float(meta["best"]), best_state or None)
    return int(meta["epoch"]), json.loads(meta["history"]), best
