"""What the two reference generators share: the estimator base class, its training data and its training loop.

:class:`ReferenceGenerator` fits on labelled HumanAct12 clips (60-frame crops from
:class:`refiner.nn.training.ClipCrops`, a held-out tenth for early stopping, the shared
:func:`refiner.nn.training.fit_network` loop), samples with a seeded numpy stream and converts its
raw output into :class:`~refiner.Motion` s through the plugin contract (adapter ``action2motion``).
"""
from __future__ import annotations

import os
import time
import warnings
from typing import Sequence

import numpy as np
import torch

from refiner.core.motion import Motion
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_action, check_is_fitted, check_random_state
from refiner.io.datasets import HUMANACT12_ACTIONS
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import ClipCrops, fit_network, resolve_device, seeded
from refiner.plugins.manager import PluginManager, get_plugin_manager

__all__ = ["N_FRAMES", "ReferenceGenerator", "JointsGenerator", "median_bone_pose", "normal_noise", "pad_with_last_frame",
           "training_crops", "training_data"]

#: Crop length of the shipped generators (frames at 20 fps).
N_FRAMES = 60


class ReferenceGenerator(NetworkComponent):
    """Base of the reference generators: training, action look-up, seeded sampling, conversion to Motions.

    Subclasses set :attr:`adapter`, ``_desc`` (the progress-bar label) and implement
    ``_make_network``, ``_fit_statistics(clips)`` (fitted statistics of the training clips),
    ``_crops(clips) -> ClipCrops``, ``_batch(crops, actions, device) -> dict`` (one training batch
    from :meth:`ClipCrops.sample`'s output), ``_loss``, ``_draw(network, actions, rng) -> ndarray``
    (the raw samples of :meth:`sample`) and :meth:`adapter_options`.
    """

    #: Adapter that converts this generator's raw output (see :meth:`adapter_options`).
    adapter = "action2motion"
    _desc = "reference generator"

    def fit(self, data, *, checkpoint: str | os.PathLike | None = None) -> "ReferenceGenerator":
        """Train on labelled HumanAct12 clips (a MotionDataset or a sequence of Motions); returns self.

        With ``checkpoint`` (a path) the training state is saved there every epoch and a run that
        finds the file resumes from it. With ``warm_start`` a fitted generator goes on training its
        network under the current ``schedule`` (the same action names and fitted statistics).
        """
        warm = bool(getattr(self, "warm_start", False)) and hasattr(self, "network_")
        if warm and list(self.action_names or self.action_names_) != list(self.action_names_):
            raise ValueError("`warm_start` needs the fitted generator's action names; got different ones.")
        self.action_names = list(self.action_names or HUMANACT12_ACTIONS)
        _check_schedule(self)
        rng = check_random_state(self.random_state)
        device = resolve_device(self._schedule().device)
        started = time.perf_counter()
        clips, labels, val_clips, val_labels = self._split(data, rng)
        self.action_names_ = list(self.action_names)
        previous = (list(self.history_), float(self.train_seconds_)) if warm else ([], 0.0)
        if not warm:
            self._fit_statistics(clips)
        train = self._crops(clips)
        val = self._crops(val_clips) if val_clips else None

        def batch(crops: ClipCrops, labs: np.ndarray, idx, r: np.random.Generator) -> dict:
            actions = torch.from_numpy(labs[np.asarray(idx)]).to(device)
            return self._batch(crops.sample(idx, r), actions, device)

        with seeded(rng):
            if not warm:
                self.network_ = self._make_network({"action_names_": self.action_names_})
            self.network_.to(device)
            val_batch = None if val is None else batch(val, val_labels, np.arange(len(val)), np.random.default_rng(0))
            history = fit_network(self.network_, self._loss, lambda idx, r: batch(train, labels, idx, r),
                                  len(train), val_batch, self._schedule(), rng, checkpoint=checkpoint, desc=self._desc)
        offset = len(previous[0])
        self.history_ = previous[0] + [{**h, "epoch": h["epoch"] + offset} for h in history]
        self.train_seconds_ = round(previous[1] + time.perf_counter() - started, 1)
        return self

    def adapter_options(self) -> dict:
        """Options for the adapter's conversion of :meth:`sample`'s output."""
        raise NotImplementedError

    def to_motions(self, raw, action=None, *, plugin_manager: PluginManager | None = None) -> list[Motion]:
        """Convert :meth:`sample`'s raw output into canonical motions with the ``action2motion`` adapter.

        Parameters
        ----------
        raw : ndarray
            Output of :meth:`sample`.
        action : int or str, optional
            Label stored on every motion.
        plugin_manager : refiner.plugins.manager.PluginManager, optional
            Default: the built-in adapters only.

        Returns
        -------
        list of Motion
            HumanAct12 motions, metres, y-down native frame, first-frame root at the origin.
        """
        pm = plugin_manager if plugin_manager is not None else get_plugin_manager(autoload=False)
        motions = pm.convert(self.adapter, raw, skeleton="humanact12", options=self.adapter_options())
        if action is None:
            return motions
        label = self._action(action)
        return [Motion(m.joints, skeleton=m.skeleton, fps=m.fps, action=label) for m in motions]

    def sample_motions(self, action, n: int = 1, *, random_state=None) -> list[Motion]:
        """:meth:`sample` followed by :meth:`to_motions` (unrefined motions)."""
        return self.to_motions(self.sample(action, n, random_state=random_state), action)

    @torch.no_grad()
    def sample(self, action, n: int = 1, *, random_state=None) -> np.ndarray:
        """Draw ``n`` clips of ``action`` from the generator's prior.

        Parameters
        ----------
        action : int or str
            HumanAct12 action index or name.
        n : int, default=1
        random_state : None, int or numpy Generator, optional

        Returns
        -------
        ndarray of shape (n, n_frames, 72) or (n, n_frames, 24, 3), float32
            The generator's raw output: :class:`~refiner.reference.LieVAEGenerator` emits
            Action2Motion's Lie layout (per frame the root position in metres and 23 axis-angle
            vectors in rad), :class:`~refiner.reference.TransformerCVAEGenerator` joint positions in
            metres (HumanAct12's y-down frame, first-frame root near the origin). Convert with
            :meth:`to_motions`.
        """
        label, n = self._action(action), self._check_n(n)
        rng = check_random_state(random_state)
        actions = torch.full((n,), label, dtype=torch.long, device=self.device_)
        return self._draw(self.network_.eval(), actions, rng)

    def _action(self, action) -> int:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return check_action(action, self.action_names_)

    def _check_n(self, n) -> int:
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"`n` must be a positive int; got {n!r}.")
        return int(n)

    def _split(self, data, rng):
        """``(clips, labels)`` of the training data and a held-out tenth for early stopping."""
        clips, labels = training_data(data, len(self.action_names))
        order = rng.permutation(len(clips))
        n_val = max(1, len(clips) // 10) if len(clips) > 1 else 0
        val, train = order[:n_val], order[n_val:] if n_val else order
        return [clips[i] for i in train], labels[train], [clips[i] for i in val], labels[val]



class JointsGenerator(ReferenceGenerator):
    """A reference generator of normalised joint positions (per-joint mean and std of the training crops,
    ``mean_`` and ``std_`` (24, 3) metres), converted by the ``action2motion`` adapter's xyz path."""

    _fitted_arrays = ("mean_", "std_")

    def _fit_statistics(self, clips: Sequence[np.ndarray]) -> None:
        stats = ClipCrops(clips, self.n_frames).sample(range(len(clips)), np.random.default_rng(0))["joints"]
        self.mean_ = stats.mean((0, 1)).astype(np.float32)
        self.std_ = np.maximum(stats.std((0, 1)), 1e-3).astype(np.float32)

    def _crops(self, clips: Sequence[np.ndarray]) -> ClipCrops:
        return ClipCrops(clips, self.n_frames)  # re-centred: the crop's first root at the origin

    def _normalised(self, crops: dict, device) -> torch.Tensor:
        """``(B, T, 24, 3)`` normalised joints of :meth:`ClipCrops.sample`'s output."""
        mean, std = torch.from_numpy(self.mean_).to(device), torch.from_numpy(self.std_).to(device)
        return (torch.from_numpy(crops["joints"]).to(device) - mean) / std

    def _metres(self, x: np.ndarray) -> np.ndarray:
        """Normalised ``(..., 24, 3)`` back to metres, float32."""
        return (x * self.std_ + self.mean_).astype(np.float32)

    def adapter_options(self) -> dict:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return {"representation": "xyz", "recenter": True}

def pad_with_last_frame(crops: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fill the frames after each crop's last valid one with that frame, in place (the A2M convention).

    ``crops (B, T, ...)``, ``valid (B, T)`` bool, a prefix of True per crop (``ClipCrops.sample``'s
    ``valid``: :class:`~refiner.nn.training.ClipCrops` pads its joints so, its per-frame labels with zeros).
    """
    for b, n in enumerate(valid.sum(axis=1)):
        crops[b, n:] = crops[b, n - 1]
    return crops


def training_crops(clips: Sequence[np.ndarray], n_frames: int, rng: np.random.Generator,
                   indices: Sequence[int] | None = None) -> np.ndarray:
    """Deprecated (goes in 0.3): random ``n_frames`` crops of per-frame arrays, padded with the last frame.

    Use :class:`refiner.nn.training.ClipCrops`, the one crop batcher (per-frame arrays other than joints
    go in its ``labels``); this is it, with the crops as stored (not re-centred) and float32.

    Returns
    -------
    ndarray of shape (len(indices), n_frames, ...), float32
    """
    warnings.warn("refiner.reference.training_crops is deprecated; use refiner.nn.training.ClipCrops "
                  "(it goes in 0.3).", DeprecationWarning, stacklevel=2)
    indices = range(len(clips)) if indices is None else indices
    frames = [np.zeros((len(c), 1, 3), dtype=np.float32) for c in clips]  # ClipCrops crops these; we want the labels
    sample = ClipCrops(frames, n_frames, {"x": [np.asarray(c) for c in clips]}).sample(indices, rng)
    return pad_with_last_frame(sample["x"].astype(np.float32), sample["valid"])


def normal_noise(rng: np.random.Generator, shape, like: torch.Tensor) -> torch.Tensor:
    """Standard normal noise from the numpy stream (reproducible), as a float32 tensor on ``like``'s device."""
    return torch.from_numpy(rng.standard_normal(tuple(shape)).astype(np.float32)).to(like.device)


def median_bone_pose(clips: Sequence[np.ndarray]) -> np.ndarray:
    """The first frame of the clip whose bone lengths are closest to the per-bone medians, ``(24, 3)`` float32."""
    skel = get_skeleton("humanact12")
    firsts = np.stack([c[0] for c in clips]).astype(np.float64)
    lengths = skel.bone_lengths(firsts)  # (N, B)
    best = int(np.argmin(np.abs(lengths - np.median(lengths, 0)).sum(1)))
    return firsts[best].astype(np.float32)


def training_data(data, n_actions: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Joints and labels of a MotionDataset or a sequence of labelled humanact12 Motions."""
    motions = getattr(data, "motions", data)
    if isinstance(motions, Motion):
        motions = [motions]
    try:
        motions = list(motions)
    except TypeError:
        raise ValueError(f"training data must be a MotionDataset or a sequence of Motion; got {type(data).__name__}.") from None
    if not motions:
        raise ValueError("training data must hold at least one clip; got none.")
    for i, m in enumerate(motions):
        if not isinstance(m, Motion):
            raise ValueError(f"training clip {i} must be a Motion; got {type(m).__name__}.")
        if m.skeleton != "humanact12":
            raise ValueError(f"training clip {i} has skeleton {m.skeleton!r}; the reference generators need 'humanact12'.")
        if m.action is None or not 0 <= m.action < n_actions:
            raise ValueError(f"training clip {i} must have an action label in 0..{n_actions - 1}; got {m.action!r}.")
    return [np.array(m.joints, dtype=np.float32) for m in motions], np.array([m.action for m in motions], dtype=np.int64)


def _check_schedule(est) -> None:
    """ValueError for schedule values the training loop cannot use."""
    schedule = est._schedule()
    for name, v in (("n_epochs", schedule.n_epochs), ("batch_size", schedule.batch_size), ("n_frames", est.n_frames)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"`{name}` must be a positive int; got {v!r}.")
    if est.n_frames > N_FRAMES + 4:
        raise ValueError(f"`n_frames` must be at most {N_FRAMES + 4}; got {est.n_frames}.")
