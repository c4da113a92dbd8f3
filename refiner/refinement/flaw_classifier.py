"""Flaw recognition from kinematic evidence: a small temporal convolution network over :func:`flaw_features`.

The transformer recogniser (:class:`~refiner.refinement.learned_refinement.FlawRecognizer`) reads raw
positions and must learn what an acceleration spike or a skating foot is; within a CPU budget it
did not (ROC AUC 0.53-0.69 on the benchmark's families after 6,000 steps). This classifier reads
those quantities directly (:mod:`refiner.refinement.flaw_features`) and learns, from the same synthetic
training flaws (:mod:`refiner.refinement.training_flaws`), which combinations over about 30 frames of
context mean a flaw. It is action-agnostic, so it serves any skeleton and unknown actions.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from refiner.core.signal import run_peak
from refiner.core.skeletons import get_skeleton, rigid_skeleton
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule, crop_start, fit_network, resolve_device, seeded, to_device
from refiner.refinement.flaw_features import N_FEATURES, flaw_features
from refiner.refinement.flaw_training import FLAW_LABEL_CM, IGNORE_BELOW_CM
from refiner.refinement.training_flaws import GROUPS, synthesize

__all__ = ["FlawClassifier", "FlawTCN"]


class FlawTCN(nn.Module):
    """``(B, T, F)`` standardised features -> ``(B, T, 1 + G)`` logits: flaw, then each flaw group of
    :data:`refiner.refinement.training_flaws.GROUPS`; dilated residual 1-D convolutions."""

    def __init__(self, n_features: int = N_FEATURES, hidden: int = 64, n_layers: int = 4, kernel: int = 5,
                 dropout: float = 0.1, n_groups: int = len(GROUPS)):
        super().__init__()
        self.inp = nn.Conv1d(n_features, hidden, 1)
        self.blocks = nn.ModuleList(
            nn.Conv1d(hidden, hidden, kernel, dilation=2**i, padding=(kernel // 2) * 2**i) for i in range(n_layers))
        self.drop = nn.Dropout(dropout)
        self.out = nn.Conv1d(hidden, 1 + n_groups, 1)

    def forward(self, feats: torch.Tensor) -> torch.Tensor:
        h = self.inp(feats.transpose(1, 2))
        for block in self.blocks:
            h = h + self.drop(F.gelu(block(h)))
        return self.out(h).transpose(1, 2)


class FlawClassifier(NetworkComponent):
    """Per-frame flaw probability from kinematic features (see the module docstring).

    Parameters
    ----------
    hidden, n_layers, kernel, dropout : network sizes (receptive field ``1 + (kernel - 1) (2^n_layers - 1)``)
    copies : int, default=8
        Flawed versions of each training clip (random mechanisms, see :func:`refiner.refinement.training_flaws.synthesize`).
    crop : int, default=64
        Training crop length.
    rigid_tolerance : float or None, default=0.005
        The refiner puts a clip whose bones vary more than this on rigid bones before detection
        (:func:`refiner.core.skeletons.rigid_skeleton`), so training crops get the same
        treatment after their flaws (None: not); the labels are what is left of the flaw.
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=30, batch_size=64, learning_rate=1e-3, patience=8, steps_per_epoch=100)
        Epochs, batch size, learning rate, device, ... (:class:`~refiner.nn.training.TrainSchedule`).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : FlawTCN
    mean_, scale_ : ndarray (F,)
        Feature standardisation.
    skeleton_ : str
    threshold_ : float
        Probability above which a frame is flagged (:meth:`calibrate`).
    history_ : list of dict
    """

    _fitted_attributes = ("skeleton_", "threshold_", "history_")
    _fitted_arrays = ("mean_", "scale_")

    def __init__(self, *, hidden: int = 64, n_layers: int = 4, kernel: int = 5, dropout: float = 0.1, copies: int = 8,
                 crop: int = 64, rigid_tolerance: float | None = 0.005,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=30, batch_size=64, learning_rate=1e-3, patience=8,
                                                         steps_per_epoch=100),
                 random_state: int | None = 0):
        self.hidden = hidden
        self.n_layers = n_layers
        self.kernel = kernel
        self.dropout = dropout
        self.copies = copies
        self.crop = crop
        self.rigid_tolerance = rigid_tolerance
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> FlawTCN:
        return FlawTCN(N_FEATURES, self.hidden, self.n_layers, self.kernel, self.dropout)

    def _examples(self, clips, rng, copies: int) -> dict[str, np.ndarray]:
        """Flawed crops of ``clips``: features ``(N, L, F)``, labels, loss mask and valid frames."""
        n_items = len(clips) * copies
        feats = np.zeros((n_items, self.crop, N_FEATURES), np.float32)
        label = np.zeros((n_items, self.crop, 1 + len(GROUPS)), np.float32)
        weight = np.zeros((n_items, self.crop), np.float32)
        k = 0
        for clip in clips:
            for _ in range(copies):
                start = crop_start(len(clip), self.crop, rng)
                crop = np.asarray(clip[start : start + self.crop], np.float64)
                if len(crop) < 8:
                    continue
                donor = clips[int(rng.integers(len(clips)))]
                flaw = synthesize(crop, rng, skeleton=self.skeleton_, donors=[donor], clean_probability=0.3)
                flawed = flaw.joints
                if self.rigid_tolerance is not None:
                    flawed = rigid_skeleton(flawed, self.skeleton_, self.rigid_tolerance)[0]
                disp = 100 * np.linalg.norm(flawed - crop, axis=-1).mean(-1)
                m = len(crop)
                feats[k, :m] = flaw_features(flawed, self.skeleton_)
                feats[k, m:] = feats[k, m - 1]
                label[k, :m, 0] = disp > FLAW_LABEL_CM
                label[k, :m, 1:] = flaw.group_touched & (disp > FLAW_LABEL_CM)[:, None]
                weight[k, :m] = ~(flaw.touched & (disp > IGNORE_BELOW_CM) & (disp <= FLAW_LABEL_CM))
                k += 1
        return {"feats": feats[:k], "label": label[:k], "weight": weight[:k]}

    def fit(self, clips, *, skeleton: str = "humanact12", validation=None, checkpoint=None) -> "FlawClassifier":
        """Train on real clips ``(T_i, J, 3)`` metres with synthetic flaws; ``validation``: held-out clips."""
        rng = check_random_state(self.random_state)
        self.skeleton_ = get_skeleton(skeleton).name
        self.threshold_ = 0.5
        train = self._examples(list(clips), rng, self.copies)
        val = self._examples(list(validation if validation is not None else clips)[:200], np.random.default_rng(7), 2)
        flat = train["feats"].reshape(-1, N_FEATURES)
        self.mean_ = flat.mean(0).astype(np.float32)
        self.scale_ = np.maximum(flat.std(0), 1e-3).astype(np.float32)
        schedule = self._schedule()
        device = resolve_device(schedule.device)

        def batch(data, idx):
            return to_device({"feats": (data["feats"][idx] - self.mean_) / self.scale_, "label": data["label"][idx],
                              "weight": data["weight"][idx]}, device)

        with seeded(rng):
            self.network_ = self._make_network({}).to(device)
            self.history_ = fit_network(self.network_, _loss, lambda idx, r: batch(train, idx), len(train["feats"]),
                                        batch(val, np.arange(len(val["feats"]))), schedule, rng,
                                        checkpoint=checkpoint, desc="flaw classifier")
        self.network_.to("cpu").eval()
        return self

    def predict(self, joints: np.ndarray) -> np.ndarray:
        """Flaw probability ``(B, T)`` of a batch ``(B, T, J, 3)`` metres."""
        return self.predict_all(joints)[..., 0]

    @torch.no_grad()
    def predict_all(self, joints: np.ndarray) -> np.ndarray:
        """``(B, T, 1 + G)``: flaw probability, then the probability that a flaw of each group of
        :data:`~refiner.refinement.training_flaws.GROUPS` is there (in that order)."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        x = np.asarray(joints)
        feats = flaw_features(x, self.skeleton_)
        t = torch.from_numpy((feats - self.mean_) / self.scale_).to(self.device_)
        return torch.sigmoid(self.network_(t)).cpu().numpy().astype(np.float64)

    def calibrate(self, clips, *, clip_rate: float = 0.05, min_run: int = 2) -> float:
        """Set ``threshold_`` so that at most ``clip_rate`` of these clean clips have ``min_run`` frames above it."""
        peaks = [run_peak(self.predict(np.asarray(c)[None])[0], min_run) for c in clips]
        self.threshold_ = float(min(max(np.quantile(peaks, 1 - clip_rate), 0.05), 0.999))
        return self.threshold_


def _loss(net, batch, rng) -> torch.Tensor:
    """Flaw BCE on the labelled frames plus, on flawed frames, the BCE of which groups caused it."""
    logits, label, w = net(batch["feats"]), batch["label"], batch["weight"]
    bce = F.binary_cross_entropy_with_logits(logits, label, reduction="none")
    flaw = (bce[..., 0] * w).sum() / w.sum().clamp_min(1.0)
    on = w * label[..., 0]
    return flaw + 0.5 * (bce[..., 1:].mean(-1) * on).sum() / on.sum().clamp_min(1.0)
