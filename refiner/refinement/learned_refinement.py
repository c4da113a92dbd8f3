"""Learned flaw recognition and repair, trained on real clips with synthetic flaws.

:class:`FlawRecognizer` is the recognition step: per-frame flaw probability, per-frame anchor
probability (the paper's anchor recognition, §3.2.1) and the action when it is not given.
:class:`FlawRepairer` is anchor refinement and transition refinement in one network (§3.2.2-3): it
corrects the frames marked suspect given the whole clip, denoising small flaws from the given
frames and in-filling large ones from the kept context, the action and its anchor concepts.

Both take batches ``(B, T, J, 3)`` in one forward pass; clips longer than ``window`` frames are cut
into half-overlapping windows that go through the network together and are blended back with
triangular weights.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from refiner.core.signal import linear_infill, overlap_add, run_peak, triangular_weights, window_starts
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule, fit_network, resolve_device, seeded
from refiner.refinement.flaw_networks import FlawRecognitionNet, FlawRepairNet, FrameTransformerConfig
from refiner.refinement.flaw_training import FlawBatches

__all__ = ["FlawRecognizer", "FlawRepairer"]


class _LearnedStep(NetworkComponent):
    """Shared hyper-parameters, training and windowed inference of the two learned steps.

    The loss weights of both steps are parameters of both (scikit-learn needs one explicit
    signature): ``anchor_weight`` and ``action_weight`` weigh the anchor BCE and the action
    cross-entropy beside the flaw BCE of recognition; ``context_weight`` (frames that are not
    suspect, which must come back as given) and ``velocity_weight`` weigh the terms of repair.
    """

    _fitted_attributes = ("n_joints_", "n_actions_", "skeleton_", "history_")

    def __init__(self, *, d_model: int = 128, n_layers: int = 3, n_heads: int = 4, ffn_dim: int = 256,
                 dropout: float = 0.1, window: int = 64, min_crop: int = 32,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=60, batch_size=64, patience=1000, steps_per_epoch=200),
                 random_state: int | None = 0, anchor_weight: float = 0.5,
                 action_weight: float = 0.2, context_weight: float = 0.2, velocity_weight: float = 0.5):
        self.anchor_weight = anchor_weight
        self.action_weight = action_weight
        self.context_weight = context_weight
        self.velocity_weight = velocity_weight
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.dropout = dropout
        self.window = window
        self.min_crop = min_crop
        self.schedule = schedule
        self.random_state = random_state

    def _config(self, fitted: dict) -> FrameTransformerConfig:
        return FrameTransformerConfig(fitted["n_joints_"], fitted["n_actions_"], self.d_model, self.n_layers,
                                      self.n_heads, self.ffn_dim, self.dropout, max_len=self.window)

    def _train(self, clips, actions, anchors, *, skeleton, n_actions, validation, checkpoint, desc, **fitted):
        """Build ``network_`` and train it on flawed crops; ``validation`` = (clips, actions, anchors)."""
        rng = check_random_state(self.random_state)
        self.n_joints_ = int(np.asarray(clips[0]).shape[1])
        self.n_actions_ = int(n_actions)
        self.skeleton_ = skeleton
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        lengths = (min(self.min_crop, self.window), self.window)
        batches = FlawBatches(clips, actions, anchors, skeleton=skeleton, lengths=lengths, n_actions=n_actions)
        val = FlawBatches(*validation, skeleton=skeleton, lengths=(self.window, self.window), n_actions=n_actions)
        with seeded(rng):
            self.network_ = self._make_network({"n_joints_": self.n_joints_, "n_actions_": self.n_actions_, **fitted})
            self._set_buffers()
            self.network_.to(device)
            self.history_ = fit_network(self.network_, self._loss, lambda idx, r: batches.sample(idx, r, device),
                                        len(batches), val.validation_batch(device), schedule, rng,
                                        checkpoint=checkpoint, desc=desc)
        self.network_.to("cpu").eval()
        return self

    def _set_buffers(self) -> None:
        """Copy fitted arrays into the network's buffers (the repairer's anchor concepts)."""

    @torch.no_grad()
    def _windowed(self, x: np.ndarray, actions: np.ndarray, fn, *extra: np.ndarray) -> list[np.ndarray]:
        """Run ``fn(x_windows, actions, *extra_windows)`` on ``(B, T, ...)`` arrays and the clips' ``(B,)``
        actions in one pass over all half-overlapping windows; blend the per-frame outputs ``(W*B, w, ...)``
        back to ``(B, T, ...)`` with triangular weights."""
        n_batch, n_frames = x.shape[:2]
        size = min(self.window, n_frames)
        starts = window_starts(n_frames, size, max(size // 2, 1))
        device = self.device_

        def cut(a):
            t = torch.from_numpy(np.array(a, copy=True))
            return torch.cat([t[:, s : s + size] for s in starts]).to(device)

        outs = fn(cut(x), torch.as_tensor(np.tile(actions, len(starts)), device=device), *[cut(e) for e in extra])
        outs = outs if isinstance(outs, tuple) else (outs,)
        results = []
        for o in outs:
            o = o.float().cpu().numpy().reshape(len(starts), n_batch, size, *o.shape[2:])  # (W, B, w, ...)
            blended = overlap_add(np.moveaxis(o, 1, 2), starts, n_frames, triangular_weights(size))  # (T, B, ...)
            results.append(np.ascontiguousarray(np.moveaxis(blended, 0, 1)))
        return results

    def _actions(self, actions, n: int) -> np.ndarray:
        """``(n,)`` action indices; None or out-of-range entries become the *unknown* index."""
        if actions is None:
            return np.full(n, self.n_actions_, np.int64)
        a = np.asarray([self.n_actions_ if v is None else int(v) for v in np.broadcast_to(np.asarray(actions, object), (n,))])
        return np.where((a >= 0) & (a < self.n_actions_), a, self.n_actions_).astype(np.int64)


class FlawRecognizer(_LearnedStep):
    """Recognition: where the flaws are, where the anchors are, and which action it is.

    Parameters are the network sizes (``d_model``, ``n_layers``, ``n_heads``, ``ffn_dim``,
    ``dropout``), ``window`` (frames seen at once), ``min_crop``, ``schedule`` (a
    :class:`~refiner.nn.training.TrainSchedule`: ``n_epochs`` x ``steps_per_epoch`` steps of ``batch_size``,
    ``max_seconds``, ``device``, ...) and ``random_state``, plus ``anchor_weight`` and ``action_weight`` (loss weights beside the flaw BCE).

    Attributes
    ----------
    network_ : FlawRecognitionNet
    n_joints_, n_actions_ : int
    skeleton_ : str
    threshold_ : float
        Flaw probability above which a frame is flagged (set by :meth:`calibrate`).
    history_ : list of dict
    """

    _fitted_attributes = _LearnedStep._fitted_attributes + ("threshold_",)

    def _make_network(self, fitted: dict) -> FlawRecognitionNet:
        return FlawRecognitionNet(self._config(fitted))

    def fit(self, clips, actions, anchors, *, skeleton: str = "humanact12", n_actions: int | None = None,
            validation=None, checkpoint=None) -> "FlawRecognizer":
        """Train on real clips (``(T_i, J, 3)`` metres), their actions and segmentation anchors;
        ``validation`` = (clips, actions, anchors) of held-out subjects for model selection."""
        n_actions = int(np.max(actions)) + 1 if n_actions is None else n_actions
        self.threshold_ = 0.5
        return self._train(clips, actions, anchors, skeleton=skeleton, n_actions=n_actions,
                           validation=validation or (clips, actions, anchors), checkpoint=checkpoint,
                           desc="flaw recognition")

    def _loss(self, net, batch, rng) -> torch.Tensor:
        valid = batch["valid"]
        flaw, anchor, action_logits = net(batch["flawed"], batch["action"], valid)
        w = (valid & batch["label_mask"]).float()
        bce = F.binary_cross_entropy_with_logits(flaw, batch["flaw_target"], reduction="none")
        loss = (bce * w).sum() / w.sum().clamp_min(1.0)
        a_bce = F.binary_cross_entropy_with_logits(anchor, batch["anchor_target"], reduction="none")
        loss = loss + self.anchor_weight * (a_bce * valid).sum() / valid.sum().clamp_min(1.0)
        unknown = batch["action"] == self.n_actions_
        if unknown.any():
            ce = F.cross_entropy(action_logits[unknown], batch["true_action"][unknown])
            loss = loss + self.action_weight * ce
        return loss

    def predict(self, joints: np.ndarray, actions=None, *, estimate_action: bool = False) -> dict[str, np.ndarray]:
        """Probabilities for a batch ``(B, T, J, 3)`` metres (T >= 2).

        Returns ``flaw`` ``(B, T)``, ``anchor`` ``(B, T)`` and ``action`` ``(B, n_actions)``
        (estimated with the action treated as unknown; meaningful for the clips whose action is unknown,
        or for every clip with ``estimate_action``, which costs a second pass where actions are given).
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        x = np.asarray(joints, np.float32)
        acts = self._actions(actions, len(x))
        unknown = bool(estimate_action) or bool((acts == self.n_actions_).any())

        def fn(xw, a):
            flaw, anchor, logits = self.network_(xw, a)
            if unknown and not bool((a == self.n_actions_).all()):  # some clips need their action estimated
                _, _, logits = self.network_(xw, torch.full_like(a, self.n_actions_))
            return torch.sigmoid(flaw), torch.sigmoid(anchor), torch.softmax(logits, -1)[:, None].expand(-1, xw.shape[1], -1)

        flaw, anchor, action = self._windowed(x, acts, fn)
        return {"flaw": flaw, "anchor": anchor, "action": action.mean(1)}

    def calibrate(self, clips, actions, *, clip_rate: float = 0.05, min_run: int = 2) -> float:
        """Set ``threshold_`` so that at most ``clip_rate`` of these *clean* clips (held-out subjects)
        have a run of ``min_run`` frames above it; returns the threshold."""
        peaks = [run_peak(self.predict(np.asarray(c, np.float32)[None], [a])["flaw"][0], min_run)
                 for c, a in zip(clips, actions)]
        self.threshold_ = float(min(max(np.quantile(peaks, 1 - clip_rate), 0.05), 0.99))
        return self.threshold_


class FlawRepairer(_LearnedStep):
    """Anchor and transition refinement: corrected frames where a clip is suspect.

    Same parameters as :class:`FlawRecognizer`, plus ``context_weight`` (loss weight of frames
    that are not suspect: they must come back as given) and ``velocity_weight``.

    Attributes
    ----------
    network_ : FlawRepairNet
    concepts_ : ndarray (A, K, J, 3)
        The anchor concepts the network attends to (root-relative, metres), ``concept_valid_ (A, K)``.
    correction_threshold_ : float
        Metres: a frame whose :meth:`correction` exceeds it is flagged as flawed (set by :meth:`calibrate`;
        infinite until then).
    """

    _fitted_attributes = _LearnedStep._fitted_attributes + ("correction_threshold_",)
    _fitted_arrays = ("concepts_", "concept_valid_")

    def _make_network(self, fitted: dict) -> FlawRepairNet:
        k = np.asarray(getattr(self, "concepts_", np.zeros((1, 8)))).shape[1]
        return FlawRepairNet(self._config(fitted), n_concepts=k)

    def _set_buffers(self) -> None:
        self.network_.concepts.copy_(torch.as_tensor(self.concepts_))
        self.network_.concept_valid.copy_(torch.as_tensor(self.concept_valid_))

    def fit(self, clips, actions, anchors, anchor_concepts, *, skeleton: str = "humanact12", validation=None,
            checkpoint=None) -> "FlawRepairer":
        """Train on real clips with synthetic flaws; ``anchor_concepts`` is a fitted
        :class:`~refiner.concepts.anchors.AnchorConcepts` (its centres become the network's concept tokens)."""
        self.correction_threshold_ = float("inf")
        centers = anchor_concepts.centers_
        k = max(len(c) for c in centers)
        self.concepts_ = np.zeros((len(centers), k) + centers[0].shape[1:], np.float32)
        self.concept_valid_ = np.zeros((len(centers), k), bool)
        for a, c in enumerate(centers):
            self.concepts_[a, : len(c)] = c
            self.concept_valid_[a, : len(c)] = True
        return self._train(clips, actions, anchors, skeleton=skeleton, n_actions=len(centers),
                           validation=validation or (clips, actions, anchors), checkpoint=checkpoint,
                           desc="flaw repair")

    def _loss(self, net, batch, rng) -> torch.Tensor:
        valid, suspect = batch["valid"], batch["suspect"]
        pred = net(batch["given"], batch["infill"], suspect, batch["hidden"], batch["action"], valid,
                   root=get_skeleton(self.skeleton_).root)
        clean = batch["clean"]
        w = valid.float() * (suspect.float() + self.context_weight * (~suspect).float())
        err = torch.linalg.vector_norm(pred - clean, dim=-1).mean(-1)
        loss = (err * w).sum() / w.sum().clamp_min(1.0)
        vel = torch.linalg.vector_norm((pred[:, 1:] - pred[:, :-1]) - (clean[:, 1:] - clean[:, :-1]), dim=-1).mean(-1)
        vw = w[:, 1:] * valid[:, :-1].float()
        return loss + self.velocity_weight * (vel * vw).sum() / vw.sum().clamp_min(1.0)

    def repair(self, joints: np.ndarray, suspect: np.ndarray, actions=None, *, hide: bool = False) -> np.ndarray:
        """Corrected joints ``(B, T, J, 3)`` for a batch ``(B, T, J, 3)`` metres and ``suspect (B, T)`` bool.

        With ``hide`` the suspect frames are not shown to the network (replaced by linear
        interpolation first): pure in-filling from the context.
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        x = np.asarray(joints, np.float32)
        suspect = np.asarray(suspect, bool)
        hidden = suspect & hide
        infill = np.stack([linear_infill(c, s) for c, s in zip(x, suspect)])
        if hide:
            x = infill
        root = get_skeleton(self.skeleton_).root

        def fn(xw, a, iw, sw, hw):
            return self.network_(xw, iw, sw, hw, a, root=root)

        return self._windowed(x, self._actions(actions, len(x)), fn, infill, suspect, hidden)[0].astype(np.float32)

    def correction(self, joints: np.ndarray, actions=None) -> np.ndarray:
        """``(B, T)`` metres: how far the network moves each frame (mean over joints) when every frame is
        suspect. Trained to leave clean frames alone, it moves flawed ones: a second flaw detector."""
        x = np.asarray(joints, np.float32)
        fixed = self.repair(x, np.ones(x.shape[:2], bool), actions)
        return np.linalg.norm(fixed - x, axis=-1).mean(-1)

    def calibrate(self, clips, actions, *, clip_rate: float = 0.05, min_run: int = 2) -> float:
        """Set ``correction_threshold_`` so that at most ``clip_rate`` of these clean clips (held-out
        subjects) have a run of ``min_run`` frames above it; returns the threshold (metres)."""
        peaks = [run_peak(self.correction(np.asarray(c, np.float32)[None], [a])[0], min_run)
                 for c, a in zip(clips, actions)]
        self.correction_threshold_ = float(np.quantile(peaks, 1 - clip_rate))
        return self.correction_threshold_
