"""Two small reference generators trained on HumanAct12, so the refiner can be shown on real generator output.

- :class:`LieVAEGenerator` (``"a2m"``) follows Action2Motion (Guo et al. 2020): a conditional GRU
  VAE with a learned prior that emits, frame by frame, the root position and 23 axis-angle
  vectors (the Lie layout of generator_formats.md §2.1). Its output is decoded into joints by
  the ``action2motion`` adapter (``representation="lie"``).
- :class:`TransformerCVAEGenerator` (``"actor"``) follows ACTOR (Petrovich et al. 2021): a
  transformer CVAE with per-action distribution tokens in the encoder and time queries in the
  decoder. It emits joint positions directly (converted by the ``action2motion`` adapter's
  ``representation="xyz"`` path, i.e. passed through and re-centred).

Both are trained on 60-frame crops (first-frame root at the origin, native y-down frame) of
HumanAct12 subjects 1-10 for a fixed number of epochs with early stopping (about 8 minutes each
on one CPU thread; an optional time limit). They are honest small models, and their flaws are
whatever such training leaves: the shipped ``a2m`` jitters (joint speed about 1.7 times the real
one) and its first frame is often off, the shipped ``actor`` is over-smoothed (about a third of
the real joint speed); the HumanAct12 recogniser names the sampled action for 40-48 % of their
samples (real clips: 99 %). The shipped weights (float16 safetensors) live
in ``refiner/weights/generators`` with a manifest; HumanAct12 is for academic, non-commercial
use only, and so are they.
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
from einops import rearrange
from torch import nn

from refiner.core.manifest import file_sha256, read_generator_manifest, write_manifest
from refiner.core.motion import Motion
from refiner.core.validation import check_action, check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.layers import sinusoidal_positions
from refiner.nn.training import fit_network, resolve_device, seeded

__all__ = [
    "GENERATOR_KINDS",
    "LieVAE",
    "LieVAEConfig",
    "LieVAEGenerator",
    "TransformerCVAE",
    "TransformerCVAEConfig",
    "TransformerCVAEGenerator",
    "WEIGHTS_DIR",
    "load_reference_generator",
    "lie_targets",
    "training_crops",
    "unwrap_rotvecs",
    "train_reference_generator",
]

#: Where the shipped generator weights and their manifest live.
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights" / "generators"
LICENCE = ("Trained on HumanAct12 (derived from PHSPD) subjects 1-10: academic, non-commercial use only. "
           "Cite Action2Motion (Guo et al. 2020) and PHSPD (Zou et al. 2020).")
_N_FRAMES = 60


# ----------------------------------------------------------------------------------------------
# data


def training_crops(clips: Sequence[np.ndarray], n_frames: int, rng: np.random.Generator,
                   indices: Sequence[int] | None = None) -> np.ndarray:
    """Random ``n_frames`` crops of per-frame arrays, padded with the last frame (the A2M convention).

    Parameters
    ----------
    clips : sequence of ndarray of shape (T_i, ...)
    n_frames : int
    rng : numpy Generator
    indices : sequence of int, optional
        Which clips to crop (one crop each); default every clip.

    Returns
    -------
    ndarray of shape (len(indices), n_frames, ...), float32
        Crops as stored; callers re-centre positions themselves.
    """
    indices = range(len(clips)) if indices is None else indices
    out = np.empty((len(indices), n_frames) + clips[0].shape[1:], dtype=np.float32)
    for b, i in enumerate(indices):
        clip = clips[i]
        start = int(rng.integers(0, max(len(clip) - n_frames, 0) + 1))
        crop = clip[start : start + n_frames]
        out[b, : len(crop)] = crop
        out[b, len(crop):] = crop[-1]
    return out


def _check_training_data(data, n_actions: int) -> tuple[list[np.ndarray], np.ndarray]:
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


def lie_targets(joints) -> np.ndarray:
    """Action2Motion Lie parameters of HumanAct12 joints that change smoothly over time.

    Action2Motion's inverse kinematics (:func:`refiner.adapters.action2motion.joints_to_lie`)
    takes each bone's global rotation as the shortest rotation from its raw offset direction to
    the bone. Those directions point up (y up) while HumanAct12 is y down, so the spine and leg
    bones sit near a rotation by pi, where the shortest rotation's axis is undefined: 3.2 % of
    the frame-to-frame steps of real clips jump by more than 1 rad, which a regression network
    cannot follow. We run the same inverse kinematics on the clip turned upright
    (:func:`~refiner.adapters.base.yup_to_ydown`) and fold the half turn back into the first
    bone of every chain; then :func:`unwrap_rotvecs`. Only the twist about bones differs from
    ``joints_to_lie``: :func:`~refiner.adapters.action2motion.lie_to_joints` gives back the same
    joints (3.6e-6 m on 300 real clips) and steps over 1 rad drop to 0.5 %.

    Parameters
    ----------
    joints : array-like of shape (T, 24, 3)
        Metres, HumanAct12's y-down frame.

    Returns
    -------
    ndarray of shape (T, 72), float32
        Root position, then 23 axis-angle vectors (rad, norms up to 2 pi).
    """
    from refiner.adapters.action2motion import joints_to_lie
    from refiner.adapters.base import get_lie_kinematics, rotmat_to_rotvec, rotvec_to_rotmat, yup_to_ydown

    joints = np.asarray(joints, dtype=np.float64)
    kin = get_lie_kinematics("humanact12")
    lie = joints_to_lie(yup_to_ydown(joints)).astype(np.float64).reshape(joints.shape)
    firsts = sorted({chain[1] for chain in kin.chains})
    half_turn = np.diag([1.0, -1.0, -1.0])  # yup_to_ydown as a rotation; its own inverse
    lie[:, firsts] = rotmat_to_rotvec(half_turn @ rotvec_to_rotmat(lie[:, firsts]))
    lie[:, 0] = joints[:, 0]
    return unwrap_rotvecs(lie.reshape(len(joints), -1))


def unwrap_rotvecs(lie: np.ndarray) -> np.ndarray:
    """Make Lie parameters continuous over time: each axis-angle ``w`` may become ``w - 2 pi w / |w|``.

    Inverse kinematics returns angles in [0, pi], so a joint rotating through pi flips its
    axis-angle vector to the opposite side (3 % of HumanAct12 frame steps jump by more than
    1 rad). Both vectors are the same rotation; per frame we keep the one closer to the previous
    frame's, so the regression targets are smooth and forward kinematics gives the same joints.

    Parameters
    ----------
    lie : ndarray of shape (T, 3 + 3K)
        Root position, then K axis-angle vectors (rad).

    Returns
    -------
    ndarray of shape (T, 3 + 3K), float32
        Same rotations, with norms up to 2 pi.
    """
    lie = np.asarray(lie, dtype=np.float64)
    canonical = lie[:, 3:].reshape(len(lie), -1, 3)
    theta = np.linalg.norm(canonical, axis=-1, keepdims=True)
    flipped = canonical - 2 * np.pi * canonical / np.maximum(theta, 1e-8)
    rot = canonical.copy()
    for t in range(1, len(rot)):
        closer = np.linalg.norm(flipped[t] - rot[t - 1], axis=-1) < np.linalg.norm(canonical[t] - rot[t - 1], axis=-1)
        rot[t, closer] = flipped[t, closer]
    return np.concatenate([lie[:, :3], rot.reshape(len(lie), -1)], axis=1).astype(np.float32)


# ----------------------------------------------------------------------------------------------
# networks


@dataclass
class LieVAEConfig:
    """Sizes of a :class:`LieVAE` (Action2Motion HumanAct12: 72-d poses, hidden 128, z 30)."""

    n_actions: int = 12
    pose_dim: int = 72
    hidden: int = 128
    latent_dim: int = 30
    n_decoder_layers: int = 2
    angle_bound: float = 2 * math.pi


class LieVAE(nn.Module):
    """Action2Motion's recurrent CVAE: posterior and prior GRUs and a GRU decoder, one step per frame.

    Every step's condition is ``[previous pose, one-hot action, t / (T - 1)]``. The posterior
    also sees the current pose; the decoder gets the condition and ``z_t`` and emits the current
    pose: root position (linear head, metres) and 23 axis-angles squashed by ``tanh * angle_bound``
    (Action2Motion uses pi; our targets are unwrapped over time, see :func:`unwrap_rotvecs`, so
    they reach up to 2 pi).
    """

    def __init__(self, config: LieVAEConfig):
        super().__init__()
        self.config = config
        c = config
        cond = c.pose_dim + c.n_actions + 1
        self.posterior = nn.GRU(cond + c.pose_dim, c.hidden, batch_first=True)
        self.prior = nn.GRU(cond, c.hidden, batch_first=True)
        self.posterior_head = nn.Linear(c.hidden, 2 * c.latent_dim)
        self.prior_head = nn.Linear(c.hidden, 2 * c.latent_dim)
        self.decoder = nn.GRU(cond + c.latent_dim, c.hidden, c.n_decoder_layers, batch_first=True)
        self.root_head = nn.Linear(c.hidden, 3)
        self.angle_head = nn.Linear(c.hidden, c.pose_dim - 3)
        with torch.no_grad():  # narrow initial posterior and prior (see TransformerCVAE)
            self.posterior_head.bias[c.latent_dim:] = -4.0
            self.prior_head.bias[c.latent_dim:] = -4.0

    def condition(self, previous: torch.Tensor, actions: torch.Tensor, start: int = 0) -> torch.Tensor:
        """``previous (B, L, D)`` poses, ``actions (B,)`` -> ``(B, L, D + C + 1)`` step inputs from frame ``start``."""
        b, length, _ = previous.shape
        onehot = nn.functional.one_hot(actions, self.config.n_actions).to(previous.dtype)
        t = (torch.arange(start, start + length, device=previous.device, dtype=previous.dtype) / (_N_FRAMES - 1))
        return torch.cat([previous, onehot[:, None].expand(b, length, -1), t[None, :, None].expand(b, length, 1)], -1)

    def output(self, h: torch.Tensor) -> torch.Tensor:
        """Decoder states ``(B, L, H)`` -> poses ``(B, L, D)``."""
        return torch.cat([self.root_head(h), torch.tanh(self.angle_head(h)) * self.config.angle_bound], -1)

    def forward(self, poses: torch.Tensor, actions: torch.Tensor, noise: torch.Tensor, keep: torch.Tensor):
        """Training pass, one step per frame, the latent drawn from the posterior.

        ``poses (B, T, D)`` targets, ``actions (B,)``, ``noise (B, T, Z)``, ``keep (B, T)`` bool:
        where True the next step is fed the real pose (teacher forcing), else the model's own
        output. Returns the reconstruction ``(B, T, D)`` and the posterior and prior
        ``(mu, logvar)``, each ``(B, T, Z)``.
        """
        b, n_frames, _ = poses.shape
        prev = poses.new_zeros(b, 1, self.config.pose_dim)
        h_q = h_p = h_d = None
        out, q, p = [], [], []
        for t in range(n_frames):
            cond = self.condition(prev, actions, start=t)
            hq, h_q = self.posterior(torch.cat([cond, poses[:, t : t + 1]], -1), h_q)
            hp, h_p = self.prior(cond, h_p)
            q_mu, q_logvar = self.posterior_head(hq).chunk(2, -1)
            q_logvar = q_logvar.clamp(-10, 10)
            z = q_mu + noise[:, t : t + 1] * torch.exp(0.5 * q_logvar)
            hd, h_d = self.decoder(torch.cat([cond, z], -1), h_d)
            pose = self.output(hd)
            prev = torch.where(keep[:, t, None, None], poses[:, t : t + 1], pose)
            out.append(pose)
            q.append((q_mu, q_logvar))
            p.append(self.prior_head(hp).chunk(2, -1))
        q_mu, q_logvar = (torch.cat(v, 1) for v in zip(*q))
        p_mu, p_logvar = (torch.cat(v, 1) for v in zip(*p))
        return torch.cat(out, 1), (q_mu, q_logvar), (p_mu, p_logvar.clamp(-10, 10))

    def generate(self, actions: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Autoregressive sampling from the learned prior: ``actions (B,)``, ``noise (B, T, Z)`` -> ``(B, T, D)``."""
        b, n_frames, _ = noise.shape
        prev = noise.new_zeros(b, 1, self.config.pose_dim)
        h_prior = h_dec = None
        out = []
        for t in range(n_frames):
            cond = self.condition(prev, actions, start=t)
            hp, h_prior = self.prior(cond, h_prior)
            mu, logvar = self.prior_head(hp).chunk(2, -1)
            z = mu + noise[:, t : t + 1] * torch.exp(0.5 * logvar.clamp(-10, 10))
            hd, h_dec = self.decoder(torch.cat([cond, z], -1), h_dec)
            prev = self.output(hd)
            out.append(prev)
        return torch.cat(out, 1)


@dataclass
class TransformerCVAEConfig:
    """Sizes of a :class:`TransformerCVAE` (ACTOR uses d_model 256 and 8 layers; ours is small)."""

    n_actions: int = 12
    n_joints: int = 24
    d_model: int = 128
    n_layers: int = 2
    n_heads: int = 4
    ffn_dim: int = 256
    dropout: float = 0.1
    max_len: int = 64


class TransformerCVAE(nn.Module):
    """ACTOR's transformer CVAE on normalised joint positions.

    Encoder: ``[mu_token[a], sigma_token[a], frames + positions]`` through a transformer encoder;
    linear heads on the first two outputs give ``mu`` and ``logvar`` (latent size = ``d_model``). Decoder: time
    queries attend to the single memory token ``z + action_bias[a]``. Unlike ACTOR the queries are
    the sinusoidal positions *plus* that token, and the layers are pre-norm: with ACTOR's
    position-only queries and post-norm layers our small model ignored the action within a CPU
    training budget (recogniser accuracy of its samples at chance).
    """

    def __init__(self, config: TransformerCVAEConfig):
        super().__init__()
        self.config = config
        c = config
        self.embed = nn.Linear(c.n_joints * 3, c.d_model)
        # Unit-scale action parameters, as ACTOR: at 0.02 the action is lost beside z ~ N(0, I).
        self.mu_token = nn.Parameter(torch.randn(c.n_actions, c.d_model))
        self.sigma_token = nn.Parameter(torch.randn(c.n_actions, c.d_model))
        self.action_bias = nn.Parameter(torch.randn(c.n_actions, c.d_model))
        self.register_buffer("positions", sinusoidal_positions(c.max_len + 2, c.d_model), persistent=False)
        self.encoder = nn.TransformerEncoder(
            nn.TransformerEncoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True, norm_first=True),
            c.n_layers, norm=nn.LayerNorm(c.d_model), enable_nested_tensor=False,
        )
        self.decoder = nn.TransformerDecoder(
            nn.TransformerDecoderLayer(c.d_model, c.n_heads, c.ffn_dim, c.dropout, batch_first=True, norm_first=True),
            c.n_layers, norm=nn.LayerNorm(c.d_model),
        )
        self.mu_head = nn.Linear(c.d_model, c.d_model)
        self.logvar_head = nn.Linear(c.d_model, c.d_model)
        # Start from a narrow posterior: Adam moves a bias by about the learning rate per step, so
        # from logvar 0 it takes thousands of steps to get there, and until then z is mostly noise.
        nn.init.constant_(self.logvar_head.bias, -4.0)
        self.head = nn.Linear(c.d_model, c.n_joints * 3)

    def encode(self, x: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``x (B, T, J, 3)`` normalised joints, ``actions (B,)`` -> ``mu, logvar (B, d_model)``."""
        h = self.embed(rearrange(x, "b t j c -> b t (j c)"))
        tokens = torch.cat([self.mu_token[actions][:, None], self.sigma_token[actions][:, None], h], 1)
        out = self.encoder(tokens + self.positions[: tokens.shape[1]][None])
        return self.mu_head(out[:, 0]), self.logvar_head(out[:, 1]).clamp(-10, 10)

    def decode(self, z: torch.Tensor, actions: torch.Tensor, n_frames: int) -> torch.Tensor:
        """``z (B, d_model)``, ``actions (B,)`` -> normalised joints ``(B, T, J, 3)``."""
        memory = (z + self.action_bias[actions])[:, None]
        # ACTOR's queries are the positions alone; adding the condition to every query as well
        # made a small model fit in a CPU budget (with positions alone it ignored the action).
        queries = self.positions[:n_frames][None] + memory
        out = self.head(self.decoder(queries, memory))
        return rearrange(out, "b t (j c) -> b t j c", c=3)

    def forward(self, x: torch.Tensor, actions: torch.Tensor, noise: torch.Tensor):
        """``x (B, T, J, 3)``, ``actions (B,)``, ``noise (B, d_model)`` -> reconstruction, mu, logvar."""
        mu, logvar = self.encode(x, actions)
        z = mu + noise * torch.exp(0.5 * logvar)
        return self.decode(z, actions, x.shape[1]), mu, logvar


# ----------------------------------------------------------------------------------------------
# estimators


class _ReferenceGenerator(NetworkComponent):
    """Shared parts: action look-up, seeded sampling, conversion to Motions through the adapter."""

    #: Adapter that converts this generator's raw output (see :attr:`adapter_options`).
    adapter = "action2motion"

    def _action(self, action) -> int:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return check_action(action, self.action_names_)

    def _check_n(self, n) -> int:
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"`n` must be a positive int; got {n!r}.")
        return int(n)

    def _split(self, data, rng):
        """``(clips, labels)`` of the training data and a held-out tenth for early stopping."""
        clips, labels = _check_training_data(data, len(self.action_names))
        order = rng.permutation(len(clips))
        n_val = max(1, len(clips) // 10) if len(clips) > 1 else 0
        val, train = order[:n_val], order[n_val:] if n_val else order
        return [clips[i] for i in train], labels[train], [clips[i] for i in val], labels[val]

    def adapter_options(self) -> dict:
        """Options for the adapter's conversion of :meth:`sample`'s output."""
        raise NotImplementedError

    def to_motions(self, raw, action=None, *, plugin_manager=None) -> list[Motion]:
        """Convert :meth:`sample`'s raw output into canonical motions with the ``action2motion`` adapter.

        Parameters
        ----------
        raw : ndarray
            Output of :meth:`sample`.
        action : int or str, optional
            Label stored on every motion.
        plugin_manager : refiner.plugins.manager.PluginManager, optional

        Returns
        -------
        list of Motion
            HumanAct12 motions, metres, y-down native frame, first-frame root at the origin.
        """
        from refiner.plugins.manager import get_plugin_manager

        pm = plugin_manager if plugin_manager is not None else get_plugin_manager(autoload=False)
        motions = pm.convert(self.adapter, raw, skeleton="humanact12", options=self.adapter_options())
        if action is None:
            return motions
        label = self._action(action)
        return [Motion(m.joints, skeleton=m.skeleton, fps=m.fps, action=label) for m in motions]

    def sample_motions(self, action, n: int = 1, *, random_state=None) -> list[Motion]:
        """:meth:`sample` followed by :meth:`to_motions` (unrefined motions)."""
        return self.to_motions(self.sample(action, n, random_state=random_state), action)


class LieVAEGenerator(_ReferenceGenerator):
    """Action2Motion-style conditional GRU VAE emitting Lie parameters ``(N, 60, 72)``.

    Training targets are the Lie parameters of real 60-frame crops (:func:`lie_targets`:
    Action2Motion's inverse kinematics with a continuous choice of twist, root re-centred per crop). The loss is
    the pose MSE plus ``kl_weight`` times the KL divergence between the posterior and the learned
    prior, summed over latent dimensions and averaged over frames. Training runs step by step
    like sampling; ``teacher_forcing`` is the share of steps fed the real previous pose instead
    of the model's own output (Action2Motion's scheduled teacher forcing; validation uses the
    same share with fixed draws).

    Parameters
    ----------
    hidden : int, default=128
    latent_dim : int, default=30
    kl_weight : float, default=1e-2
        Action2Motion's released HumanAct12 model uses 0.001 (0.01 for NTU); with 0.001 our
        short training gave jittery samples (joint speed three times the real one).
    teacher_forcing : float, default=0.0
        0 trains exactly as it samples; 0.5 gave lower recogniser accuracy in a 200 s trial.
    n_frames : int, default=60
    n_epochs, batch_size, learning_rate, patience, steps_per_epoch, max_seconds : training schedule
    device : str, default="auto"
    random_state : int or None, default=0
    verbose : bool, default=False

    Attributes
    ----------
    network_ : LieVAE
    action_names_ : list of str
    reference_ : ndarray of shape (24, 3), float32
        A real training pose whose bone lengths are the per-bone medians of the training data;
        the adapter takes the decoding bone lengths from it.
    history_ : list of dict
    train_seconds_ : float

    Examples
    --------
    >>> gen = load_reference_generator("a2m")                              # doctest: +SKIP
    >>> raw = gen.sample("walk", 4, random_state=0); raw.shape            # doctest: +SKIP
    (4, 60, 72)
    >>> motions = gen.to_motions(raw, "walk")                              # doctest: +SKIP
    """

    _fitted_attributes = ("action_names_", "history_", "train_seconds_")
    _fitted_arrays = ("reference_",)

    def __init__(self, hidden: int = 128, *, latent_dim: int = 30, kl_weight: float = 1e-2, teacher_forcing: float = 0.0,
                 n_frames: int = _N_FRAMES, action_names: Sequence[str] | None = None, n_epochs: int = 110,
                 batch_size: int = 128, learning_rate: float = 1e-3, patience: int = 30, steps_per_epoch: int | None = None,
                 max_seconds: float | None = None, device: str = "auto", random_state: int | None = 0,
                 verbose: bool = False):
        self.hidden = hidden
        self.latent_dim = latent_dim
        self.kl_weight = kl_weight
        self.teacher_forcing = teacher_forcing
        self.n_frames = n_frames
        self.action_names = action_names
        self.n_epochs = n_epochs
        self.batch_size = batch_size
        self.learning_rate = learning_rate
        self.patience = patience
        self.steps_per_epoch = steps_per_epoch
        self.max_seconds = max_seconds
        self.device = device
        self.random_state = random_state
        self.verbose = verbose

    def _make_network(self, fitted: dict) -> LieVAE:
        return LieVAE(LieVAEConfig(len(fitted["action_names_"]), 72, self.hidden, self.latent_dim))

    def fit(self, data) -> "LieVAEGenerator":
        """Train on labelled HumanAct12 clips (a MotionDataset or a sequence of Motions); returns self."""
        from refiner.io.datasets import HUMANACT12_ACTIONS

        self.action_names = list(self.action_names or HUMANACT12_ACTIONS)
        _check_schedule(self)
        rng = check_random_state(self.random_state)
        device = resolve_device(self.device)
        started = time.perf_counter()
        clips, labels, val_clips, val_labels = self._split(data, rng)
        # Per clip once: cropping Lie = Lie of the crop (root aside).
        lie = [lie_targets(c) for c in clips]
        val_lie = [lie_targets(c) for c in val_clips]
        self.action_names_ = list(self.action_names)
        self.reference_ = _median_bone_pose(clips)
        n = self.n_frames

        def batch(lies, labs, idx, r):
            x = training_crops(lies, n, r, idx)
            x[..., :3] -= x[:, :1, :3]  # the crop's first root at the origin
            return {"poses": torch.from_numpy(x).to(device), "actions": torch.from_numpy(labs[np.asarray(idx)]).to(device)}

        with seeded(rng):
            self.network_ = self._make_network({"action_names_": self.action_names_}).to(device)
            val = None if not val_lie else batch(val_lie, val_labels, np.arange(len(val_lie)), np.random.default_rng(0))
            self.history_ = fit_network(self.network_, self._loss, lambda idx, r: batch(lie, labels, idx, r), len(lie),
                                        val, self._schedule(), rng, desc="a2m Lie VAE")
        self.train_seconds_ = round(time.perf_counter() - started, 1)
        return self

    def _loss(self, net: LieVAE, batch: dict, rng) -> torch.Tensor:
        poses, actions = batch["poses"], batch["actions"]
        keep = torch.from_numpy(rng.random(poses.shape[:2]) < self.teacher_forcing).to(poses.device)
        noise = _normal(rng, poses.shape[:2] + (net.config.latent_dim,), poses)
        recon, (q_mu, q_logvar), (p_mu, p_logvar) = net(poses, actions, noise, keep)
        kl = 0.5 * (p_logvar - q_logvar + (q_logvar.exp() + (q_mu - p_mu) ** 2) / p_logvar.exp() - 1).sum(-1).mean()
        return nn.functional.mse_loss(recon, poses) + self.kl_weight * kl

    @torch.no_grad()
    def sample(self, action, n: int = 1, *, random_state=None) -> np.ndarray:
        """Draw ``n`` clips of ``action`` from the learned prior.

        Parameters
        ----------
        action : int or str
            HumanAct12 action index or name.
        n : int, default=1
        random_state : None, int or numpy Generator, optional

        Returns
        -------
        ndarray of shape (n, 60, 72), float32
            Per frame: root position (metres) and 23 axis-angle vectors (rad), Action2Motion's
            Lie layout. Decode with :meth:`to_motions` (or the ``action2motion`` adapter with
            ``representation="lie"`` and ``reference=reference_``).
        """
        label, n = self._action(action), self._check_n(n)
        rng = check_random_state(random_state)
        net, device = self.network_.eval(), self.device_
        noise = torch.from_numpy(rng.standard_normal((n, self.n_frames, self.latent_dim)).astype(np.float32)).to(device)
        actions = torch.full((n,), label, dtype=torch.long, device=device)
        return net.generate(actions, noise).cpu().numpy().astype(np.float32)

    def adapter_options(self) -> dict:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return {"representation": "lie", "reference": np.array(self.reference_, dtype=np.float32)}


class TransformerCVAEGenerator(_ReferenceGenerator):
    """ACTOR-style transformer CVAE emitting joint positions ``(N, 60, 24, 3)``.

    Joints are standardised per coordinate with the training crops' mean and standard deviation.
    The loss is the MSE of the standardised joints plus ``velocity_weight`` times the MSE of
    their frame differences plus ``kl_weight`` times the KL divergence to N(0, I) (summed over
    latent dimensions).

    Parameters
    ----------
    d_model : int, default=64
    n_layers : int, default=2
        Encoder and decoder layers each.
    n_heads : int, default=4
    ffn_dim : int, default=128
    dropout : float, default=0.0
    kl_weight : float, default=1e-2
        Weaker KL let the latent carry the action, so samples from the prior lost it (recogniser
        accuracy 29 % at 1e-3 against 42 % at 1e-2 in 150 s trials).
    velocity_weight : float, default=1.0
    n_frames : int, default=60
    n_epochs, batch_size, learning_rate, patience, steps_per_epoch, max_seconds : training schedule
    device : str, default="auto"
    random_state : int or None, default=0
    verbose : bool, default=False

    Attributes
    ----------
    network_ : TransformerCVAE
    action_names_ : list of str
    mean_, std_ : ndarray of shape (24, 3), float32
        Standardisation of the joints (metres).
    history_ : list of dict
    train_seconds_ : float
    """

    _fitted_attributes = ("action_names_", "history_", "train_seconds_")
    _fitted_arrays = ("mean_", "std_")

    def __init__(self, d_model: int = 64, *, n_layers: int = 2, n_heads: int = 4, ffn_dim: int = 128, dropout: float = 0.0,
                 kl_weight: float = 1e-2, velocity_weight: float = 1.0, n_frames: int = _N_FRAMES,
                 action_names: Sequence[str] | None = None, n_epochs: int = 150, batch_size: int = 64,
                 learning_rate: float = 1e-3, patience: int = 40, steps_per_epoch: int | None = None,
                 max_seconds: float | None = None, device: str = "auto", random_state: int | None = 0,
                 verbose: bool = False):
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.dropout = dropout
        self.kl_weight = kl_weight
        self.velocity_weight = velocity_weight
        self.n_frames = n_frames
        self.action_names = action_names
        self.n_epochs = n_epochs
        self.batch_size = batch_size
        self.learning_rate = learning_rate
        self.patience = patience
        self.steps_per_epoch = steps_per_epoch
        self.max_seconds = max_seconds
        self.device = device
        self.random_state = random_state
        self.verbose = verbose

    def _make_network(self, fitted: dict) -> TransformerCVAE:
        return TransformerCVAE(TransformerCVAEConfig(len(fitted["action_names_"]), 24, self.d_model, self.n_layers,
                                                     self.n_heads, self.ffn_dim, self.dropout, max(self.n_frames, 2)))

    def fit(self, data) -> "TransformerCVAEGenerator":
        """Train on labelled HumanAct12 clips (a MotionDataset or a sequence of Motions); returns self."""
        from refiner.io.datasets import HUMANACT12_ACTIONS

        self.action_names = list(self.action_names or HUMANACT12_ACTIONS)
        _check_schedule(self)
        rng = check_random_state(self.random_state)
        device = resolve_device(self.device)
        started = time.perf_counter()
        clips, labels, val_clips, val_labels = self._split(data, rng)
        n = self.n_frames
        stats = training_crops(clips, n, np.random.default_rng(0))
        stats -= stats[:, :1, :1]
        self.action_names_ = list(self.action_names)
        self.mean_ = stats.mean((0, 1)).astype(np.float32)
        self.std_ = np.maximum(stats.std((0, 1)), 1e-3).astype(np.float32)
        mean, std = torch.from_numpy(self.mean_).to(device), torch.from_numpy(self.std_).to(device)

        def batch(cl, labs, idx, r):
            x = training_crops(cl, n, r, idx)
            x -= x[:, :1, :1]
            return {"x": (torch.from_numpy(x).to(device) - mean) / std,
                    "actions": torch.from_numpy(labs[np.asarray(idx)]).to(device)}

        with seeded(rng):
            self.network_ = self._make_network({"action_names_": self.action_names_}).to(device)
            val = None if not val_clips else batch(val_clips, val_labels, np.arange(len(val_clips)), np.random.default_rng(0))
            self.history_ = fit_network(self.network_, self._loss, lambda idx, r: batch(clips, labels, idx, r), len(clips),
                                        val, self._schedule(), rng, desc="actor transformer CVAE")
        self.train_seconds_ = round(time.perf_counter() - started, 1)
        return self

    def _loss(self, net: TransformerCVAE, batch: dict, rng) -> torch.Tensor:
        x, actions = batch["x"], batch["actions"]
        recon, mu, logvar = net(x, actions, _normal(rng, (len(x), net.config.d_model), x))
        kl = -0.5 * (1 + logvar - mu**2 - logvar.exp()).sum(-1).mean()
        vel = nn.functional.mse_loss(recon[:, 1:] - recon[:, :-1], x[:, 1:] - x[:, :-1])
        return nn.functional.mse_loss(recon, x) + self.velocity_weight * vel + self.kl_weight * kl

    @torch.no_grad()
    def sample(self, action, n: int = 1, *, random_state=None) -> np.ndarray:
        """Draw ``n`` clips of ``action`` from the prior N(0, I).

        Parameters
        ----------
        action : int or str
            HumanAct12 action index or name.
        n : int, default=1
        random_state : None, int or numpy Generator, optional

        Returns
        -------
        ndarray of shape (n, 60, 24, 3), float32
            Joint positions in metres, HumanAct12's y-down frame, first-frame root near the origin.
        """
        label, n = self._action(action), self._check_n(n)
        rng = check_random_state(random_state)
        net, device = self.network_.eval(), self.device_
        z = torch.from_numpy(rng.standard_normal((n, net.config.d_model)).astype(np.float32)).to(device)
        actions = torch.full((n,), label, dtype=torch.long, device=device)
        x = net.decode(z, actions, self.n_frames).cpu().numpy()
        return (x * self.std_ + self.mean_).astype(np.float32)

    def adapter_options(self) -> dict:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return {"representation": "xyz", "recenter": True}


#: Reference generator classes by the short name used by the CLI and the shipped weights.
GENERATOR_KINDS: dict[str, type[_ReferenceGenerator]] = {"a2m": LieVAEGenerator, "actor": TransformerCVAEGenerator}


# ----------------------------------------------------------------------------------------------
# shipped weights and training


def load_reference_generator(kind: str = "a2m", *, folder: str | os.PathLike | None = None, device: str = "cpu",
                             verify: bool = True):
    """Load a trained reference generator.

    Parameters
    ----------
    kind : {"a2m", "actor"}, default="a2m"
    folder : path, optional
        A folder written by :func:`train_reference_generator` (``<kind>.safetensors`` plus
        ``manifest.json``); default the shipped weights, :data:`WEIGHTS_DIR`.
    device : str, default="cpu"
    verify : bool, default=True
        Check the manifest against its `content_sha256` and the file against its sha256.

    Returns
    -------
    LieVAEGenerator or TransformerCVAEGenerator

    Raises
    ------
    ValueError
        Unknown kind, missing or corrupt weights.
    """
    cls = _kind(kind)
    folder = Path(folder) if folder is not None else WEIGHTS_DIR
    _, paths = read_generator_manifest(folder, verify=verify)
    if kind not in paths:
        raise ValueError(f"{str(folder / 'manifest.json')!r} lists no {kind!r} generator; train one with "
                         f"`motion-refiner train-generator --kind {kind} --out {folder}`.")
    path = paths[kind]
    return cls.load(path, device=device)


def train_reference_generator(kind: str, dataset, out: str | os.PathLike, *, split: str = "train", quick: bool = False,
                              max_seconds: float | None = None, random_state: int = 0, device: str = "auto",
                              verbose: bool = False, command: str = ""):
    """Train one reference generator on a split of HumanAct12 and save it (float16) with a manifest entry.

    Parameters
    ----------
    kind : {"a2m", "actor"}
    dataset : MotionDataset
        HumanAct12 (with subject ids when ``split`` is not ``"all"``).
    out : path
        Folder; ``<kind>.safetensors`` is written and ``manifest.json`` updated (other kinds kept).
    split : {"train", "all"}, default="train"
        ``"train"`` is subjects 1-10, the shipped weights' split.
    quick : bool, default=False
        A tiny network and a few epochs (for tests).
    max_seconds : float, optional
        Training time limit (training then depends on the machine's speed; by default the fixed
        number of epochs and early stopping make it reproducible for a seed).
    random_state : int, default=0
    device : str, default="auto"
    verbose : bool, default=False
        Show a progress bar.
    command : str, optional
        The command line recorded in the manifest.

    Returns
    -------
    LieVAEGenerator or TransformerCVAEGenerator
        The fitted generator.
    """
    cls = _kind(kind)
    data = dataset.split(split)
    params: dict[str, Any] = {"max_seconds": max_seconds, "random_state": random_state, "device": device,
                              "verbose": verbose}
    if quick:
        params.update(n_epochs=2, steps_per_epoch=2, batch_size=16, patience=5)
        params.update({"hidden": 16, "latent_dim": 4} if kind == "a2m" else
                      {"d_model": 16, "n_layers": 1, "n_heads": 2, "ffn_dim": 16})
    gen = cls(**params).fit(data)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{kind}.safetensors"
    gen.save(path, half=True)
    manifest_path = out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    manifest.update({"dataset": getattr(dataset, "name", "humanact12"), "licence": LICENCE,
                     "crop_frames": gen.n_frames, "frame": "HumanAct12 native (metres, y down, facing -z), "
                     "first-frame root at the origin"})
    subjects = sorted({int(s) for s in getattr(data, "subjects", [])})
    manifest.setdefault("generators", {})[kind] = {
        "file": path.name, "sha256": file_sha256(path), "class": cls.__name__, "split": split, "subjects": subjects,
        "clips": len(data), "parameters": gen.n_parameters(), "epochs": len(gen.history_),
        "best_val_loss": min((h["val"] for h in gen.history_ if "val" in h), default=None),
        "train_seconds": gen.train_seconds_, "seed": random_state, "dtype": "float16", "command": command,
        "adapter": gen.adapter, "adapter_options": {k: v for k, v in gen.adapter_options().items() if k != "reference"},
    }
    write_manifest(manifest_path, manifest)
    return gen


# ----------------------------------------------------------------------------------------------
# helpers


def _kind(kind: str) -> type[_ReferenceGenerator]:
    if kind not in GENERATOR_KINDS:
        raise ValueError(f"unknown reference generator {kind!r}; known: {', '.join(GENERATOR_KINDS)}.")
    return GENERATOR_KINDS[kind]


def _check_schedule(est) -> None:
    """ValueError for schedule values the training loop cannot use."""
    for name in ("n_epochs", "batch_size", "n_frames"):
        v = getattr(est, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"`{name}` must be a positive int; got {v!r}.")
    if est.n_frames > _N_FRAMES + 4:
        raise ValueError(f"`n_frames` must be at most {_N_FRAMES + 4}; got {est.n_frames}.")


def _normal(rng: np.random.Generator, shape, like: torch.Tensor) -> torch.Tensor:
    """Standard normal noise from the numpy stream (reproducible), as a tensor like ``like``."""
    return torch.from_numpy(rng.standard_normal(tuple(shape)).astype(np.float32)).to(like.device)


def _median_bone_pose(clips: Sequence[np.ndarray]) -> np.ndarray:
    """The first frame of the clip whose bone lengths are closest to the per-bone medians."""
    from refiner.core.skeletons import get_skeleton

    skel = get_skeleton("humanact12")
    firsts = np.stack([c[0] for c in clips]).astype(np.float64)
    lengths = skel.bone_lengths(firsts)  # (N, B)
    best = int(np.argmin(np.abs(lengths - np.median(lengths, 0)).sum(1)))
    return firsts[best].astype(np.float32)
