"""The Action2Motion-style reference generator ``"a2m"``: a conditional GRU VAE emitting Lie parameters.

Follows Action2Motion (Guo et al. 2020): a recurrent CVAE with a learned prior that emits, frame by
frame, the root position and 23 axis-angle vectors (the Lie layout of generator_formats.md §2.1).
Its training targets come from real clips through the ``action2motion`` adapter's inverse conversion
(:func:`lie_targets`) and its output is decoded into joints by the same adapter
(``representation="lie"``), both through the plugin contract.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from torch import nn

from refiner.core.motion import Motion
from refiner.core.validation import check_is_fitted
from refiner.nn.components import NOT_FITTED
from refiner.nn.training import ClipCrops, TrainSchedule
from refiner.plugins.manager import PluginManager, get_plugin_manager
from refiner.reference.base import (
    N_FRAMES,
    ReferenceGenerator,
    median_bone_pose,
    normal_noise,
    pad_with_last_frame,
)

__all__ = ["LieVAE", "LieVAEConfig", "LieVAEGenerator", "lie_targets"]

_ADAPTER = "action2motion"
#: Options of the adapter's ``refiner_encode_motions`` that give the Lie VAE's training targets.
_TARGET_OPTIONS = {"representation": "lie", "continuous": True}


def lie_targets(joints, *, plugin_manager: PluginManager | None = None) -> np.ndarray:
    """Action2Motion Lie parameters of HumanAct12 joints that change smoothly over time (the Lie VAE's targets).

    Action2Motion's own inverse kinematics (``joints_to_lie`` of the ``action2motion`` adapter) jumps
    where a bone turns through pi: frame-to-frame steps of real clips jump by more than 1 rad, which a
    regression network cannot follow. The adapter's continuous variant (its
    ``refiner_encode_motions`` hook with ``representation="lie", continuous=True``, reached through
    the plugin manager) differs only in the twist about bones: decoding gives back the same joints and
    steps over 1 rad become rare (docs/decisions.md D14).

    Parameters
    ----------
    joints : array-like of shape (T, 24, 3)
        Metres, HumanAct12's y-down frame.
    plugin_manager : refiner.plugins.manager.PluginManager, optional
        Default: the built-in adapters only.

    Returns
    -------
    ndarray of shape (T, 72), float32
        Root position, then 23 axis-angle vectors (rad, norms up to 2 pi).
    """
    return _lie_targets([joints], plugin_manager)[0]


def _lie_targets(clips: Sequence[np.ndarray], pm: PluginManager | None = None) -> list[np.ndarray]:
    """:func:`lie_targets` of many clips through one plugin manager."""
    pm = pm if pm is not None else get_plugin_manager(autoload=False)
    motions = [Motion(c, skeleton="humanact12") for c in clips]
    return pm.encode(_ADAPTER, motions, options=_TARGET_OPTIONS)


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
    (Action2Motion uses pi; our targets are unwrapped over time, see :func:`lie_targets`, so
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

    def condition(self, previous: torch.Tensor, actions: torch.Tensor, start: int = 0,
                  guidance: float = 0.0) -> torch.Tensor:
        """``previous (B, L, D)`` poses, ``actions (B,)`` -> ``(B, L, D + C + 1)`` step inputs from frame ``start``.

        ``guidance`` g extrapolates the action code away from the uniform mixture of all actions:
        ``onehot + g (onehot - 1 / C)`` (g = 0: the one-hot the network was trained on).
        """
        b, length, _ = previous.shape
        onehot = nn.functional.one_hot(actions, self.config.n_actions).to(previous.dtype)
        if guidance:
            onehot = onehot + guidance * (onehot - 1.0 / self.config.n_actions)
        t = (torch.arange(start, start + length, device=previous.device, dtype=previous.dtype) / (N_FRAMES - 1))
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

    def generate(self, actions: torch.Tensor, noise: torch.Tensor, guidance: float = 0.0) -> torch.Tensor:
        """Autoregressive sampling from the learned prior: ``actions (B,)``, ``noise (B, T, Z)`` -> ``(B, T, D)``;
        ``guidance`` as in :meth:`condition`."""
        b, n_frames, _ = noise.shape
        prev = noise.new_zeros(b, 1, self.config.pose_dim)
        h_prior = h_dec = None
        out = []
        for t in range(n_frames):
            cond = self.condition(prev, actions, start=t, guidance=guidance)
            hp, h_prior = self.prior(cond, h_prior)
            mu, logvar = self.prior_head(hp).chunk(2, -1)
            z = mu + noise[:, t : t + 1] * torch.exp(0.5 * logvar.clamp(-10, 10))
            hd, h_dec = self.decoder(torch.cat([cond, z], -1), h_dec)
            prev = self.output(hd)
            out.append(prev)
        return torch.cat(out, 1)


class LieVAEGenerator(ReferenceGenerator):
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
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=110, batch_size=128, learning_rate=1e-3, patience=30)
    random_state : int or None, default=0
    warm_start : bool, default=False
        When fitted already, :meth:`fit` goes on training the fitted network (a fresh ``schedule``)
        instead of starting anew; ``history_`` and ``train_seconds_`` then add up.
    guidance : float, default=0.0
        Sampling only: the action code fed to the prior and the decoder is pushed away from the
        uniform mixture of all actions, ``onehot + guidance (onehot - 1 / C)`` (the one-hot-input
        analogue of classifier-free guidance; :data:`~refiner.reference.loading.KIND_PARAMETERS`
        records how the ``a2m-large`` value was chosen).

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
    _desc = "a2m Lie VAE"

    def __init__(self, hidden: int = 128, *, latent_dim: int = 30, kl_weight: float = 1e-2, teacher_forcing: float = 0.0,
                 n_frames: int = N_FRAMES, action_names: Sequence[str] | None = None,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=110, batch_size=128, learning_rate=1e-3, patience=30),
                 random_state: int | None = 0, warm_start: bool = False, guidance: float = 0.0):
        self.hidden = hidden
        self.latent_dim = latent_dim
        self.kl_weight = kl_weight
        self.teacher_forcing = teacher_forcing
        self.n_frames = n_frames
        self.action_names = action_names
        self.schedule = schedule
        self.random_state = random_state
        self.warm_start = warm_start
        self.guidance = guidance

    def _make_network(self, fitted: dict) -> LieVAE:
        return LieVAE(LieVAEConfig(len(fitted["action_names_"]), 72, self.hidden, self.latent_dim))

    def _fit_statistics(self, clips: Sequence[np.ndarray]) -> None:
        self.reference_ = median_bone_pose(clips)

    def _crops(self, clips: Sequence[np.ndarray]) -> ClipCrops:
        # Lie targets per clip once: cropping Lie = Lie of the crop (root aside).
        return ClipCrops(clips, self.n_frames, {"lie": _lie_targets(clips)})

    def _batch(self, crops: dict, actions: torch.Tensor, device) -> dict:
        x = pad_with_last_frame(crops["lie"], crops["valid"])
        x[..., :3] -= x[:, :1, :3]  # the crop's first root at the origin
        return {"poses": torch.from_numpy(x).to(device), "actions": actions}

    def _loss(self, net: LieVAE, batch: dict, rng) -> torch.Tensor:
        poses, actions = batch["poses"], batch["actions"]
        keep = torch.from_numpy(rng.random(poses.shape[:2]) < self.teacher_forcing).to(poses.device)
        noise = normal_noise(rng, poses.shape[:2] + (net.config.latent_dim,), poses)
        recon, (q_mu, q_logvar), (p_mu, p_logvar) = net(poses, actions, noise, keep)
        kl = 0.5 * (p_logvar - q_logvar + (q_logvar.exp() + (q_mu - p_mu) ** 2) / p_logvar.exp() - 1).sum(-1).mean()
        return nn.functional.mse_loss(recon, poses) + self.kl_weight * kl

    def _draw(self, net: LieVAE, actions: torch.Tensor, rng: np.random.Generator) -> np.ndarray:
        """Autoregressive samples from the learned prior, ``(n, n_frames, 72)`` float32: per frame the root
        position (metres) and 23 axis-angle vectors (rad), Action2Motion's Lie layout; decode with
        :meth:`to_motions` (or the ``action2motion`` adapter with ``representation="lie"`` and
        ``reference=reference_``)."""
        if isinstance(self.guidance, bool) or not isinstance(self.guidance, (int, float)) or not np.isfinite(self.guidance):
            raise ValueError(f"`guidance` must be a finite number; got {self.guidance!r}.")
        noise = normal_noise(rng, (len(actions), self.n_frames, self.latent_dim), actions)
        return net.generate(actions, noise, self.guidance).cpu().numpy().astype(np.float32)

    def adapter_options(self) -> dict:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return {"representation": "lie", "reference": np.array(self.reference_, dtype=np.float32)}
