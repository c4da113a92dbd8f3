"""Anchor recognition (paper §3.2.1): where the anchors are, and which of them are flawed.

A motion encoder and an MLP give every frame an anchor probability (trained with BCE on the
segmentation's anchors). A 2-component Gaussian mixture fitted by maximum likelihood on the
encoder features of real anchors scores each recognised anchor; anchors whose log-likelihood falls
below ``threshold_`` (the ``flaw_percentile``-th percentile of held-out real anchors' scores) are
flagged as flawed.

Choices beyond the paper, each for a measured reason:

- BCE targets are softened with a 1-frame Gaussian around each anchor: the DP's junction frame is
  only defined to about a frame. Anchors are the local maxima of the probability above
  ``detect_threshold_``, which ``fit`` picks on held-out clips for the best F1 against the
  segmentation (a fixed 0.5 found almost no interior anchors: recall 0.45, first/last frames only).
- An action head on the pooled features lets ``refine(..., action=None)`` infer the action.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from sklearn.mixture import GaussianMixture
from torch import nn

from refiner.core.signal import overlap_add, window_starts
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.layers import MLP
from refiner.nn.training import ClipCrops, TrainSchedule, fit_network, resolve_device, seeded, to_device
# AnchorQuality (the pose-plausibility score of the same anchors) is importable from here as well: the 0.1
# module refiner.recognition, which now means this one, held both
from refiner.refinement.anchor_quality import AnchorQuality, gmm_log_likelihood  # noqa: F401
from refiner.refinement.encoders import MotionEncoder, MotionEncoderConfig, encoder_config

__all__ = ["AnchorRecognizer", "AnchorRecognitionNet", "Recognition", "anchor_peaks", "anchor_targets", "match_anchors"]


@dataclass
class Recognition:
    """What anchor recognition found in one clip.

    Attributes
    ----------
    anchors : ndarray of int (K,)
        Recognised anchor frames, first and last frame included.
    probability : ndarray (T,)
        Per-frame anchor probability.
    scores : ndarray (K,)
        GMM log-likelihood of each anchor's feature (higher = more like real anchors).
    flagged : ndarray of bool (K,)
        ``scores < threshold``.
    threshold : float
    action_probability : ndarray (n_actions,)
    """

    anchors: np.ndarray
    probability: np.ndarray
    scores: np.ndarray
    flagged: np.ndarray
    threshold: float
    action_probability: np.ndarray

    @property
    def flagged_anchors(self) -> np.ndarray:
        return self.anchors[self.flagged]


class AnchorRecognitionNet(nn.Module):
    """Motion encoder + anchor MLP + action MLP: ``(B, T, J*3) -> (B, T) logits, (B, A) logits, (B, T, D)``."""

    def __init__(self, encoder: MotionEncoderConfig, n_actions: int):
        super().__init__()
        self.encoder = MotionEncoder(encoder)
        self.anchor_head = MLP(encoder.d_model, 1, encoder.d_model)
        self.action_head = MLP(encoder.d_model, n_actions, encoder.d_model)

    def forward(self, x: torch.Tensor, valid: torch.Tensor | None = None):
        h = self.encoder(x, valid=valid)
        logits = self.anchor_head(h).squeeze(-1)
        w = torch.ones_like(logits) if valid is None else valid.to(h.dtype)
        pooled = (h * w[..., None]).sum(1) / w.sum(1, keepdim=True).clamp_min(1.0)
        return logits, self.action_head(pooled), h


def anchor_targets(n_frames: int, anchors, sigma: float = 1.0) -> np.ndarray:
    """Soft per-frame targets ``(T,)``: ``max_a exp(-(t - a)^2 / 2 sigma^2)`` over anchors."""
    t = np.arange(n_frames)[:, None]
    a = np.asarray(anchors)[None]
    return np.exp(-((t - a) ** 2) / (2 * sigma**2)).max(1).astype(np.float32)


def match_anchors(predicted, reference, tolerance: int = 2) -> tuple[int, int, int]:
    """Greedy one-to-one matching within ``tolerance`` frames: ``(true positives, n_predicted, n_reference)``."""
    predicted, reference = list(np.asarray(predicted)), list(np.asarray(reference))
    used, tp = set(), 0
    for p in predicted:
        best = None
        for j, r in enumerate(reference):
            if j not in used and abs(int(p) - int(r)) <= tolerance and (best is None or abs(p - r) < abs(p - reference[best])):
                best = j
        if best is not None:
            used.add(best)
            tp += 1
    return tp, len(predicted), len(reference)


class AnchorRecognizer(NetworkComponent):
    """Recognise anchors and score their quality (paper §3.2.1).

    Parameters
    ----------
    d_model, n_layers, n_heads, ffn_dim, dropout : motion-encoder sizes (appendix A)
    crop_frames : int, default=60
        Training crop length (and the inference window is twice that).
    n_components : int, default=2
        GMM components (paper: 2).
    flaw_percentile : float, default=1.0
        Threshold = this percentile of held-out real anchors' scores: about this share of real
        anchors is flagged.
    detect_threshold : float or "auto", default="auto"
        Minimum probability of a recognised anchor; "auto" picks it on held-out clips (best F1).
    action_weight : float, default=0.2
        Weight of the action cross-entropy beside the anchor BCE.
    schedule : TrainSchedule, default=TrainSchedule()
        Epochs, batch size, learning rate, device, ... (:class:`~refiner.nn.training.TrainSchedule`).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : AnchorRecognitionNet
    n_joints_, n_actions_ : int
    gmm_weights_ (C,), gmm_means_ (C, D), gmm_covariances_ (C, D, D) : ndarray
    threshold_ : float
    detect_threshold_ : float
    history_ : list of dict
    """

    _fitted_attributes = ("n_joints_", "n_actions_", "threshold_", "detect_threshold_", "history_")
    _fitted_arrays = ("gmm_weights_", "gmm_means_", "gmm_covariances_")
    _symmetric_arrays = ("gmm_covariances_",)

    def __init__(self, *, d_model: int = 128, n_layers: int = 2, n_heads: int = 4, ffn_dim: int = 128,
                 dropout: float = 0.1, crop_frames: int = 60, n_components: int = 2, flaw_percentile: float = 1.0,
                 detect_threshold: float | str = "auto", action_weight: float = 0.2,
                 schedule: TrainSchedule = TrainSchedule(), random_state: int | None = 0):
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.dropout = dropout
        self.crop_frames = crop_frames
        self.n_components = n_components
        self.flaw_percentile = flaw_percentile
        self.detect_threshold = detect_threshold
        self.action_weight = action_weight
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> AnchorRecognitionNet:
        return AnchorRecognitionNet(encoder_config(self, fitted["n_joints_"]), fitted["n_actions_"])

    def fit(self, clips, anchors, actions, *, n_actions: int | None = None, validation=None) -> "AnchorRecognizer":
        """Train on real clips and their segmentation anchors.

        Parameters
        ----------
        clips : sequence of ndarray (T_i, J, 3), metres
        anchors : sequence of int arrays, the segmentation's anchor frames of each clip
        actions : sequence of int
        validation : tuple (clips, anchors, actions), optional
            Held-out clips for early stopping and the flaw threshold; default: 10 % of the clips.
        """
        clips = [np.asarray(c, dtype=np.float32) for c in clips]
        if not clips or len(clips) != len(anchors) or len(clips) != len(actions):
            raise ValueError("`clips`, `anchors` and `actions` must be non-empty and of equal length.")
        actions = np.asarray(actions, dtype=np.int64)
        rng = check_random_state(self.random_state)
        if validation is None:
            order = rng.permutation(len(clips))
            n_val = max(1, len(clips) // 10)
            val_idx, tr_idx = order[:n_val], order[n_val:]
            validation = ([clips[i] for i in val_idx], [anchors[i] for i in val_idx], actions[val_idx])
            clips, anchors, actions = [clips[i] for i in tr_idx], [anchors[i] for i in tr_idx], actions[tr_idx]
        self.n_joints_ = int(clips[0].shape[1])
        self.n_actions_ = int(n_actions if n_actions is not None else max(actions.max(), np.max(validation[2])) + 1)
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        crops = self._crops(clips, anchors, actions)
        val_crops = self._crops(*validation)
        with seeded(rng):
            self.network_ = self._make_network({"n_joints_": self.n_joints_, "n_actions_": self.n_actions_}).to(device)
            val_batch = to_device(val_crops.sample(np.arange(len(val_crops)), np.random.default_rng(0)), device)
            self.history_ = fit_network(
                self.network_, self._loss, lambda idx, r: to_device(crops.sample(idx, r), device), len(crops),
                val_batch, schedule, rng, desc="anchor recognition",
            )
        train_feats = self._anchor_features(clips, anchors)
        gmm = GaussianMixture(self.n_components, covariance_type="full", reg_covar=1e-4,
                              random_state=int(rng.integers(2**31))).fit(train_feats)
        # float32 halves the file; the likelihood is computed in float64 from them (agrees to ~1e-4 nats)
        self.gmm_weights_, self.gmm_means_, self.gmm_covariances_ = (
            np.asarray(a, np.float32) for a in (gmm.weights_, gmm.means_, gmm.covariances_))
        val_scores = self._score_features(self._anchor_features(validation[0], validation[1]))
        self.threshold_ = float(np.percentile(val_scores, self.flaw_percentile))
        if self.detect_threshold == "auto":
            self.calibrate_detection(validation[0], validation[1])
        else:
            self.detect_threshold_ = float(self.detect_threshold)
        return self

    def calibrate_detection(self, clips, anchors) -> dict[float, float]:
        """Set ``detect_threshold_`` to the candidate with the best anchor F1 on these clips.

        Returns the F1 (tolerance 2 frames) of every candidate threshold.
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        probs = [self._forward_clip(np.asarray(c, np.float32))[0] for c in clips]
        f1 = {}
        for th in _DETECT_CANDIDATES:
            tp = n_pred = n_ref = 0
            for p, a in zip(probs, anchors):
                counts = match_anchors(anchor_peaks(p, th), a)
                tp, n_pred, n_ref = tp + counts[0], n_pred + counts[1], n_ref + counts[2]
            f1[float(th)] = 2 * tp / max(n_pred + n_ref, 1)
        self.detect_threshold_ = max(f1, key=f1.get)
        return f1

    def _crops(self, clips, anchors, actions) -> ClipCrops:
        targets = [anchor_targets(len(c), a) for c, a in zip(clips, anchors)]
        acts = [np.full(len(c), a, dtype=np.int64) for c, a in zip(clips, actions)]
        return ClipCrops(clips, self.crop_frames, {"target": targets, "action": acts})

    def _loss(self, net: AnchorRecognitionNet, batch: dict, rng) -> torch.Tensor:
        x, valid = batch["joints"].flatten(2), batch["valid"]
        logits, action_logits, _ = net(x, valid)
        bce = F.binary_cross_entropy_with_logits(logits, batch["target"], reduction="none")
        bce = (bce * valid).sum() / valid.sum()
        return bce + self.action_weight * F.cross_entropy(action_logits, batch["action"][:, 0])

    @torch.no_grad()
    def _forward_clip(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Probability (T,), action probabilities (A,), features (T, D) of a whole clip, windowed."""
        net, device = self.network_.eval(), self.device_
        n_frames, window = len(joints), 2 * self.crop_frames
        starts = window_starts(n_frames, window, self.crop_frames)
        crops = np.stack([joints[s : s + window] - joints[s : s + 1, :1] for s in starts])
        x = torch.from_numpy(np.ascontiguousarray(crops)).to(device).flatten(2)
        logits, action_logits, feats = net(x)
        prob = overlap_add(torch.sigmoid(logits).cpu().numpy(), starts, n_frames)
        action = torch.softmax(action_logits, -1).mean(0).cpu().numpy()
        return prob, action, overlap_add(feats.cpu().numpy(), starts, n_frames)

    def _anchor_features(self, clips, anchors) -> np.ndarray:
        return np.concatenate([self._forward_clip(np.asarray(c, np.float32))[2][np.asarray(a)] for c, a in zip(clips, anchors)])

    def _score_features(self, feats: np.ndarray) -> np.ndarray:
        return gmm_log_likelihood(feats, self.gmm_weights_, self.gmm_means_, self.gmm_covariances_)

    def recognize(self, joints, *, anchors=None) -> Recognition:
        """Recognise and score the anchors of one clip.

        Parameters
        ----------
        joints : ndarray (T, J, 3), metres, canonical frame
        anchors : int array, optional
            Use these anchor frames instead of recognising them (they are still scored).
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        joints = np.asarray(joints, dtype=np.float32)
        prob, action, feats = self._forward_clip(joints)
        if anchors is None:
            anchors = anchor_peaks(prob, self.detect_threshold_)
        anchors = np.asarray(anchors, dtype=np.int64)
        scores = self._score_features(feats[anchors])
        return Recognition(anchors, prob.astype(np.float32), scores, scores < self.threshold_, self.threshold_, action)


_DETECT_CANDIDATES = np.round(np.arange(0.05, 0.55, 0.05), 2)


def anchor_peaks(prob: np.ndarray, threshold: float) -> np.ndarray:
    """Anchor frames ``(K,)`` from a per-frame anchor probability ``prob (T,)``: the first and last frame and
    the local maxima of ``prob`` above ``threshold``, at least 3 frames apart."""
    n = len(prob)
    left = np.r_[-np.inf, prob[:-1]]
    right = np.r_[prob[1:], -np.inf]
    peaks = np.flatnonzero((prob >= left) & (prob > right) & (prob >= threshold))
    peaks = peaks[(peaks >= 3) & (peaks <= n - 4)]  # a transition needs 3 frame intervals
    kept: list[int] = []
    for p in peaks:
        if not kept or p - kept[-1] >= 3:
            kept.append(int(p))
        elif prob[p] > prob[kept[-1]]:
            kept[-1] = int(p)
    return np.array([0, *kept, n - 1], dtype=np.int64)
