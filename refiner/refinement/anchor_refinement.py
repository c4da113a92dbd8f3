"""Anchor refinement (paper §3.2.2): replace a flawed anchor by a new one built from its concept.

The flawed anchor and its neighbouring transitions are masked; the motion encoder's feature at the
anchor position feeds a classifier over the action's anchor concepts; the feature concatenated with
the concept's embedding is decoded by an MLP into the new anchor. Training masks random real
anchors and uses the true concept for the decoder (teacher forcing), with cross-entropy on the
concept and MPJPE on the anchor.

The decoder predicts the root position and a root-relative offset *from the concept pose*, so a
new anchor is the concept adapted to its context rather than a pose from nothing.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from refiner.concepts.anchors import AnchorConcepts
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.layers import MLP, mpjpe
from refiner.nn.training import TrainSchedule, crop_start, fit_network, put_crop, resolve_device, seeded, to_device
from refiner.refinement.encoders import MotionEncoder, MotionEncoderConfig, encoder_config

__all__ = ["AnchorRefiner", "AnchorRefinementNet", "masked_window"]


class AnchorRefinementNet(nn.Module):
    """Masked motion encoder + concept classifier + anchor decoder.

    ``forward(x (B, T, J*3), keep (B, T), valid (B, T), index (B,), concept (B,), concept_pose (B, J, 3))``
    -> concept logits ``(B, C)`` over all concepts of all actions, new anchor ``(B, J, 3)``.
    """

    def __init__(self, encoder: MotionEncoderConfig, n_concepts: int, n_joints: int):
        super().__init__()
        d = encoder.d_model
        self.n_joints = n_joints
        self.encoder = MotionEncoder(encoder)
        self.classifier = MLP(d, n_concepts, d)
        self.concept_embedding = nn.Embedding(n_concepts, d)
        self.decoder = MLP(2 * d, 3 + n_joints * 3, d)

    def features(self, x, keep, valid, index):
        h = self.encoder(x, keep=keep, valid=valid)
        return h[torch.arange(len(h), device=h.device), index]  # (B, D)

    def decode(self, feature, concept, concept_pose):
        out = self.decoder(torch.cat([feature, self.concept_embedding(concept)], dim=-1))
        root, offset = out[:, :3], out[:, 3:].view(-1, self.n_joints, 3)
        pose = concept_pose + offset
        return pose - pose[:, :1] + root[:, None]


def masked_window(n_frames: int, anchors: np.ndarray, k: int) -> tuple[int, int]:
    """Frames ``(lo, hi)`` hidden when anchor ``k`` (an index into ``anchors``) is refined.

    The anchor and the interiors of both neighbouring transitions; the neighbouring anchors stay
    visible. ``hi`` is exclusive.
    """
    lo = int(anchors[k - 1]) + 1 if k > 0 else 0
    hi = int(anchors[k + 1]) if k + 1 < len(anchors) else n_frames
    return lo, hi


class AnchorRefiner(NetworkComponent):
    """Synthesise replacement anchors from anchor concepts (paper §3.2.2).

    Parameters
    ----------
    d_model, n_layers, n_heads, ffn_dim, dropout : motion-encoder sizes
    crop_frames : int, default=60
    concept_weight : float, default=0.1
        Weight of the concept cross-entropy beside the anchor MPJPE. The paper does not give one;
        at 1.0 the held-out cross-entropy (rising after ~15 epochs) drove early stopping long
        before the anchor MPJPE stopped improving.
    schedule : TrainSchedule, default=TrainSchedule()
        Epochs, batch size, learning rate, device, ... (:class:`~refiner.nn.training.TrainSchedule`).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : AnchorRefinementNet
    n_joints_, n_actions_ : int
    concept_offsets_ : ndarray (A + 1,)
        Concepts of action a are global indices ``concept_offsets_[a]:concept_offsets_[a + 1]``.
    concept_poses_ : ndarray (C, J, 3)
        Root-relative concept poses.
    history_ : list of dict
    """

    _fitted_attributes = ("n_joints_", "n_actions_", "history_")
    _fitted_arrays = ("concept_offsets_", "concept_poses_")

    def __init__(self, *, d_model: int = 128, n_layers: int = 2, n_heads: int = 4, ffn_dim: int = 128,
                 dropout: float = 0.1, crop_frames: int = 60, concept_weight: float = 0.1,
                 schedule: TrainSchedule = TrainSchedule(), random_state: int | None = 0):
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.dropout = dropout
        self.crop_frames = crop_frames
        self.concept_weight = concept_weight
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> AnchorRefinementNet:
        n_concepts = int(np.asarray(self.concept_offsets_)[-1])
        return AnchorRefinementNet(encoder_config(self, fitted["n_joints_"]), n_concepts, fitted["n_joints_"])

    def fit(self, clips, anchors, actions, concepts: AnchorConcepts, *, validation=None) -> "AnchorRefiner":
        """Train on real clips, their segmentation anchors and fitted anchor concepts.

        ``validation`` : tuple (clips, anchors, actions), optional
            Held-out clips whose anchors select the best weights and stop training early; default:
            10 % of the training clips' anchors.
        """
        check_is_fitted(concepts, msg="`concepts` must be a fitted AnchorConcepts.")
        clips = [np.asarray(c, dtype=np.float32) for c in clips]
        if not clips or len(clips) != len(anchors) or len(clips) != len(actions):
            raise ValueError("`clips`, `anchors` and `actions` must be non-empty and of equal length.")
        actions = np.asarray(actions, dtype=np.int64)
        n_fit = len(clips)
        if validation is not None:  # the held-out clips go after the training ones; all their anchors validate
            val_clips, val_anchors, val_actions = validation
            if not len(val_clips) or len(val_clips) != len(val_anchors) or len(val_clips) != len(val_actions):
                raise ValueError("`validation` must be non-empty (clips, anchors, actions) of equal length.")
            clips = clips + [np.asarray(c, dtype=np.float32) for c in val_clips]
            anchors = [*anchors, *val_anchors]
            actions = np.concatenate([actions, np.asarray(val_actions, dtype=np.int64)])
        rng = check_random_state(self.random_state)
        self.n_joints_ = int(clips[0].shape[1])
        self.n_actions_ = int(concepts.n_actions_)
        self.concept_offsets_ = np.concatenate([[0], np.cumsum(concepts.n_concepts_)]).astype(np.int64)
        self.concept_poses_ = np.concatenate(concepts.centers_).astype(np.float32)
        items = [(c, k) for c, a in enumerate(anchors) for k in range(len(a))]
        labels = {(c, k): int(self.concept_offsets_[actions[c]] + concepts.predict(clips[c][anchors[c][k]][None], actions[c])[0])
                  for c, k in items}
        fit_items = [(c, k) for c, k in items if c < n_fit]
        order = rng.permutation(len(fit_items))
        n_val = max(1, len(fit_items) // 10) if validation is None else 0
        train_items = [fit_items[i] for i in order[n_val:]]
        val_items = [fit_items[i] for i in order[:n_val]] if validation is None else [(c, k) for c, k in items if c >= n_fit]
        schedule = self._schedule()
        device = resolve_device(schedule.device)

        def make_batch(idx, r, pool=train_items):
            return to_device(self._batch([pool[i] for i in idx], clips, anchors, actions, labels, r), device)

        with seeded(rng):
            self.network_ = self._make_network({"n_joints_": self.n_joints_}).to(device)
            val_batch = make_batch(np.arange(len(val_items)), np.random.default_rng(0), val_items) if val_items else None
            self.history_ = fit_network(self.network_, self._loss, make_batch, len(train_items), val_batch,
                                        schedule, rng, desc="anchor refinement")
        return self

    def _batch(self, items, clips, anchors, actions, labels, rng) -> dict:
        length, joints = self.crop_frames, self.n_joints_
        n = len(items)
        x = np.zeros((n, length, joints, 3), np.float32)
        keep = np.ones((n, length), bool)
        valid = np.zeros((n, length), bool)
        index = np.zeros(n, np.int64)
        target = np.zeros((n, joints, 3), np.float32)
        concept = np.zeros(n, np.int64)
        action = np.zeros(n, np.int64)
        for b, (c, k) in enumerate(items):
            clip, anc = clips[c], anchors[c]
            frame = int(anc[k])
            start = crop_start(len(clip), length, rng, holding=frame)
            crop = clip[start : start + length]
            origin = crop[:1, :1]
            valid[b, : put_crop(x, b, crop, origin)] = True
            lo, hi = masked_window(len(clip), anc, k)
            keep[b, max(lo - start, 0) : max(hi - start, 0)] = False
            index[b] = frame - start
            target[b] = clip[frame] - origin[0]
            concept[b] = labels[(c, k)]
            action[b] = actions[c]
        return {"joints": x, "keep": keep, "valid": valid, "index": index, "target": target, "concept": concept,
                "action": action, "concept_pose": self.concept_poses_[concept]}

    def _restrict(self, logits: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Logits of other actions' concepts set to -inf."""
        offsets = torch.as_tensor(self.concept_offsets_, device=logits.device)
        idx = torch.arange(logits.shape[1], device=logits.device)[None]
        inside = (idx >= offsets[action][:, None]) & (idx < offsets[action + 1][:, None])
        return logits.masked_fill(~inside, float("-inf"))

    def _loss(self, net: AnchorRefinementNet, batch: dict, rng) -> torch.Tensor:
        x = batch["joints"].flatten(2)
        feat = net.features(x, batch["keep"], batch["valid"], batch["index"])
        logits = self._restrict(net.classifier(feat), batch["action"])
        pose = net.decode(feat, batch["concept"], batch["concept_pose"])
        return mpjpe(pose, batch["target"]) + self.concept_weight * F.cross_entropy(logits, batch["concept"])

    @torch.no_grad()
    def refine_anchor(self, joints, anchors, k: int, action: int) -> tuple[np.ndarray, int]:
        """A new pose for anchor ``k`` of a clip.

        Parameters
        ----------
        joints : ndarray (T, J, 3), metres
        anchors : int array (K,), the clip's anchor frames
        k : int
            Index into ``anchors`` of the anchor to replace.
        action : int

        Returns
        -------
        pose : ndarray (J, 3), float32, metres, in the clip's frame
        concept : int
            Index of the chosen concept among the action's concepts.
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        if not 0 <= action < self.n_actions_:
            raise ValueError(f"`action` must be in 0..{self.n_actions_ - 1}; got {action}.")
        net, device = self.network_.eval(), self.device_
        joints = np.asarray(joints, dtype=np.float32)
        frame, window = int(anchors[k]), 2 * self.crop_frames
        start = int(np.clip(frame - window // 2, 0, max(len(joints) - window, 0)))
        crop = joints[start : start + window]
        origin = crop[:1, :1]
        lo, hi = masked_window(len(joints), anchors, k)
        keep = np.ones(len(crop), bool)
        keep[max(lo - start, 0) : max(hi - start, 0)] = False
        x = torch.from_numpy(np.ascontiguousarray(crop - origin)).to(device).flatten(1)[None]
        feat = net.features(x, torch.from_numpy(keep).to(device)[None], None, torch.tensor([frame - start], device=device))
        act = torch.tensor([action], device=device)
        concept = int(self._restrict(net.classifier(feat), act).argmax(-1))
        pose = net.decode(feat, torch.tensor([concept], device=device),
                          torch.from_numpy(self.concept_poses_[concept : concept + 1]).to(device))
        return (pose[0].cpu().numpy() + origin[0]).astype(np.float32), concept - int(self.concept_offsets_[action])

    def propose(self, joints: np.ndarray, anchors, k: int, action: int, generator) -> tuple[np.ndarray, tuple[int, int], int, float]:
        """``joints (T, J, 3)`` with anchor ``k`` replaced by a new one (:meth:`refine_anchor`) and both
        neighbouring transitions regenerated between it and its neighbours by ``generator`` (a fitted
        :class:`~refiner.concepts.transitions.TransitionGenerator`; the paper's anchor refinement).

        Returns
        -------
        proposal : ndarray (T, J, 3)
        window : (int, int)
            The frames ``lo <= t < hi`` it changes (:func:`masked_window`).
        concept : int
            The chosen concept among the action's.
        moved_cm : float
            Mean distance the anchor's joints moved.
        """
        frame = int(anchors[k])
        pose, concept = self.refine_anchor(joints, anchors, k, action)
        proposal = joints.copy()
        proposal[frame] = pose
        starts, ends, durations = [], [], []
        if k > 0:
            starts.append(joints[anchors[k - 1]]), ends.append(pose), durations.append(frame - int(anchors[k - 1]))
        if k + 1 < len(anchors):
            starts.append(pose), ends.append(joints[anchors[k + 1]]), durations.append(int(anchors[k + 1]) - frame)
        pieces = generator.generate(np.stack(starts), np.stack(ends), np.array(durations))
        if k > 0:
            proposal[anchors[k - 1] : frame + 1] = pieces[0]
        if k + 1 < len(anchors):
            proposal[frame : anchors[k + 1] + 1] = pieces[-1]
        moved_cm = 100 * float(np.linalg.norm(pose - joints[frame], axis=-1).mean())
        return proposal, masked_window(len(joints), anchors, k), concept, moved_cm
