"""The motion model: one learned model of real motion that finds flawed frames and parts and in-fills them.

It works on rigid motion (:mod:`refiner.core.bone_directions`): features are each bone's unit direction and the root's
velocity, so whatever it proposes is put back on the clip's own bones. Per frame and part (every bone, and the root)
it gives a flaw probability (recognition) and the clean features with the hidden parts in-filled from their context
(anchor and transition refinement of the flagged frames). Trained by
:func:`refiner.refinement.training.motion_training.train_motion_model`.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import load_file, save_file

from refiner.core.bone_directions import from_bone_directions, to_bone_directions
from refiner.core.contact import contact_joints, foot_joints
from refiner.core.signal import linear_infill
from refiner.core.skeletons import get_skeleton
from refiner.refinement.networks.motion_net import MotionNet, MotionNetConfig

__all__ = ["MotionModel", "motion_features", "ground_context", "linear_fill", "ROOT_SCALE", "N_CONTEXT"]

#: Root velocity (metres per frame) is scaled by this so its features weigh like unit directions.
ROOT_SCALE = 10.0


def motion_features(joints, skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``joints (N, T, J, 3)`` metres -> ``features (N, T, 3B + 3)`` float32 (bone directions, scaled root velocity with
    frame 0's set to 0), ``root (N, T, 3)`` and ``lengths (N, T, B)`` metres."""
    root, dirs, lengths = to_bone_directions(joints, skeleton)
    vel = np.diff(root, axis=-2, prepend=root[..., :1, :]) * ROOT_SCALE
    feats = np.concatenate([dirs.reshape(*dirs.shape[:-2], -1), vel], -1)
    return feats.astype(np.float32), root, lengths


#: Input-only channels of :func:`ground_context`.
N_CONTEXT = 5


def ground_context(joints, skeleton) -> np.ndarray:
    """``joints (N, T, J, 3)`` -> ``(N, T, 5)`` float32: heights of the root and both feet above the clip's ground (its
    contact joints' lowest point), metres, and both feet's horizontal speed (scaled as root velocity): where the body
    meets the floor, which directions and velocities alone do not show."""
    skel = get_skeleton(skeleton)
    x = np.asarray(joints, np.float64)
    up = skel.up_vector
    h = x @ up
    ground = h[..., list(contact_joints(skel))].min((-1, -2), keepdims=True)
    feet = list(foot_joints(skel))
    step = np.diff(x[..., feet, :], axis=-3, prepend=x[..., :1, feet, :])
    horizontal = np.linalg.norm(step - (step @ up)[..., None] * up, axis=-1) * ROOT_SCALE
    return np.concatenate([h[..., [skel.root]] - ground, h[..., feet] - ground, horizontal], -1).astype(np.float32)


def joints_from_features(features, root0, lengths, skeleton) -> np.ndarray:
    """Inverse of :func:`motion_features`: ``features (N, T, F)``, ``root0 (N, 3)`` (frame 0's root), ``lengths
    (N, T, B)`` -> ``joints (N, T, J, 3)`` float64."""
    f = np.asarray(features, np.float64)
    n_bones = (f.shape[-1] - 3) // 3
    dirs = f[..., :3 * n_bones].reshape(*f.shape[:-1], n_bones, 3)
    vel = f[..., 3 * n_bones:] / ROOT_SCALE
    vel[..., 0, :] = 0.0
    root = np.asarray(root0)[..., None, :] + np.cumsum(vel, axis=-2)
    return from_bone_directions(root, dirs, lengths, skeleton)


def linear_fill(features, hidden) -> np.ndarray:
    """``features (N, T, 3P)`` with each part's ``hidden (N, T, P)`` frames interpolated linearly between the frames
    that bound them (:func:`refiner.core.signal.linear_infill`): the start the in-fill corrects."""
    out = np.array(features, np.float32)
    for i, p in zip(*np.nonzero(np.asarray(hidden).any(1))):
        out[i, :, 3 * p:3 * p + 3] = linear_infill(out[i, :, 3 * p:3 * p + 3], hidden[i, :, p])
    return out


def part_features(n_bones: int) -> np.ndarray:
    """``(P, 3)`` feature columns of each part: bone ``b`` -> ``3b..3b+2``, the root (part ``B``) -> its velocity."""
    return np.arange(3 * n_bones + 3).reshape(n_bones + 1, 3)


class MotionModel:
    """Flaw probabilities and in-filling for one skeleton (sklearn conventions: learned state ends in ``_``).

    Parameters
    ----------
    skeleton : str
    action_names : sequence of str
        The actions it is conditioned on (an unknown action has its own embedding).
    config : MotionNetConfig, optional
        Network sizes (default: :class:`MotionNetConfig` for the skeleton's bones and actions).
    """

    def __init__(self, skeleton: str = "humanact12", action_names=(), config: MotionNetConfig | None = None):
        self.skeleton = get_skeleton(skeleton).name
        self.action_names = tuple(action_names)
        self.config = config or MotionNetConfig(n_bones=len(get_skeleton(skeleton).bones), n_actions=len(self.action_names),
                                                n_context=N_CONTEXT)

    @property
    def network_(self) -> MotionNet:
        if not hasattr(self, "_network"):
            raise ValueError("This MotionModel is not fitted yet; train it (train_motion_model) or load() it first.")
        return self._network

    def set_network(self, network: MotionNet, training: dict | None = None) -> "MotionModel":
        self._network = network.eval()
        self.training_ = dict(training or {})
        return self

    def action_index(self, actions, n: int) -> torch.Tensor:
        """``(n,)`` long: each action's index, ``n_actions`` where it is None (unknown)."""
        unknown = self.config.n_actions
        return torch.tensor([unknown if a is None else int(a) for a in actions], dtype=torch.long).reshape(n)

    def inputs(self, features, hidden, context) -> tuple[torch.Tensor, torch.Tensor]:
        """The network's input: ``features`` with the ``hidden (N, T, P)`` parts linearly in-filled (:func:`linear_fill`;
        the hidden mask goes in too), then ``context`` (zeroed on frames with any part hidden, so it tells nothing of
        what is hidden)."""
        hidden = np.asarray(hidden, bool)
        h = torch.as_tensor(hidden)
        shown = torch.as_tensor(linear_fill(features, hidden) if hidden.any() else np.asarray(features, np.float32))
        if self.config.n_context:
            if context is None:
                raise ValueError("this motion model needs `context` (ground_context of the clips).")
            ctx = torch.as_tensor(np.asarray(context, np.float32)) * ~h.any(-1, keepdim=True)
            shown = torch.cat([shown, ctx], -1)
        return shown, h

    @torch.no_grad()
    def predict(self, features: np.ndarray, hidden: np.ndarray, actions, context=None) -> tuple[np.ndarray, np.ndarray]:
        """``features (N, T, F)``, ``hidden (N, T, P)`` bool, ``context (N, T, C)`` (:func:`ground_context`) -> clean
        ``features (N, T, F)`` and flaw ``probability (N, T, P)``."""
        shown, h = self.inputs(features, hidden, context)
        clean, logits = self.network_(shown, h, self.action_index(actions, len(shown)))
        return clean.numpy(), torch.sigmoid(logits).numpy()

    def scan(self, joints, actions) -> tuple[np.ndarray, np.ndarray]:
        """``joints (N, T, J, 3)`` with nothing hidden -> clean ``features`` and flaw ``probability (N, T, P)``."""
        feats = motion_features(joints, self.skeleton)[0]
        hidden = np.zeros(feats.shape[:-1] + (self.config.n_parts,), bool)
        return self.predict(feats, hidden, actions, ground_context(joints, self.skeleton))

    def save(self, path: str | os.PathLike, *, half: bool = False) -> None:
        """Weights as safetensors (float16 with ``half``); config, skeleton, actions and the training record in its metadata."""
        meta = {"config": json.dumps(self.config.to_dict()), "skeleton": self.skeleton,
                "action_names": json.dumps(list(self.action_names)), "training": json.dumps(self.training_)}
        state = {k: (v.half() if half and v.is_floating_point() else v).contiguous() for k, v in self.network_.state_dict().items()}
        save_file(state, str(path), metadata=meta)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "MotionModel":
        """Load what :meth:`save` wrote; ``ValueError`` naming the file when it is not a motion model."""
        from safetensors import safe_open

        path = Path(path)
        if not path.is_file():
            raise ValueError(f"no motion model at {path}.")
        with safe_open(str(path), "pt") as f:
            meta = f.metadata() or {}
        if "config" not in meta:
            raise ValueError(f"{path} is not a motion model file (no config in its metadata).")
        model = cls(meta["skeleton"], json.loads(meta["action_names"]), MotionNetConfig.from_dict(json.loads(meta["config"])))
        net = MotionNet(model.config)
        net.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in load_file(str(path)).items()})
        return model.set_network(net, json.loads(meta.get("training", "{}")))
